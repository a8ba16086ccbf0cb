"""``orthocal sim --config-out FILE``: the virtual station as its own process.

Runs until SIGINT/SIGTERM and writes a station config (TOML) pointing at it, so
``orthocal run --config FILE`` can rehearse the real workflow from another
terminal. A separate process cannot be told where the operator mounted the
gauges, so six fixed indicators stand two per leg, all mounted at once.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import sys
import threading
from pathlib import Path
from typing import Any

from drivers.sim.station import VirtualStation


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a valid TOML basic string
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(type(value).__name__)


def to_toml(config: dict[str, Any], header: str) -> str:
    lines = [f"# {line}" for line in header.splitlines()] + [""]
    for section in ("machine", "controller"):
        lines.append(f"[{section}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in config[section].items()]
        lines.append("")
    for array in ("indicators", "setups"):
        for item in config[array]:
            lines.append(f"[[{array}]]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in item.items()]
            lines.append("")
    for section in ("procedure", "writeback"):
        lines.append(f"[{section}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in config[section].items()]
        lines.append("")
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    from station.errors import BadInput

    seed = args.seed if args.seed is not None else random.randrange(2**31)
    rng = random.Random(seed)
    drho = list(args.true_drho) if args.true_drho is not None else \
        [round(rng.uniform(-2.0, 2.0), 4) for _ in range(3)]
    dl = list(args.true_dl) if args.true_dl is not None else [0.0, 0.0, 0.0]
    noise = 0.002 if args.noise is None else args.noise
    if noise < 0:
        raise BadInput(f"--noise: must be >= 0 mm, got {noise}")
    if args.speed is not None and not args.speed > 0:
        raise BadInput(f"--speed: must be > 0 mm/s, got {args.speed}")
    kwargs: dict[str, Any] = {}
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
                                     indicator_count=6, port=args.port, mount_all=True,
                                     **kwargs)
        except OSError as exc:
            raise BadInput(f"--port: cannot serve on 127.0.0.1:{args.port} ({exc})") from None
        with station:
            header = (f"orthocal sim (pid {os.getpid()}): seed {seed}, hidden Δρ = {drho} mm, "
                      f"ΔL = {dl} mm, noise {noise} mm\n"
                      f"Use: orthocal run --config {out}")
            out.write_text(to_toml(station.config(), header))
            print(f"orthocal sim: Modbus TCP on 127.0.0.1:{station.controller.port}, "
                  f"{len(station.indicators)} indicators ({args.protocol}); "
                  f"config written to {out}", file=sys.stderr, flush=True)
            print(f"orthocal sim: hidden Δρ = {drho} mm; stop with Ctrl-C",
                  file=sys.stderr, flush=True)
            while not stop.wait(0.5):
                pass
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)
    print("orthocal sim: stopped", file=sys.stderr)
    return 0
