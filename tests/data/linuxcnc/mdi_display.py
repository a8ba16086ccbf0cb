#!/usr/bin/python3
"""A headless LinuxCNC "display" for the tests (tests/linuxcnc.py): LinuxCNC starts it
as ``[DISPLAY] DISPLAY`` with ``-ini INIFILE`` and shuts itself down when it exits.

It runs under Debian's /usr/bin/python3 with its ``linuxcnc`` module (python3-linuxcnc),
not under the project's virtualenv. It reads the job, ``mdi_job.json`` beside the INI:
``{"targets": [[x, y, z], ...], "feed": null or mm/min, "timeout_s": s}``; brings the
machine up (E-stop reset, machine on, every joint homed), sends each target in MDI
(G0, or G1 at the feed), waits for the motion to end, records where the joints and the
tool point stand, and writes ``mdi_results.json`` beside it:
``{"points": [{"target", "joints", "position", "actual_position", "motor",
"motor_offset"}], "error": null or text, "kinematics_type"}``. ``joints`` are the
joints commanded (``joint.N.output``, before screw compensation); ``motor`` the HAL
pins ``joint.N.motor-pos-cmd`` and ``motor_offset`` ``joint.N.motor-offset``, read
through a HAL component of its own: motor-pos-cmd less motor-offset is the joint
commanded with its compensation (a COMP_FILE's trim) added. Every wait has a deadline;
any failure is written as ``error`` and the exit status is 1.
"""

import json
import os
import sys
import time

import hal
import linuxcnc

POLL_S = 0.02
JOB, RESULTS = "mdi_job.json", "mdi_results.json"


class Failed(Exception):
    """The job cannot go on; the message says why."""


class Machine:
    def __init__(self, timeout_s):
        self.timeout_s = timeout_s
        self.pins = None
        deadline = time.monotonic() + timeout_s
        while True:  # the task's NML channels, normally up before the display starts
            try:
                self.command = linuxcnc.command()
                self.stat = linuxcnc.stat()
                self.errors = linuxcnc.error_channel()
                self.stat.poll()
                break
            except linuxcnc.error:
                if time.monotonic() > deadline:
                    raise
                time.sleep(POLL_S)

    def attach_hal(self):
        """A HAL component of the display's own, so that it may read pins."""
        self.pins = hal.component("orthocal-mdi-display")
        self.pins.ready()

    def detach_hal(self):
        if self.pins is not None:
            self.pins.exit()
            self.pins = None

    def motors(self, joints):
        """(motor-pos-cmd, motor-offset) of each joint."""
        return ([hal.get_value(f"joint.{n}.motor-pos-cmd") for n in range(joints)],
                [hal.get_value(f"joint.{n}.motor-offset") for n in range(joints)])

    def poll(self):
        self.stat.poll()
        error = self.errors.poll()
        if error and error[0] in (linuxcnc.NML_ERROR, linuxcnc.OPERATOR_ERROR):
            raise Failed("LinuxCNC: " + error[1])
        return self.stat

    def wait_for(self, what, condition):
        deadline = time.monotonic() + self.timeout_s
        while not condition(self.poll()):
            if time.monotonic() > deadline:
                raise Failed(f"timed out after {self.timeout_s:.0f} s waiting for {what}")
            time.sleep(POLL_S)

    def set_state(self, state, name):
        self.command.state(state)
        self.wait_for("state " + name, lambda s: s.task_state == state)

    def set_mode(self, mode, name):
        self.command.mode(mode)
        self.wait_for("mode " + name, lambda s: s.task_mode == mode)

    def start(self):
        """E-stop reset, machine on, every joint homed (immediate homing: the
        configuration's HOME_SEARCH_VEL = 0), then MDI in millimetres."""
        self.wait_for("the task to answer", lambda s: s.task_state != 0)
        self.set_state(linuxcnc.STATE_ESTOP_RESET, "E-stop reset")
        self.set_state(linuxcnc.STATE_ON, "machine on")
        self.set_mode(linuxcnc.MODE_MANUAL, "manual")
        self.command.teleop_enable(0)
        self.command.wait_complete(self.timeout_s)
        self.command.home(-1)
        self.command.wait_complete(self.timeout_s)
        self.wait_for("every joint homed",
                      lambda s: all(s.homed[n] for n in range(s.joints)))
        self.set_mode(linuxcnc.MODE_MDI, "MDI")
        self.mdi("G21 G90")

    def mdi(self, line):
        self.command.mdi(line)
        if self.command.wait_complete(self.timeout_s) == -1:
            raise Failed(f"timed out after {self.timeout_s:.0f} s on MDI {line}")
        self.wait_for("the end of MDI " + line, lambda s: s.interp_state
                      == linuxcnc.INTERP_IDLE and s.inpos and s.queue == 0
                      and s.state == linuxcnc.RCS_DONE)

    def move(self, target, feed):
        # Fixed notation: the G-code reader takes no exponent; 17 decimals give the
        # double back exactly.
        words = " ".join(f"{a}{v:.17f}" for a, v in zip("XYZ", target, strict=True))
        self.mdi(f"G0 {words}" if feed is None else f"G1 {words} F{feed:.6f}")
        s = self.settled()
        motor, offset = self.motors(s.joints)
        return {"target": list(target),
                "joints": [s.joint[n]["output"] for n in range(s.joints)],
                "position": list(s.position[:3]),
                "actual_position": list(s.actual_position[:3]),
                "motor": motor, "motor_offset": offset}

    def settled(self):
        """The status once the feedback stands still: in position is reached a servo
        cycle or two before actual_position (the kinematics' forward of the joints'
        feedback) has caught up, and a compensation's trim ramps to its value after the
        move, so two polls in a row must agree (poll() refreshes one stat object: its
        values are copied to compare)."""
        def seen(s):
            return (list(s.actual_position[:3]),
                    [s.joint[n]["output"] for n in range(s.joints)],
                    self.motors(s.joints))

        deadline = time.monotonic() + self.timeout_s
        last = seen(self.poll())
        while time.monotonic() < deadline:
            time.sleep(POLL_S)
            now = seen(self.poll())
            if now == last:
                return self.stat
            last = now
        raise Failed(f"the feedback did not settle within {self.timeout_s:.0f} s")

    def stop(self):
        """E-stop, so that the machine is off before LinuxCNC unloads it."""
        self.command.state(linuxcnc.STATE_ESTOP)
        self.command.wait_complete(self.timeout_s)


def run(folder):
    with open(os.path.join(folder, JOB)) as f:
        job = json.load(f)
    out = {"points": [], "error": None, "kinematics_type": None}
    machine = None
    try:
        machine = Machine(float(job.get("timeout_s", 30.0)))
        machine.attach_hal()
        machine.start()
        out["kinematics_type"] = machine.poll().kinematics_type
        for target in job["targets"]:
            out["points"].append(machine.move(target, job.get("feed")))
    except (Failed, linuxcnc.error) as exc:
        out["error"] = str(exc)
    finally:
        if machine is not None:
            try:
                machine.stop()
            except linuxcnc.error as exc:
                out["error"] = out["error"] or f"E-stop failed: {exc}"
            machine.detach_hal()
        partial = os.path.join(folder, RESULTS + ".part")
        with open(partial, "w") as f:
            json.dump(out, f)
        os.replace(partial, os.path.join(folder, RESULTS))
    return 0 if out["error"] is None else 1


def main(argv):
    if len(argv) < 3 or argv[1] != "-ini":
        sys.stderr.write("usage: mdi_display.py -ini INIFILE (run by LinuxCNC)\n")
        return 2
    return run(os.path.dirname(os.path.abspath(argv[2])))


if __name__ == "__main__":
    sys.exit(main(sys.argv))
