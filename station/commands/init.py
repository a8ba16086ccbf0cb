"""``orthocal init --out FILE [PORT ...] [--controller HOST:PORT]``: a commented
starter config from what ``orthocal probe`` finds.

Every gauge that answered becomes an ``[[indicators]]`` entry at its protocol;
setups are proposed for the gauges found (six: two per leg; fewer: two moved
from leg to leg; one: one direction per setup) and the operator edits which
gauge sits on which leg and which way round. A controller that answered gives
the ``[controller]`` table; one without readable soft limits gets commented
``soft_min``/``soft_max`` lines marked as required, because only the operator
knows the machine's limits. The text is loaded back through the config's own
validation before it is written, so ``orthocal run --config FILE --plan``
accepts it as written. An existing file is never overwritten.
"""

from __future__ import annotations

import argparse
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from station.commands.probe import gather
from station.config import parse_config, with_map_file
from station.config import toml_value as v
from station.errors import BadInput

NAMES = "ABCDEFGHIJKLMNOPQRSTUVWXYZ"


def propose_setups(names: list[str]) -> list[tuple[str, dict[str, str]]]:
    """(leg, {name: direction}) per setup for the gauges found. Directions are
    the two axes other than the leg's, plungers pointing the positive way."""
    if len(names) >= 6:
        a, b, c, d, e, f = names[:6]
        return [("x", {a: "y", b: "z"}), ("y", {c: "x", d: "z"}), ("z", {e: "x", f: "y"})]
    if len(names) >= 2:
        a, b = names[:2]
        return [("x", {a: "y", b: "z"}), ("y", {a: "x", b: "z"}), ("z", {a: "x", b: "y"})]
    a = names[0]
    return [(leg, {a: d}) for leg in "xyz" for d in "xyz" if d != leg]


def _controller_lines(found: dict[str, Any] | None, args: argparse.Namespace) -> list[str]:
    lines = ["[controller]"]
    answered = found is not None and "error" not in found
    spec = args.controller
    if spec and spec.startswith(("/", "COM")):
        lines += ['transport = "rtu"',
                  f"port = {v(spec)}                # the serial device of the RTU link",
                  f"baudrate = {args.baudrate}"]
    elif spec:
        host, _, port = spec.rpartition(":")
        lines += ['transport = "tcp"              # "tcp" or "rtu"',
                  f"host = {v(host)}", f"port = {int(port)}"]
    else:
        lines += ['transport = "tcp"              # "tcp" or "rtu"',
                  'host = "192.168.0.10"          # EDIT: no controller was probed '
                  "(orthocal init --controller HOST:PORT)",
                  "port = 502"]
    lines += [f"device_id = {args.device_id}", _profile_line(args),
              "timeout_s = 2.0                # per Modbus request",
              "speed_mm_s = 50.0              # axis speed of the test moves"]
    limits = (found or {}).get("soft_limits_mm") or {}
    if answered and limits.get("lower") is not None:
        lines += ["# The controller reports its soft limits (mm): "
                  + "; ".join(f"{a} [{limits['lower'][a]:.3f}, {limits['upper'][a]:.3f}]"
                              for a in "xyz"),
                  "# soft_min = [..., ..., ...]   # narrow them (never widens)",
                  "# soft_max = [..., ..., ...]"]
    elif answered:
        lines += ["# REQUIRED: the controller does not tell its soft limits: "
                  f"{limits.get('reason') or 'unknown'}.",
                  "# Copy them from the drive's parameters (joint mm, x, y, z) and "
                  "uncomment:",
                  "# soft_min = [200.0, 200.0, 200.0]",
                  "# soft_max = [380.0, 380.0, 380.0]"]
    else:
        why = (found or {}).get("error") or "not probed"
        lines += [f"# Controller: {why}.",
                  "# soft_min = [205.0, 205.0, 205.0]   # needed when the controller has no "
                  "soft-limit registers",
                  "# soft_max = [375.0, 375.0, 375.0]"]
    return lines


def _profile_line(args: argparse.Namespace) -> str:
    """The profile: the built-in map, or the map file of ``--profile`` as a path from
    the config's folder (where the station looks for it)."""
    from drivers.map_files import is_map_file

    profile = getattr(args, "profile", None)
    if not profile:
        return 'profile = "orthocal-generic"   # built-in register map (design.md)'
    if not is_map_file(profile):
        return f"profile = {v(profile)}   # built-in register map"
    here = Path(args.out).resolve().parent
    path = Path(profile).resolve()
    try:
        shown = str(path.relative_to(here))
    except ValueError:
        shown = str(path)
    return (f"profile = {v(shown)}   # the drive's register map file (from this config's "
            "folder)")


def render(found: dict[str, Any], args: argparse.Namespace) -> str:
    gauges = [ind for ind in found["indicators"] if ind["protocol"] is not None]
    silent = [ind for ind in found["indicators"] if ind["protocol"] is None]
    names = [NAMES[i] for i in range(min(len(gauges), len(NAMES)))]
    stamp = datetime.now(UTC).astimezone().isoformat(timespec="seconds")
    out = [
        f"# orthocal station config, written by `orthocal init` on {stamp}",
        "# from what `orthocal probe` found. Check every line marked EDIT, then:",
        f"#   orthocal run --config {args.out} --plan     (lists and checks, moves nothing)",
        f"#   orthocal run --config {args.out}            (the calibration)",
        "# Every key is checked: a typo stops `orthocal run` with exit 2 naming the field.",
        "",
        "[machine]                      # EDIT: your machine's nominal geometry (mm)",
        "leg_length = 310.25",
        "rho_min = -100.0               # Π_i^−: end point at ρmin·e_i",
        "rho_max = 60.0                 # Π_i^+: end point at ρmax·e_i",
        "",
    ]
    out += _controller_lines(found["controller"], args)
    out += ["", "# One [[indicators]] table per gauge found. stroke_mm: EDIT to your gauge's",
            "# plunger travel; preload_mm: how far it is pushed in at mounting (default",
            "# stroke/2). The plan check refuses moves beyond the stroke."]
    if not gauges:
        out += ["# EDIT: no gauge answered on any port probed; set the ports (and protocols).",
                "[[indicators]]", 'name = "A"', 'port = "/dev/ttyUSB0"',
                'protocol = "mitutoyo"          # mitutoyo | sylvac | mahr | generic',
                "stroke_mm = 12.5", "",
                "[[indicators]]", 'name = "B"', 'port = "/dev/ttyUSB1"',
                'protocol = "mitutoyo"', "stroke_mm = 12.5"]
        names = ["A", "B"]
    for name, ind in zip(names, gauges, strict=False):
        reading = "" if ind["reading_mm"] is None else f", reading {ind['reading_mm']:+.4f} mm"
        out += ["", f"[[indicators]]                 # answered at {ind['line']}{reading}",
                f"name = {v(name)}", f"port = {v(ind['port'])}",
                f"protocol = {v(ind['protocol'])}", "stroke_mm = 12.5"]
    for ind in silent:
        out.append(f"# {ind['port']}: no gauge ({ind['reason']})")
    out += ["", "# Setups proposed for the gauges found: one [[setups]] per mounting; the",
            "# operator is prompted before each to mount its gauges at the middle of the",
            "# leg at Π0 and remove the others. EDIT which gauge sits on which leg, and",
            '# the direction each measures along ("-y" if mounted reversed).']
    for leg, inds in propose_setups(names):
        out += ["[[setups]]", f"leg = {v(leg)}", f"indicators = {v(inds)}", ""]
    out += [
        "[procedure]",
        "cycles = 3                     # Π0 → Π+ → Π− → Π0 cycles per setup (at most)",
        "readings = 5                   # readings averaged at each stop",
        "settle_s = 0.3                 # wait after arriving before reading",
        "repeatability_mm = 0.02        # spread across cycles above this: repeat, then flag",
        'model = "rho"                  # rho | L | full',
        'method = "nonlinear"           # linear | nonlinear',
        "verify = true                  # measure again after write-back",
        "",
        "[writeback]",
        "max_abs_offset_mm = 3.0        # refuse larger corrections (nothing written)",
        "",
    ]
    return "\n".join(out)


def main(args: argparse.Namespace) -> int:
    import tomllib

    out = Path(args.out)
    if out.exists():
        raise BadInput(f"--out: {out} exists; init never overwrites a config "
                       "(choose another name or remove it)")
    found = gather(args)
    text = render(found, args)
    # What init hands out must load as it stands (its map file too, from its folder).
    with_map_file(parse_config(tomllib.loads(text), f"{out} (as generated)"),
                  out.resolve().parent, f"{out} (as generated)")
    try:
        with open(out, "x", encoding="utf-8") as fh:
            fh.write(text)
    except FileExistsError:
        raise BadInput(f"--out: {out} exists; init never overwrites a config") from None
    except OSError as exc:
        raise BadInput(f"--out: cannot write {out}: {exc.strerror}") from None
    gauges = sum(1 for ind in found["indicators"] if ind["protocol"] is not None)
    c = found["controller"]
    where = "no controller" if c is None else (
        f"controller {c['address']}: " + ("not reachable" if "error" in c else "answered"))
    print(f"orthocal init: wrote {out}: {gauges} gauge(s) of {len(found['indicators'])} "
          f"port(s), {where}. Edit the lines marked EDIT, then: "
          f"orthocal run --config {out} --plan", file=sys.stderr)
    return 0
