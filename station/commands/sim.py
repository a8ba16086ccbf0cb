"""``orthocal sim --config-out FILE``: the virtual station as its own process.

Runs until SIGINT/SIGTERM and writes a station config (TOML) pointing at it
(Modbus TCP on 127.0.0.1, or with ``--transport rtu`` Modbus RTU over a
pseudo-terminal pair whose client end the config names), so
``orthocal run --config FILE`` can rehearse the real workflow from another
terminal. A separate process cannot be told where the operator mounted the
gauges, so six fixed indicators stand two per leg, all mounted at once.
The drive moves as ``--motion`` and ``--drive-*`` say (station.commands.simulation), and
the config it writes tells the station only what an integrator would: that the
axes are coordinated, if they are, and the default acceleration. A map whose axes
are separate drives (unit ids) gets a drive that does not interpolate, as with
``run --simulate`` (``separate_drives``), and the config is checked by the rule
``run`` refuses by (station.plan.limits.motion_model) before it is written: what
``sim`` hands out, ``run --config`` accepts.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import signal
import sys
import threading
from pathlib import Path
from typing import Any

from drivers.sim.station import DEFAULT_MOUNT_ERROR_MM, VirtualStation
from station.commands.options import DriveOptions
from station.commands.simulation import (
    backlash_mm,
    drive_motion,
    drive_params,
    gaps_mm,
    gauge_scales,
    leg_bow_mm,
    map_profile,
    separate_drives,
    served_map,
    station_config,
)
from station.config import parse_config
from station.config.toml import dump_toml
from station.errors import BadInput
from station.plan.limits import motion_model

SIX_GAUGES = 6  # A..F, two per leg: what a separate process mounts (module docstring)


def main(args: argparse.Namespace) -> int:
    seed = args.seed if args.seed is not None else random.randrange(2**31)
    rng = random.Random(seed)
    drho = list(args.true_drho) if args.true_drho is not None else \
        [round(rng.uniform(-2.0, 2.0), 4) for _ in range(3)]
    dl = list(args.true_dl) if args.true_dl is not None else [0.0, 0.0, 0.0]
    tilt = list(args.true_tilt) if args.true_tilt is not None else [0.0, 0.0, 0.0]
    gap = gaps_mm(args.true_gap)
    noise = 0.002 if args.noise is None else args.noise
    if noise < 0:
        raise BadInput(f"--noise: must be >= 0 mm, got {noise}")
    mount_error = DEFAULT_MOUNT_ERROR_MM if args.mount_error is None else args.mount_error
    if not (math.isfinite(mount_error) and mount_error >= 0):
        raise BadInput(f"--mount-error: must be >= 0 mm, got {mount_error}")
    if args.speed is not None and not args.speed > 0:
        raise BadInput(f"--speed: must be > 0 mm/s, got {args.speed}")
    profile = map_profile(args.profile)
    # As run --simulate: axes on separate drives cannot move on one line.
    drive = drive_params(DriveOptions.from_args(args), separate_drives=separate_drives(profile))
    backlash = backlash_mm(args.backlash)
    bow = leg_bow_mm(args.leg_bow)
    scale = gauge_scales(args.gauge_scale, SIX_GAUGES)
    kwargs: dict[str, Any] = served_map(profile)
    if args.speed is not None:
        kwargs["speed_mm_s"] = args.speed
    out = Path(args.config_out)
    stop = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        del signum, frame
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        try:
            station = VirtualStation(drho, dl, noise, seed, protocol=args.protocol,
                                     indicator_count=SIX_GAUGES, port=args.port, mount_all=True,
                                     mount_error_mm=mount_error,
                                     motion=drive_motion(drive),
                                     controller_options={"transport": args.transport},
                                     true_tilt=tilt, true_gap=gap, backlash=backlash,
                                     leg_bow=bow, gauge_scale=scale, **kwargs)
        except OSError as exc:
            raise BadInput(f"--port: cannot serve on 127.0.0.1:{args.port} ({exc})") from None
        with station:
            header = (f"orthocal sim (pid {os.getpid()}): seed {seed}, hidden Δρ = {drho} mm, "
                      f"ΔL = {dl} mm, tilts = {tilt} mrad, axis gaps = {gap} mm, noise "
                      f"{noise} mm, stands off by up to {mount_error} mm, lost motion "
                      f"{backlash} mm, legs bowed {bow} mm, gauge scale errors {scale}, "
                      f"drive {_describe(drive)}\n"
                      f"Use: orthocal run --config {out}")
            # Validated like any operator's config: what we hand out must load, and
            # its motion be one run accepts (checked by run's own rule).
            config = parse_config(station_config(station, {}), "orthocal sim")
            motion_model(config)
            out.write_text(dump_toml(config, header))
            link = (f"Modbus TCP on 127.0.0.1:{station.controller.port}"
                    if args.transport == "tcp" else
                    f"Modbus RTU on {station.controller.serial_port} "
                    f"({station.controller.baudrate} 8N1, a pseudo-terminal)")
            print(f"orthocal sim: {link}, "
                  f"{len(station.indicators)} indicators ({args.protocol}); "
                  f"config written to {out}", file=sys.stderr, flush=True)
            gaps = f", axis gaps = {gap} mm" if any(gap) else ""
            print(f"orthocal sim: hidden Δρ = {drho} mm, tilts = {tilt} mrad{gaps}; "
                  "stop with Ctrl-C", file=sys.stderr, flush=True)
            while not stop.wait(0.5):
                pass
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
    print("orthocal sim: stopped", file=sys.stderr)
    return 0


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
