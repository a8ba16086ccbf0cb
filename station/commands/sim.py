"""``orthocal sim --config-out FILE``: the virtual station as its own process.

Runs until SIGINT/SIGTERM and writes a station config (TOML) pointing at it
(Modbus TCP on 127.0.0.1, or with ``--transport rtu`` Modbus RTU over a
pseudo-terminal pair whose client end the config names; the gauges on
pseudo-terminals, or with ``--gauges tcp`` on sockets of 127.0.0.1 that the config
names as ``socket://`` URLs), so
``orthocal run --config FILE`` can rehearse the real workflow from another
terminal. A separate process cannot be told where the operator mounted the
gauges, so six fixed indicators stand two per leg, all mounted at once; with
``--joint-test`` three more stand on the carriages against step gauges whose faces
set themselves as the station asks (station.commands.simulate.station_setups).
The drive moves as ``--motion`` and ``--drive-*`` say (station.commands.simulate.launch), and
the config it writes tells the station only what an integrator would: that the
axes are coordinated, if they are, and the default acceleration. A map whose axes
are separate drives (unit ids) gets a drive that does not interpolate, as with
``run --simulate`` (``separate_drives``), and the config is checked by the rule
``run`` refuses by (station.plan.limits.motion_model) before it is written: what
``sim`` hands out, ``run --config`` accepts.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import random
import signal
import sys
import threading
from pathlib import Path
from typing import Any

from drivers.sim.gauge_lines import pseudo_terminals
from drivers.sim.specs import DriveSpec, GaugeSpec, MachineTruth
from station.commands.given_paths import file_to_write, write_new
from station.commands.options import DriveOptions
from station.commands.simulate.launch import (
    DEFAULT_MOUNT_ERROR_MM,
    DEFAULT_NOISE_MM,
    backlash_mm,
    drive_motion,
    drive_params,
    gaps_mm,
    gauge_line,
    gauge_scales,
    joint_lead,
    joint_pitch,
    leg_bow_mm,
    map_profile,
    separate_drives,
    served_map,
    station_config,
)
from station.commands.simulate.station_setups import JOINT_GAUGES, SimulatedStation, gauges_for
from station.config import parse_config
from station.config.toml import dump_toml
from station.errors import BadInput
from station.plan.limits import motion_model

SIX_GAUGES = 6  # A..F, two per leg: what a separate process mounts (module docstring)


def main(args: argparse.Namespace) -> int:
    seed = args.seed if args.seed is not None else random.randrange(2**31)
    truth, drive_spec, gauges, drive = _specs(args, seed)
    out = Path(args.config_out)
    # Before the station starts: a config there is the user's (never overwritten, as
    # init), a folder that is not there or takes no file is bad input.
    file_to_write("--config-out", out, replace=False)
    stop = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        del signum, frame
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            station = SimulatedStation(truth, drive_spec, gauges, seed=seed)
        except OSError as exc:
            raise BadInput(f"--port: cannot serve on 127.0.0.1:{args.port} ({exc})") from None
        with station:
            if args.joint_test:
                station.stand_joint_gauges()
            header = (f"orthocal sim (pid {os.getpid()}): seed {seed}, "
                      f"{_hidden(truth, gauges)}, drive {_describe(drive)}\n"
                      f"Use: orthocal run --config {out}")
            # Validated like any operator's config: what we hand out must load, and
            # its motion be one run accepts (checked by run's own rule).
            config = parse_config(station_config(station, {}), "orthocal sim")
            motion_model(config)
            write_new("--config-out", out, dump_toml(config, header))
            _announce(args, station, out, truth)
            while not stop.wait(0.5):
                pass
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
    print("orthocal sim: stopped", file=sys.stderr)
    return 0


def _specs(args: argparse.Namespace, seed: int
           ) -> tuple[MachineTruth, DriveSpec, GaugeSpec, dict[str, Any]]:
    """The virtual station the options ask for (BadInput naming the option), and
    its drive's behaviour as drive_params gives it."""
    rng = random.Random(seed)
    drho = list(args.true_drho) if args.true_drho is not None else \
        [round(rng.uniform(-2.0, 2.0), 4) for _ in range(3)]
    # the documented default (docs/design.md, --noise), the same as run --simulate's
    noise = DEFAULT_NOISE_MM if args.noise is None else args.noise
    if noise < 0:
        raise BadInput(f"--noise: must be >= 0 mm, got {noise}")
    mount_error = DEFAULT_MOUNT_ERROR_MM if args.mount_error is None else args.mount_error
    if not (math.isfinite(mount_error) and mount_error >= 0):
        raise BadInput(f"--mount-error: must be >= 0 mm, got {mount_error}")
    if args.speed is not None and not args.speed > 0:
        raise BadInput(f"--speed: must be > 0 mm/s, got {args.speed}")
    profile = map_profile(args.profile)
    line = gauge_line(args.gauges)
    if args.transport == "rtu" and not pseudo_terminals():
        raise BadInput("--transport rtu: the virtual drive's RTU line is a pseudo-terminal "
                       "pair, which this system lacks; give --transport tcp")
    # As run --simulate: axes on separate drives cannot move on one line.
    drive = drive_params(DriveOptions.from_args(args), separate_drives=separate_drives(profile))
    zero = (0.0, 0.0, 0.0)
    truth = MachineTruth(drho=drho, dl=zero if args.true_dl is None else args.true_dl,
                         tilt=zero if args.true_tilt is None else args.true_tilt,
                         gap=gaps_mm(args.true_gap),
                         backlash=backlash_mm(args.backlash), leg_bow=leg_bow_mm(args.leg_bow),
                         joint_lead=joint_lead(args.joint_lead),
                         joint_pitch=joint_pitch(args.joint_pitch))
    scale = gauge_scales(args.gauge_scale, SIX_GAUGES)
    kwargs: dict[str, Any] = served_map(profile)
    if args.speed is not None:
        kwargs["speed_mm_s"] = args.speed
    drive_spec = DriveSpec(motion=drive_motion(drive), port=args.port,
                           controller_options={"transport": args.transport}, **kwargs)
    gauges = gauges_for(SIX_GAUGES, GaugeSpec(protocol=args.protocol, noise_mm=noise,
                                              mount_error_mm=mount_error, scale=scale,
                                              line=line),
                        mounted=True)
    if args.joint_test:  # a gauge on each carriage for the joints' own test
        gauges = dataclasses.replace(gauges, names=(*gauges.names, *JOINT_GAUGES.values()),
                                     scale=[*scale, 0.0, 0.0, 0.0])
    return truth, drive_spec, gauges, drive


def _hidden(truth: MachineTruth, gauges: GaugeSpec) -> str:
    """The hidden machine and gauges, for the config's header line."""
    t = truth
    return (f"hidden Δρ = {list(t.drho)} mm, ΔL = {list(t.dl)} mm, tilts = {list(t.tilt)} "
            f"mrad, axis gaps = {list(t.gap)} mm, noise {gauges.noise_mm} mm, stands off by "
            f"up to {gauges.mount_error_mm} mm, lost motion {list(t.backlash)} mm, legs "
            f"bowed {list(t.leg_bow)} mm, gauge scale errors {gauges.scale}, joint leads "
            f"{list(t.joint_lead)} µm/m, joint pitch {list(t.joint_pitch)} (µm, mm)")


def _announce(args: argparse.Namespace, station: SimulatedStation, out: Path,
              truth: MachineTruth) -> None:
    """Where the station serves and what it hides, on stderr."""
    ctl = station.controller
    link = (f"Modbus TCP on 127.0.0.1:{ctl.port}" if args.transport == "tcp" else
            f"Modbus RTU on {ctl.serial_port} ({ctl.baudrate} 8N1, a pseudo-terminal)")
    lines = ("on pseudo-terminals" if station.gauge_spec.line == "pty" else
             "on TCP 127.0.0.1, socket:// URLs")
    print(f"orthocal sim: {link}, {len(station.indicators)} indicators ({args.protocol}, "
          f"{lines}); config written to {out}", file=sys.stderr, flush=True)
    gaps = f", axis gaps = {list(truth.gap)} mm" if any(truth.gap) else ""
    print(f"orthocal sim: hidden Δρ = {list(truth.drho)} mm, tilts = {list(truth.tilt)} "
          f"mrad{gaps}; stop with Ctrl-C", file=sys.stderr, flush=True)


def _describe(drive: dict[str, Any]) -> str:
    """The drive's behaviour in the config's header line (the config itself says
    nothing of it: that is the point)."""
    parts = [drive["motion"]]
    if drive["drive_profile"]:
        parts.append("profile " + ",".join(drive["drive_profile"]))
    if drive["drive_accel_mm_s2"]:
        parts.append("accel " + ",".join(f"{a:g}" for a in drive["drive_accel_mm_s2"])
                     + " mm/s²")
    if drive["drive_delays_s"]:
        parts.append("delays " + ",".join(f"{d:g}" for d in drive["drive_delays_s"]) + " s")
    if drive["drive_sequence"]:
        parts.append("sequence " + drive["drive_sequence"])
    return ", ".join(parts)
