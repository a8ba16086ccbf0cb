"""``orthocal init --out FILE [PORT ...] [--controller HOST:PORT | --config FILE]``: a
commented starter config from what ``orthocal probe`` finds.

Every gauge that answered becomes an ``[[indicators]]`` entry at its protocol;
setups are proposed for the gauges found (six: two per leg; fewer: two moved
from leg to leg; one: one direction per setup) and the operator edits which
gauge sits on which leg and which way round. A controller that answered gives
the ``[controller]`` table; one without readable soft limits gets commented
``soft_min``/``soft_max`` lines marked as required, because only the operator
knows the machine's limits. The text is loaded back through the config's own
validation before it is written, so ``orthocal run --config FILE --plan``
accepts it as written. An existing file is never overwritten.

``--config FILE`` probes what ``orthocal probe --config FILE`` probes (the same
code: :func:`station.commands.probe.gather`), and the starter config points at
that controller (its connection, map and ``[controller.registers]``) and keeps
what only the operator knows and that config already says: the machine's
geometry, the soft limits, the offsets the station holds, how the drive moves
(``motion``) and its timings, the gauges under their own names with what it says
of each (stroke, preload, serial, line settings; the protocol the port answers),
and its setups as given: which gauge on which leg, along which direction, with
its sign (``"-z"``, a reversed mount: dropping the sign would turn every reading
of that gauge over).

Every other value is the default of station.config (the documented one), read
from there rather than written again here.
"""

from __future__ import annotations

import argparse
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, get_args

from pydantic import BaseModel

from station.commands.given_paths import file_to_write
from station.commands.probe import gather
from station.config import (
    ControllerConfig,
    IndicatorConfig,
    MachineConfig,
    ProcedureConfig,
    StationConfig,
    WritebackConfig,
    load_config,
    parse_config,
    with_map_file,
)
from station.config.toml import toml_value as v
from station.errors import BadInput

NAMES = "ABCDEFGHIJKLMNOPQRSTUVWXYZ"
COMMENT_COLUMN = 31  # where the comments of the key lines start


def _default(table: type[BaseModel], key: str) -> Any:
    """The documented default of ``key`` in a table of station.config."""
    return table.model_fields[key].default


def _line(key: str, value: Any, comment: str = "") -> str:
    """``key = value`` as TOML, with its comment aligned."""
    text = f"{key} = {v(value)}"
    return f"{text.ljust(COMMENT_COLUMN - 1)} # {comment}" if comment else text


def _machine_id(args: argparse.Namespace, machine: MachineConfig) -> list[str]:
    """The machine's serial: recorded in every run and its history, checked by compare."""
    known = getattr(args, "machine_id", None) or machine.id
    if known:
        return [_line("id", known, "the machine's serial (its runs' history)")]
    return ['# id = "SERIAL"                # EDIT: the machine\'s serial, so that its runs '
            "form a history (orthocal history, orthocal compare)"]


def _defaults(table: type[BaseModel], *keys: tuple[str, str]) -> list[str]:
    """The lines of ``keys`` ((key, comment) pairs) at their defaults."""
    return [_line(key, _default(table, key), comment) for key, comment in keys]


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


def _controller_lines(found: dict[str, Any] | None, args: argparse.Namespace,
                      config: StationConfig | None = None) -> list[str]:
    lines = ["[controller]"]
    answered = found is not None and "error" not in found
    spec = args.controller
    given = config.controller if config is not None else None
    if given is not None:
        lines.append(f"# The controller of {args.config}")
        if given.transport == "rtu":
            lines += ['transport = "rtu"', _line("port", given.port,
                                                 "the serial device of the RTU link"),
                      f"baudrate = {given.baudrate}"]
        else:
            lines += [_line("transport", "tcp", '"tcp" or "rtu"'), f"host = {v(given.host)}",
                      f"port = {given.port}"]
    elif spec and spec.startswith(("/", "COM")):
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
    device_id = given.device_id if given is not None else args.device_id
    profile = given.profile if given is not None else getattr(args, "profile", None)
    lines += [f"device_id = {device_id}", _profile_line(profile, Path(args.out))]
    for key, comment in (("timeout_s", "per Modbus request"),
                         ("speed_mm_s", "axis speed of the test moves")):
        value = _default(ControllerConfig, key) if given is None else getattr(given, key)
        lines.append(_line(key, value, comment))
    if given is not None:
        lines += _kept_controller(given)
    if given is not None and given.offsets is not None:
        lines.append(_line("offsets", given.offsets, "the offsets the station holds"))
    limits = (found or {}).get("soft_limits_mm") or {}
    # soft_min/soft_max the config gives: the operator's, kept as they are.
    kept = [] if given is None else [_line(key, getattr(given, key))
                                     for key in ("soft_min", "soft_max")
                                     if getattr(given, key) is not None]
    if answered and limits.get("lower") is not None:
        lines += ["# The controller reports its soft limits (mm): "
                  + "; ".join(f"{a} [{limits['lower'][a]:.3f}, {limits['upper'][a]:.3f}]"
                              for a in "xyz")]
        lines += kept or ["# soft_min = [..., ..., ...]   # narrow them (never widens)",
                          "# soft_max = [..., ..., ...]"]
    elif kept:
        why = limits.get("reason") if answered else (found or {}).get("error")
        lines += [f"# The controller's soft limits are unknown ({why or 'not probed'}); "
                  f"those of {args.config}:", *kept]
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
    if given is not None and given.registers:
        lines += ["", "[controller.registers]         # single addresses overriding the map's",
                  *(f"{name} = {address}" for name, address in given.registers.items())]
    return lines


#: [controller] keys a --config gives that init writes back as given, where given:
#: how the drive moves (``motion``: the plan's model of every move, which only the
#: operator knows for a real drive) and the timings the operator set for it.
_KEPT_CONTROLLER = {"motion": "how COMMAND 1 moves the axes",
                    "accel_mm_s2": "the acceleration deadlines assume",
                    "reconnect_s": "how long a lost connection is retried",
                    "home_timeout_s": "deadline of homing"}


def _kept_controller(given: ControllerConfig) -> list[str]:
    return [_line(key, getattr(given, key), comment)
            for key, comment in _KEPT_CONTROLLER.items()
            if key in given.model_fields_set and getattr(given, key) is not None]


#: Settings of an [[indicators]] entry that belong to its protocol: kept only while
#: the gauge answers the protocol the config names.
_LINE_KEYS = {"protocol", "baudrate", "bytesize", "parity", "stopbits", "request",
              "terminator", "pattern", "error_pattern", "unit", "scale"}


def _config_gauges(found: dict[str, Any], config: StationConfig, source: str) -> list[str]:
    """--config: that config's gauges under their own names (its setups name them),
    each with what the config says of it (stroke, preload, serial, line settings);
    the protocol the one its port answered where that is another (then without the
    config's line settings, which were for the other protocol). A gauge that did not
    answer is kept as given, with why: it may be unplugged for now."""
    by_port = {ind["port"]: ind for ind in found["indicators"]}
    out: list[str] = []
    for ind in config.indicators:
        seen = by_port.get(ind.port) or {}
        keys = ind.model_fields_set - {"name", "port"}
        if ind.preload_mm == ind.stroke_mm / 2:
            keys.discard("preload_mm")  # the validator's default: stroke/2 follows stroke
        given = ind.model_dump(include=keys, exclude_none=True)
        given.setdefault("stroke_mm", ind.stroke_mm)  # EDIT-worthy: always written
        if seen.get("protocol") is None:
            head = [f"# {ind.port}: no gauge ({seen.get('reason') or 'not probed'}); "
                    f"as {source} gives it", "[[indicators]]"]
            given.setdefault("protocol", ind.protocol)
        else:
            reading = "" if seen["reading_mm"] is None else \
                f", reading {seen['reading_mm']:+.4f} mm"
            head = [f"[[indicators]]                 # answered at {seen['line']}{reading}"]
            if seen["protocol"] != ind.protocol:
                head.insert(0, f"# {source} said protocol {ind.protocol!r}; the gauge "
                            f"answers {seen['protocol']!r}")
                given = {k: v for k, v in given.items() if k not in _LINE_KEYS}
            given["protocol"] = seen["protocol"]
        order = ["protocol", *(k for k in IndicatorConfig.model_fields if k in given
                               and k != "protocol")]
        out += ["", *head, f"name = {v(ind.name)}", f"port = {v(ind.port)}",
                *(_line(k, given[k]) for k in order)]
    return out


def _setup_lines(config: StationConfig | None, names: list[str],
                 source: str | None) -> list[str]:
    """The [[setups]]: --config's as it gives them, each gauge's direction with its
    sign (a reversed mount stays reversed), and the plane where not the middle; else
    proposed for the gauges found."""
    if config is None:
        out = ["", "# Setups proposed for the gauges found: one [[setups]] per mounting; the",
               "# operator is prompted before each to mount its gauges at the middle of the",
               "# leg at Π0 and remove the others. EDIT which gauge sits on which leg, and",
               '# the direction each measures along ("-y" if mounted reversed).']
        for leg, inds in propose_setups(names):
            out += ["[[setups]]", f"leg = {v(leg)}", f"indicators = {v(inds)}", ""]
        return out
    out = ["", f"# The setups of {source}, as it gives them: which gauge sits on which leg,",
           '# and the direction each measures along ("-y": mounted reversed).']
    for setup in config.setups:
        out += ["[[setups]]", f"leg = {v(setup.leg)}",
                f"indicators = {v(dict(setup.indicators))}"]
        if "at" in setup.model_fields_set:
            out.append(_line("at", setup.at, "the gauge plane, from the carriage's joint"))
        out.append("")
    return out


def _profile_line(profile: str | None, out: Path) -> str:
    """The profile: the built-in map, or the map file (``--profile``, or the
    ``--config``'s) as a path from the folder of ``out`` (where the station looks
    for it)."""
    from drivers.map_files import is_map_file

    if not profile:
        return (f"profile = {v(_default(ControllerConfig, 'profile'))}   # built-in register "
                "map (docs/design.md)")
    if not is_map_file(profile):
        return f"profile = {v(profile)}   # built-in register map"
    here = out.resolve().parent
    path = Path(profile).resolve()
    try:
        shown = str(path.relative_to(here))
    except ValueError:
        shown = str(path)
    return (f"profile = {v(shown)}   # the drive's register map file (from this config's "
            "folder)")


def render(found: dict[str, Any], args: argparse.Namespace,
           config: StationConfig | None = None) -> str:
    """The starter config's text; ``config``: that of ``--config``, whose controller
    was probed (module docstring)."""
    gauges = [ind for ind in found["indicators"] if ind["protocol"] is not None]
    silent = [ind for ind in found["indicators"] if ind["protocol"] is None]
    names = [NAMES[i] for i in range(min(len(gauges), len(NAMES)))]
    stamp = datetime.now(UTC).astimezone().isoformat(timespec="seconds")
    probe = "orthocal probe" if config is None else f"orthocal probe --config {args.config}"
    machine = config.machine if config is not None else MachineConfig()
    stroke = _default(IndicatorConfig, "stroke_mm")
    out = [
        f"# orthocal station config, written by `orthocal init` on {stamp}",
        f"# from what `{probe}` found. Check every line marked EDIT, then:",
        f"#   orthocal run --config {args.out} --plan     (lists and checks, moves nothing)",
        f"#   orthocal run --config {args.out}            (the calibration)",
        "# Every key is checked: a typo stops `orthocal run` with exit 2 naming the field.",
        "",
        "[machine]                      # EDIT: your machine's nominal geometry (mm)",
        *_machine_id(args, machine),
        _line("leg_length", machine.leg_length),
        _line("rho_min", machine.rho_min, "stroke of Π_i^− from Π0 (joint at L + rho_min)"),
        _line("rho_max", machine.rho_max, "stroke of Π_i^+ from Π0 (joint at L + rho_max)"),
        "",
    ]
    out += _controller_lines(found["controller"], args, config)
    out += ["", "# One [[indicators]] table per gauge found. stroke_mm: EDIT to your gauge's",
            "# plunger travel; preload_mm: how far it is pushed in at mounting (default",
            "# stroke/2). The plan check refuses moves beyond the stroke."]
    if config is not None:
        out += _config_gauges(found, config, str(args.config))
    elif not gauges:
        out += ["# EDIT: no gauge answered on any port probed; set the ports (and protocols).",
                "[[indicators]]", 'name = "A"', 'port = "/dev/ttyUSB0"',
                'protocol = "mitutoyo"          # mitutoyo | sylvac | mahr | generic',
                _line("stroke_mm", stroke), "",
                "[[indicators]]", 'name = "B"', 'port = "/dev/ttyUSB1"',
                'protocol = "mitutoyo"', _line("stroke_mm", stroke)]
        names = ["A", "B"]
    if config is None:
        for name, ind in zip(names, gauges, strict=False):
            reading = "" if ind["reading_mm"] is None else \
                f", reading {ind['reading_mm']:+.4f} mm"
            out += ["", f"[[indicators]]                 # answered at {ind['line']}{reading}",
                    f"name = {v(name)}", f"port = {v(ind['port'])}",
                    f"protocol = {v(ind['protocol'])}", _line("stroke_mm", stroke)]
        for ind in silent:
            out.append(f"# {ind['port']}: no gauge ({ind['reason']})")
    out += _setup_lines(config, names, getattr(args, "config", None))
    models = get_args(ProcedureConfig.model_fields["model"].annotation)
    methods = get_args(ProcedureConfig.model_fields["method"].annotation)
    out += [
        "[procedure]",
        *_defaults(ProcedureConfig,
                   ("cycles", "Π0 → Π+ → Π− → Π0 cycles per setup (at most)"),
                   ("readings", "readings averaged at each stop"),
                   ("settle_s", "wait after arriving before reading"),
                   ("repeatability_mm", "spread across cycles above this: repeat, then flag")),
        "# model: auto, the smallest model the run's own noise supports "
        '(docs/method.md, "Models"),',
        "# or one of " + " | ".join(m for m in models if m != "auto"),
        *_defaults(ProcedureConfig, ("model", ""), ("method", " | ".join(methods)),
                   ("verify", "measure again after write-back")),
        "",
        "[writeback]",
        *_defaults(WritebackConfig,
                   ("max_abs_offset_mm", "refuse larger corrections (nothing written)")),
        "",
        *UNCERTAINTY_LINES,
    ]
    return "\n".join(out)


#: The inputs the statement's uncertainty rests on, commented: a shop states what it
#: measured (docs/design.md, "Uncertainty budget"); left out, each is taken at the
#: default the run names as assumed, which on a tilted machine alone keeps the joints
#: from being shown within a few micrometres.
UNCERTAINTY_LINES = [
    "# What the run's uncertainty rests on (docs/design.md, \"Uncertainty budget\"). EDIT:",
    "# state what you measured. A line left commented is taken at the default shown and",
    "# named as assumed in the result; the defaults are cautious, and on a machine whose",
    "# axes lean the legs' straightness alone can keep the joints from being shown within",
    "# converge_mm (the run then says so and what to state). Each gauge's MPE and serial",
    "# go in its [[indicators]] table: mpe_mm = 0.003 (its data sheet or certificate,",
    "# default 0.003 mm for mitutoyo, sylvac and mahr) and serial = \"…\" (the certificate).",
    "[uncertainty]",
    "# leg_straightness_mm = 0.010  # the legs' straightness over the plunger's slide, read",
    "#                              #   as a bow's sagitta; one value or [x, y, z]",
    "# temperature_change_c = 0.5   # how much the room may change during a run, °C",
    "# plunger_angle_deg = 2.0      # how far a plunger may stand off the leg's normal",
    "",
    "# [acceptance]                 # the shop's limit on the tool after calibration, at 95 %",
    "# tool_rms_um = 10",
    "# tool_max_um = 25",
    "",
]


def main(args: argparse.Namespace) -> int:
    import tomllib

    out = Path(args.out)
    if out.exists():
        raise BadInput(f"--out: {out} exists; init never overwrites a config "
                       "(choose another name or remove it)")
    file_to_write("--out", out, replace=False)  # its folder, before the ports are probed
    found = gather(args)  # --config: its errors are probe's, one line, exit 2
    config = load_config(args.config) if getattr(args, "config", None) else None
    text = render(found, args, config)
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
