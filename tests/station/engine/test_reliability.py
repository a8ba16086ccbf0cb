"""Reliability through the real command line and the real simulators.

Faults are injected through the knobs of the simulated devices (Modbus server
faults, pty gauge faults, the virtual machine) while ``orthocal run --simulate``
runs in-process through ``station.commands.cli.main``: transient faults are retried,
journaled and give the right answer; persistent ones stop the axes, keep the
journal and end in one line naming the device (exit 1); a write-back that
fails is undone; a knock on the stand is rejected and recorded (bad input:
test_bad_input.py).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import FAST, CliOutcome, Rig, no_figures_file, on_setup

from drivers.sim.station import VirtualStation
from station import report
from station.engine import devices
from station.record.journal_file import read_journal

SEED = 11
TRUE_DRHO = (0.7, -1.1, 0.35)
SPEED = "20000"  # mm/s: the virtual machine's moves stay physical but short
#: The controller's timeout where its retries are counted: far above any stall of a
#: loaded machine, while one lost reply still costs only this once.
CONTROLLER_TIMEOUT_S = 1.5
STOP = 2  # COMMAND code of a stop in orthocal-generic
WRITABLE = ("COMMAND", "TARGET_X", "TARGET_Y", "TARGET_Z", "SPEED", "OFFSET_X", "OFFSET_Y",
            "OFFSET_Z")


def run_args(tmp_path: Path, *extra: str, procedure: dict[str, Any] | None = None,
             drho: tuple[float, float, float] = TRUE_DRHO) -> list[str]:
    # Stands placed exactly (--mount-error 0) and 2 µm gauges: one write-back, two
    # phases, so the faults injected per setup land where these tests count them.
    return ["run", "--simulate", no_figures_file(tmp_path), "--seed", str(SEED), "--true-drho",
            ",".join(str(v) for v in drho), "--mount-error", "0", "--noise", "0.002",
            "--out", str(tmp_path / "runs"),
            "--sim-speed", SPEED, "--sim-procedure", json.dumps(procedure or FAST),
            *extra]


def assert_right_answer(result: dict[str, Any], drho: tuple[float, float, float] = TRUE_DRHO
                        ) -> None:
    for axis, true in zip("xyz", drho, strict=True):
        name = f"drho_{axis}"
        se = result["std_errors"][name]
        assert math.isfinite(se) and se > 0
        assert abs(result["identified"][name] - true) <= 4 * se, (name, result["identified"])


def lost_readings(records: list[dict[str, Any]], readings: int) -> int:
    """Stops that a journaled cycle was computed from but whose readings the
    journal does not hold in full (every mounted gauge, ``readings`` values)."""
    names = {(r["phase"], r["setup"]): list(r["indicators"]) for r in records
             if r["type"] == "setup"}
    # a setup whose gauges were left on from the round before is journaled as kept
    names |= {(e["phase"], e["setup"]): list(e["indicators"]) for r in records
              if r["type"] == "event" and (e := r["event"])["event"] == "mount-kept"
              and e["kept"]}
    have = {(r["stop"], r["indicator"]) for r in records
            if r["type"] == "reading" and len(r["values"]) == readings}
    lost = 0
    for r in records:
        if r["type"] != "cycle":
            continue
        p, s, c = r["phase"], r["setup"], r["cycle"]
        for stop in (f"{p}:{s}:{c - 1}:0", f"{p}:{s}:{c}:+", f"{p}:{s}:{c}:-", f"{p}:{s}:{c}:0"):
            lost += sum(1 for n in names[(p, s)] if (stop, n) not in have)
    return lost


def retry_events(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r["event"] for r in records
            if r["type"] == "event" and r["event"].get("event") == "retry"]


def wait_until_still(station: VirtualStation, limit_s: float = 10.0) -> None:
    """A decelerating stop takes time; wait (bounded) for the axes to come to rest."""
    deadline = time.monotonic() + limit_s
    while station.machine.status().moving and time.monotonic() < deadline:
        time.sleep(0.02)


# --- transient faults ------------------------------------------------------------------


def test_transient_faults_are_retried_journaled_and_give_the_right_answer(
        tmp_path: Path, orthocal) -> None:
    def prepare(rig: Rig, station: VirtualStation) -> None:
        if len(rig.stations) > 1:
            return
        a, b = station.indicators["A"].faults, station.indicators["B"].faults
        c = station.controller.faults
        a.drop_next = 2          # replies lost
        b.garble_next = 2        # replies garbled (bad characters or cut short)
        # Later in the run, one of each other kind, so that they do not overlap.
        on_setup(station, 2, lambda: (setattr(a, "error_next", 1),
                                      setattr(c, "busy_next", 1)))
        on_setup(station, 3, lambda: (setattr(b, "late_next", 1), setattr(b, "late_s", 0.4),
                                      setattr(c, "drop_next", 1)))
        on_setup(station, 4, lambda: setattr(c, "garble_next", 1))
        on_setup(station, 5, lambda: setattr(c, "disconnect_next", 1))

    # The controller's retries are counted exactly below, so its timeout is long enough
    # that a loaded test machine (a reply late by a quarter second, as seen in CI) is
    # not a fault of its own; the lost reply costs that timeout once.
    o = orthocal(*run_args(tmp_path, "--json"), prepare=prepare,
                 controller_timeout_s=CONTROLLER_TIMEOUT_S)
    assert o.code in (0, 3), o.err
    result = json.loads(o.out)
    # completed: 0, or 3 where its closed loop did not converge (it says why)
    assert o.code == (3 if report.not_converged(result) else 0), o.err
    assert "Traceback" not in o.err
    assert result["status"] == "ok" and result["writeback"]["status"] == "written"
    assert_right_answer(result)

    station = o.rig.station
    for f in (o.rig.gauges["A"].faults, o.rig.gauges["B"].faults, station.controller.faults):
        left = {k: v for k, v in vars(f).items() if k.endswith("_next") and v}
        assert not left, f"faults never injected: {left}"
    stats = station.controller.stats
    assert stats.dropped == stats.garbled == stats.busy == stats.disconnects == 1

    records = o.journal
    retries = retry_events(records)
    ctrl = [e for e in retries if e["device"].startswith("controller")]
    # every failed controller exchange was retried once, and each retry journaled
    assert len(ctrl) == stats.dropped + stats.garbled + stats.busy + stats.disconnects, [
        (e["op"], e["error"]) for e in ctrl]
    errors_a = " ".join(e["error"] for e in retries if e.get("indicator") == "A")
    errors_b = [e["error"] for e in retries if e.get("indicator") == "B"]
    assert errors_a.count("no reply") >= 2 and "gauge error" in errors_a
    assert len(errors_b) >= 3  # two garbled, one late
    assert result["timing"]["retries"] == len(retries)
    assert lost_readings(records, FAST["readings"]) == 0
    # nothing was written outside the register map's writable registers
    m = station.controller.map
    allowed = {a for name in WRITABLE
               for a in range(m[name].address, m[name].address + m[name].words)}
    assert o.rig.writes and all(set(range(a, a + n)) <= allowed for a, n in o.rig.writes)


# --- persistent faults -----------------------------------------------------------------


def _unplug(station: VirtualStation) -> None:
    on_setup(station, 2, lambda: station.indicators["B"].unplug())


def _silence(station: VirtualStation) -> None:
    on_setup(station, 2, lambda: setattr(station.controller.faults, "silent", True))


def _alarm(station: VirtualStation) -> None:
    # the drive faults halfway through the second move of the second setup
    on_setup(station, 2, lambda: setattr(station.controller.faults, "alarm_after_moves", 1))


def _estop(station: VirtualStation) -> None:
    on_setup(station, 2, lambda: setattr(station.controller.faults, "estop", True))


def _refuse_targets(station: VirtualStation) -> None:
    # The drive's soft limits shrink after the plan was checked against them.
    def shrink() -> None:
        station.controller.soft_max = station.controller.soft_max - 60.0

    on_setup(station, 2, shrink)


def _slow_axes(station: VirtualStation) -> None:
    # The axes accelerate far slower than the station assumes (a failing drive, a
    # brake left on): the move cannot arrive within its derived deadline.
    on_setup(station, 2, lambda: setattr(station.machine, "accel_mm_s2", 100.0))


PERSISTENT = {
    # name: (inject, device prefix, what happened, a stop reached the drive)
    "indicator unplugged": (_unplug, "indicator B (", "port", True),
    "controller silent": (_silence, "controller 127.0.0.1:", "no reply", False),
    "alarm": (_alarm, "controller 127.0.0.1:", "alarm 17", True),
    "e-stop": (_estop, "controller 127.0.0.1:", "emergency stop", True),
    "target refused": (_refuse_targets, "controller 127.0.0.1:", "refused", True),
    "move too slow": (_slow_axes, "controller 127.0.0.1:", "not in position", True),
}


# A deadline is the subject of "move too slow": its machine at real time (conftest).
@pytest.mark.parametrize("name", [
    pytest.param(n, marks=pytest.mark.real_time) if n == "move too slow" else n
    for n in PERSISTENT])
def test_persistent_fault_stops_axes_keeps_journal_one_line_exit_1(
        tmp_path: Path, orthocal, name: str) -> None:
    inject, device, what, stop_reaches_drive = PERSISTENT[name]

    def prepare(rig: Rig, station: VirtualStation) -> None:
        if len(rig.stations) == 1:
            inject(station)

    o = orthocal(*run_args(tmp_path), prepare=prepare)
    assert o.code == 1
    assert "Traceback" not in o.err + o.out
    (line,) = o.failure_lines()
    assert device in line and what in line, line
    assert f"orthocal resume {o.run_dir}" in line

    station = o.rig.station
    if stop_reaches_drive:
        assert station.controller.stats.commands.get(STOP, 0) >= 1
        assert "Axes stopped" in line
    else:  # never claim a stop that the drive could not be told
        assert "Axes stopped" not in line and "did not reach the controller" in line
    wait_until_still(station)
    assert not station.machine.status().moving

    records = o.journal
    fault = records[-1]
    assert fault["type"] == "fault" and fault["device"].startswith(device)
    if not stop_reaches_drive:  # the stop could not be sent: that is on record too
        assert any(r["type"] == "event" and r["event"].get("event") == "stop-failed"
                   for r in records)
    # the first setup's cycles were measured before the fault and are all kept
    assert sum(1 for r in records if r["type"] == "cycle") >= FAST["cycles"]
    assert lost_readings(records, FAST["readings"]) == 0
    assert json.loads((o.run_dir / "result.json").read_text())["status"] == "failed"
    assert not any(r["type"] == "writeback" for r in records)


@pytest.mark.parametrize("name", ["indicator unplugged", "controller silent"])
def test_after_a_persistent_fault_resume_finishes(tmp_path: Path, orthocal, name: str) -> None:
    inject = PERSISTENT[name][0]
    rig = Rig()
    failed = orthocal(*run_args(tmp_path), rig=rig,
                      prepare=lambda r, s: inject(s) if len(r.stations) == 1 else None)
    assert failed.code == 1
    before = (failed.run_dir / "journal.jsonl").read_bytes()
    o = orthocal("resume", str(failed.run_dir), "--json", rig=rig)
    assert o.code in (0, 3), o.err
    result = json.loads(o.out)
    assert o.code == (3 if report.not_converged(result) else 0), o.err
    assert result["status"] == "ok"
    assert_right_answer(result)
    assert (failed.run_dir / "journal.jsonl").read_bytes().startswith(before)
    assert lost_readings(o.journal, FAST["readings"]) == 0


# --- write-back ------------------------------------------------------------------------


def _offset_addresses(station: VirtualStation) -> set[int]:
    m = station.controller.map
    return {m[f"OFFSET_{a}"].address for a in "XYZ"}


def _on_offset_write(rig: Rig, station: VirtualStation, action: Callable[[], None]) -> None:
    """Run ``action`` once, the first time the drive is sent new offsets."""
    offsets = _offset_addresses(station)
    write = station.controller._write
    done: list[bool] = []

    def wrapped(start: int, address: int, values: list[int], registers: list[int]):
        if address in offsets and not done:
            done.append(True)
            action()
        return write(start, address, values, registers)

    station.controller._write = wrapped  # type: ignore[method-assign]


def _refuse_offsets(rig: Rig, station: VirtualStation) -> None:
    station.controller.max_offset_mm = 0.5  # exception 3 for |o| > 0.5 mm


def _flaky_storage(rig: Rig, station: VirtualStation) -> None:
    # The first write lands 4 µm off on x: the read-back must catch it.
    machine = station.machine
    store = machine.set_offsets
    calls: list[int] = []

    def set_offsets(offsets) -> None:
        calls.append(1)
        o = np.asarray(offsets, dtype=float)
        store(o + np.array([0.004, 0.0, 0.0]) if len(calls) == 1 else o)

    machine.set_offsets = set_offsets  # type: ignore[method-assign]


def _write_reply_lost(rig: Rig, station: VirtualStation) -> None:
    # The write reaches the drive but no reply does, through every retry: the
    # station cannot know what the drive holds.
    f = station.controller.faults
    _on_offset_write(rig, station,
                     lambda: setattr(f, "drop_next", devices.DEVICE_RETRIES + 1))


WRITEBACK_FAULTS = {
    "write refused": (_refuse_offsets, "exception 3"),
    "read-back differs": (_flaky_storage, "read back"),
    "write reply lost": (_write_reply_lost, "no reply"),
}


@pytest.mark.parametrize("name", list(WRITEBACK_FAULTS))
def test_failed_write_back_restores_the_backup(tmp_path: Path, orthocal, name: str) -> None:
    inject, what = WRITEBACK_FAULTS[name]
    o = orthocal(*run_args(tmp_path, "--json"), prepare=lambda r, s: inject(r, s))
    assert o.code == 1
    assert "Traceback" not in o.err
    result = json.loads(o.out)
    assert result["status"] == "failed" and result["writeback"]["status"] == "failed-restored"
    reason = result["writeback"]["reason"]
    assert what in reason and "restored" in reason
    assert result["offsets_written"] is None and result["verification"] is None
    before = result["offsets_before"]
    station = o.rig.station
    np.testing.assert_allclose(station.offsets, [before[a] for a in "xyz"], atol=1e-9)
    nvram = json.loads((o.run_dir / "controller_nvram.json").read_text())["offsets_mm"]
    np.testing.assert_allclose(nvram, [before[a] for a in "xyz"], atol=1e-9)
    stages = [r["stage"] for r in o.journal if r["type"] == "writeback"]
    assert stages == ["backup", "intent", "failed-restored"]


def test_write_back_whose_restore_fails_says_so_and_rollback_repairs(
        tmp_path: Path, orthocal) -> None:
    def prepare(rig: Rig, station: VirtualStation) -> None:
        if len(rig.stations) == 1:  # the drive goes silent right after taking the write
            f = station.controller.faults
            _on_offset_write(rig, station, lambda: setattr(f, "silent", True))

    rig = Rig()
    o = orthocal(*run_args(tmp_path), prepare=prepare, rig=rig)
    assert o.code == 1 and "Traceback" not in o.err
    (line,) = o.failure_lines()
    assert "restoring the backup failed too" in line
    assert f"orthocal rollback {o.run_dir}" in line
    backup = json.loads((o.run_dir / "offsets_backup.json").read_text())["offsets_mm"]
    # the drive did take the new offsets: they are not the backup
    assert not np.allclose(rig.station.offsets, [backup[a] for a in "xyz"])

    back = orthocal("rollback", str(o.run_dir), "--json", rig=rig)
    assert back.code == 0, back.err
    np.testing.assert_allclose(rig.stations[-1].offsets, [backup[a] for a in "xyz"],
                               atol=1e-9)


def test_correction_beyond_the_limit_writes_nothing(tmp_path: Path, orthocal) -> None:
    o = orthocal(*run_args(tmp_path, "--json", drho=(0.2, 3.4, -0.1)))
    assert o.code == 1
    result = json.loads(o.out)
    assert result["status"] == "refused" and "max_abs_offset_mm" in result["message"]
    offsets = _offset_addresses(o.rig.station)
    assert not [a for a, _ in o.rig.writes if a in offsets]
    np.testing.assert_allclose(o.rig.station.offsets, [0.0, 0.0, 0.0], atol=1e-12)


# --- outliers --------------------------------------------------------------------------


KNOCK_MM = 0.25


def test_a_knock_on_the_stand_is_rejected_and_recorded(tmp_path: Path, orthocal) -> None:
    """One reading of one gauge jumps by a quarter of a millimetre, in four stops of
    each phase:
    averaged in, each would move its deviation by 50 µm, i.e. tens of standard
    errors of the identified offsets."""
    knocked: list[int] = []

    def prepare(rig: Rig, station: VirtualStation) -> None:
        if len(rig.stations) > 1:
            return
        source = station.source

        def knocking(leg: str, direction: str) -> Callable[[], float]:
            read = source(leg, direction)
            calls = [0]

            def value() -> float:
                calls[0] += 1
                # call 1 zeroes the gauge at mounting; then 5 readings per stop:
                # the 3rd reading of the 2nd, 5th, 7th and 9th stops of the setup
                if leg == "x" and direction == "y" and calls[0] in (9, 19, 29, 39):
                    knocked.append(calls[0])
                    return read() + KNOCK_MM
                return read()

            return value

        station.source = knocking  # type: ignore[method-assign]

    # The knocks are placed by counting the gauge's readings at stops: without the
    # plunger guard's readings during the first cycle's moves.
    procedure = {**FAST, "cycles": 3, "readings": 5, "plunger_guard": False}
    o = orthocal(*run_args(tmp_path, "--json", procedure=procedure), prepare=prepare)
    assert o.code in (0, 3), o.err
    result = json.loads(o.out)
    assert o.code == (3 if report.not_converged(result) else 0), o.err
    assert_right_answer(result)
    records = o.journal
    # four in the measurement, four in each verification (one mounting of leg x each)
    mountings = [r for r in records if r["type"] == "setup" and r["leg"] == "x"]
    assert len(mountings) >= 2 and len(knocked) == 4 * len(mountings)
    outliers = [r for r in records if r["type"] == "outlier"]
    knocks = [v for r in outliers for v in r["rejected"] if v - r["median"] > KNOCK_MM / 2]
    assert len(knocks) == len(knocked)  # each knock rejected, with its value on record
    for r in outliers:
        raw = next(x for x in records if x["type"] == "reading" and x["stop"] == r["stop"]
                   and x["indicator"] == r["indicator"])
        assert set(r["rejected"]) <= set(raw["values"])  # the raw reading is kept too
    assert result["timing"]["outliers_rejected"] >= len(knocked)
    assert result["verification"]["deviations_rms_mm"] < 0.005  # knocks left no trace


# --- a torn journal, reopened ----------------------------------------------------------


def _failed_run_with_torn_journal(tmp_path: Path, orthocal) -> tuple[Rig, CliOutcome, bytes]:
    """A run stopped by an alarm, whose journal then gets half a record, as a
    kill -9 in the middle of a write leaves it."""
    rig = Rig()
    failed = orthocal(*run_args(tmp_path), rig=rig,
                      prepare=lambda r, s: _alarm(s) if len(r.stations) == 1 else None)
    assert failed.code == 1
    path = failed.run_dir / "journal.jsonl"
    with open(path, "ab") as fh:
        fh.write(b'{"t":1,"type":"reading","stop":"m:1:1:+","indica')
    return rig, failed, path.read_bytes()


def test_torn_journal_survives_a_retry_before_the_resume_is_journaled(
        tmp_path: Path, orthocal) -> None:
    rig, failed, before = _failed_run_with_torn_journal(tmp_path, orthocal)

    def prepare(r: Rig, station: VirtualStation) -> None:
        station.controller.faults.drop_next = 1  # the resume's first request is retried

    o = orthocal("resume", str(failed.run_dir), "--json", rig=rig, prepare=prepare)
    assert o.code in (0, 3), o.err
    assert o.code == (3 if report.not_converged(json.loads(o.out)) else 0), o.err
    assert (failed.run_dir / "journal.jsonl").read_bytes().startswith(before)
    records = o.journal  # still readable: the fragment is followed by the resume
    assert records[-1]["type"] == "finished" and retry_events(records)


def test_torn_journal_survives_a_rollback(tmp_path: Path, orthocal) -> None:
    rig = Rig()
    # killed as it journaled the end of the run: the last record is torn
    done = orthocal(*run_args(tmp_path, procedure={**FAST, "verify": False}), rig=rig)
    assert done.code == 0, done.err
    path = done.run_dir / "journal.jsonl"
    lines = path.read_bytes().splitlines(keepends=True)
    assert json.loads(lines[-1])["type"] == "finished"
    path.write_bytes(b"".join(lines[:-1]) + lines[-1][:20])
    before = path.read_bytes()
    back = orthocal("rollback", str(done.run_dir), "--json", rig=rig)
    assert back.code == 0, back.err
    assert path.read_bytes().startswith(before)
    records = read_journal(path)  # still readable: the fragment is followed by the rollback
    assert [r.get("stage") for r in records if r["type"] == "rollback"] == ["intent", "done"]
    np.testing.assert_allclose(rig.stations[-1].offsets, [0.0, 0.0, 0.0], atol=1e-12)
