"""The configuration reference, docs/config-reference.md, rendered from the config's
models: every table and key with its type, default and range as pydantic checks them,
so that the page cannot drift from what a config may say. Each key's meaning is its
field's ``description`` where it has one, else its entry in ``MEANINGS``; a key with
neither, or a meaning left for a key that no longer exists, is an error
(tests/test_docs_site.py). Regenerate the page with
``python -m station.config.reference > docs/config-reference.md``."""

from __future__ import annotations

import types
import typing
from collections.abc import Iterator
from typing import Any, Literal

from annotated_types import Ge, Gt, Le, Lt, MaxLen, MinLen
from pydantic import BaseModel
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

from station.config import StationConfig

MEANINGS: dict[str, str] = {
    "station.operator": "Who calibrates: in result.json (`operator`), the journal and the "
    "report's header and certificate; `run --operator NAME` wins.",
    "machine.id": "The machine's serial: every run records it, and the history, `compare` "
    "and \"Since the last calibration\" go by it.",
    "machine.leg_length": "The legs' nominal length L, mm.",
    "machine.rho_min": "The stroke s of the test posture Π_i^−, mm from Π0 (joint "
    "coordinate L + s).",
    "machine.rho_max": "The stroke s of the test posture Π_i^+, mm from Π0.",
    "machine.workspace": "The box `[[xmin, xmax], [ymin, ymax], [zmin, zmax]]` (tool "
    "points, mm) over which accuracy at the tool is stated; absent: "
    "`[rho_min, rho_max]`³.",
    "controller.transport": "Modbus TCP or Modbus RTU (a serial line).",
    "controller.host": "The controller's address (TCP).",
    "controller.port": "The TCP port, or for RTU the serial device (`/dev/ttyUSB9`, "
    "`COM5`).",
    "controller.device_id": "The Modbus unit id; a register map may give each register "
    "its own.",
    "controller.profile": "The register map: a built-in name or a map file, a path "
    "relative to the config's folder ([Your drive](drive.md)).",
    "controller.offsets": "The zero offsets the station holds for a drive without "
    "Modbus-writable ones, mm: the last run's `offsets_final` "
    "([Offsets the station holds](drive.md#offsets-the-station-holds)).",
    "controller.registers": "`[controller.registers]`: single addresses overriding the "
    "map's, `NAME = address`.",
    "controller.timeout_s": "Per Modbus request, s.",
    "controller.reconnect_s": "How long a lost connection (a drive's power cut) is "
    "retried, s.",
    "controller.home_timeout_s": "The homing deadline when `run` or `resume` homes, s.",
    "controller.speed_mm_s": "Axis speed of the test moves (written before each move), "
    "mm/s.",
    "controller.accel_mm_s2": "The acceleration the station assumes for move deadlines "
    "and the run time, mm/s²; never for safety.",
    "controller.baudrate": "The RTU line's baud rate.",
    "controller.motion": "What a move promises: `coordinated` (the joints on the straight "
    "line) or `independent` (each axis monotone, any pace, any order); absent: what the "
    "map says ([Safety](safety.md)).",
    "controller.soft_min": "Joint mm, x/y/z: narrow the controller's soft limits (never "
    "widen them); the limits themselves where it has none.",
    "controller.soft_max": "As `soft_min`, the upper limits.",
    "indicators.name": "The gauge's name in setups, prompts and the record.",
    "indicators.port": "Any pyserial port or URL; better a stable "
    "`/dev/serial/by-id/...` path (see `reopen_s`).",
    "indicators.protocol": "The gauge's protocol; `generic` is described by the keys "
    "below.",
    "indicators.stroke_mm": "The plunger's travel, mm: the plan check keeps every move "
    "within it.",
    "indicators.preload_mm": "How far the plunger is pushed in at mounting, mm; absent: "
    "half the stroke.",
    "indicators.resolution_mm": "The gauge's resolution, mm.",
    "indicators.timeout_s": "Per reading, s.",
    "indicators.reopen_s": "How long a vanished port (an adapter pulled) is reopened by "
    "its path, s.",
    "indicators.baudrate": "Line setting; the protocol's own unless given (`generic` "
    "needs it).",
    "indicators.bytesize": "Line setting; the protocol's own unless given.",
    "indicators.parity": "Line setting; the protocol's own unless given.",
    "indicators.stopbits": "Line setting; the protocol's own unless given.",
    "indicators.request": "`generic`: the bytes that ask for a reading (required).",
    "indicators.terminator": "`generic`: what ends a reply.",
    "indicators.pattern": "`generic`: a regular expression with one group, the value "
    "(required).",
    "indicators.error_pattern": "`generic`: the gauge's error reply, at most one group "
    "(its code).",
    "indicators.unit": "`generic`: the reply's unit; value = number × scale × (1, 0.001, "
    "25.4).",
    "indicators.scale": "`generic`: a factor on the reply, e.g. −1 for a gauge counting "
    "the other way.",
    "indicators.mpe_mm": "The gauge's maximum permissible error over a deviation's span "
    "(its data sheet); absent: its family's typical figure, named as assumed.",
    "indicators.serial": "The gauge's serial number, for the certificate.",
    "setups.leg": "The leg the setup's gauges are mounted against.",
    "setups.indicators": "Gauge name → the direction it measures along, `\"-y\"` for a "
    "reversed mount.",
    "setups.at": "Where along the leg the gauges touch it, as the fraction of its length "
    "from the carriage's joint at Π0: the middle, or a second plane (0.75).",
    "procedure.cycles": "Cycles per setup (at most, with `target_std_error_mm`).",
    "procedure.readings": "Readings averaged at each stop.",
    "procedure.settle_s": "The wait after arriving, before reading, s.",
    "procedure.repeatability_mm": "A spread across cycles above this repeats the setup, "
    "then flags it.",
    "procedure.max_repeats": "How often a setup's cycles may be repeated.",
    "procedure.target_std_error_mm": "Adaptive cycles: a setup stops once every deviation "
    "is known to this standard error.",
    "procedure.outlier_k": "Readings beyond median ± k·1.4826·MAD at a stop are rejected "
    "and journaled.",
    "procedure.plunger_guard": "Watch the gauges while the axes move (each mounting's "
    "first cycle) and stop them before a plunger nears an end.",
    "procedure.plunger_margin_mm": "How close to either end of its stroke a plunger may "
    "come, mm.",
    "procedure.model": "The model identified; `auto`: the smallest the run's own noise "
    "supports ([Models](method.md#models)).",
    "procedure.method": "The identification: on the exact model, or its linearisation.",
    "procedure.verify": "Measure again after the write-back.",
    "procedure.max_iterations": "The closed loop's write-backs at most (1: no loop).",
    "procedure.converge_mm": "\"Converged\": every offset shown within this at 95 %, mm.",
    "procedure.max_extra_passes": "Further passes of a verification that cannot tell yet.",
    "procedure.max_cycles_in_mounting": "A verification's cycles per mounting at most; "
    "absent: cycles × (1 + max_extra_passes).",
    "procedure.strokes": "The stops Π_i(s) of a cycle, mm, within rho_min..rho_max, "
    "nonzero, unique; absent: rho_max and rho_min.",
    "procedure.approach": "The side every joint approaches a stop from "
    "([Lost motion](method.md#lost-motion)).",
    "procedure.approach_overrun_mm": "The last short leg of a move to a stop starts this "
    "far beyond it, mm.",
    "procedure.measure_reversal": "Read Π0 approached from the other side in every cycle: "
    "each joint's reversal.",
    "procedure.stand_tolerance_mm": "How far off the leg's middle a stand may be set by "
    "eye (±), mm; modelled, 0: placed exactly.",
    "writeback.max_abs_offset_mm": "Larger corrections, and a larger total, are refused, "
    "mm.",
    "writeback.objective": "`joints`: the paper's Δρ (legs parallel); `tool`: the offsets "
    "that leave the least tool-point error.",
    "writeback.frame": "How the tool-point error is stated: after a translation (tool "
    "offset touched off) or a rigid motion (parts aligned by probing).",
    "uncertainty.leg_straightness_mm": "The legs' straightness (a bow's sagitta), mm, one "
    "value or `[x, y, z]`.",
    "uncertainty.temperature_change_c": "The temperature change during the run, K.",
    "uncertainty.plunger_angle_deg": "How far a plunger may be off the leg's normal, "
    "degrees.",
    "uncertainty.joint_positioning_um_per_m": "A bound on an untested joint's positioning "
    "error per metre of travel from Π0, µm/m ([design.md, \"Joints\"](design.md#joints)).",
    "joints.tests": "Each joint's ISO 230-2 test as CSV, any subset of the joints "
    "(`{ x = \"x.csv\" }`), paths relative to the config's folder "
    "([design.md, \"Joints\"](design.md#joints)).",
    "joints.station_test": "The joints the station tests itself before the calibration, "
    "against `[joints.reference]` read with one of its gauges on each carriage "
    "([design.md, \"The station's own joint test\"](design.md#the-stations-own-joint-test)).",
    "joints.station_gauge": "The indicator on the carriage: one for all, or "
    "`{ x = \"A\", y = \"B\" }`; absent: the config's first.",
    "joints.station_repeats": "Approaches of each target from each side (ISO 230-2: five).",
    "joints.station_targets": "With gauge blocks, the targets over the joint's travel (ISO "
    "230-2's irregular spacing).",
    "joints.reference": "`[joints.reference]`: the length reference the station's own test "
    "reads.",
    "joints.reference.kind": "Gauge blocks (the station chooses the stacks), a step gauge "
    "(`faces_mm`) or a length bar (`length_mm`).",
    "joints.reference.faces_mm": "A step gauge's faces' calibrated distances from its "
    "first, mm, increasing.",
    "joints.reference.length_mm": "A length bar's calibrated length, mm.",
    "joints.reference.expansion_per_k": "The reference's linear expansion, 1/K (steel).",
    "joints.reference.temperature_c": "The reference's temperature during the test, °C: "
    "its lengths are taken at it; absent: 20 ± 5 °C, assumed and named.",
    "joints.reference.plunger": "The gauge's plunger along the joint: `-` toward lower ρ "
    "(the datum at the low end of the travel), `+` toward higher.",
    "history.url": "Where finished runs are recorded: a database URL (`sqlite:///…`, "
    "`postgresql://…`); absent: `history.sqlite` beside the runs.",
    "history.enabled": "Record finished runs in the history.",
    "report.figures": "false: report.html without its figures (`orthocal report RUN_DIR` "
    "draws them later).",
    "acceptance.tool_rms_um": "The shop's limit on the tool's RMS error after "
    "calibration, judged at 95 %, µm.",
    "acceptance.tool_max_um": "The shop's limit on the tool's largest error over the "
    "workspace, judged at 95 %, µm.",
}

UNCERTAINTY = ("Absent: the budget's default, listed in it as assumed ([Uncertainty "
               "budget](method.md#uncertainty-budget)).")

HEADER = """\
# Every key of the station config

<!-- Generated by station/config/reference.py from the config's models: do not edit.
     python -m station.config.reference > docs/config-reference.md -->

Every table and key the station config accepts, as the station checks it (station/config,
pydantic): any other key is an error naming it, and so is a value of the wrong type or out
of its range, exit 2 before anything moves. What the tables are for, with an example:
[The station config](configuration.md). This page is generated from the models, so it says
what the code checks.
"""


def _model(annotation: Any) -> type[BaseModel] | None:
    """The model a table or an array of tables holds, or None for a plain key."""
    for candidate in (annotation, *typing.get_args(annotation)):
        if isinstance(candidate, type) and issubclass(candidate, BaseModel):
            return candidate
    return None


def tables() -> Iterator[tuple[str, bool, type[BaseModel]]]:
    """(name, is an array of tables, model) of every table, in the config's order; a
    table inside a table (``joints.reference``) after it."""
    for name, info in StationConfig.model_fields.items():
        model = _model(info.annotation)
        if model is not None:
            yield name, typing.get_origin(info.annotation) is list, model
            for key, inner in model.model_fields.items():
                sub = _model(inner.annotation)
                if sub is not None and typing.get_origin(inner.annotation) is not list:
                    yield f"{name}.{key}", False, sub


def keys() -> list[str]:
    """Every key as ``table.key``."""
    return [f"{table}.{key}" for table, _, model in tables() for key in model.model_fields]


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(value) if isinstance(value, float) else str(value)


def _kind(annotation: Any, many: bool = False) -> str:
    """The TOML value a key takes, in words (``many``: as the items of a list)."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is Literal:
        return " or ".join(f"`{_toml(a)}`" for a in args)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_kind(a, many) for a in args if a is not type(None))
    if origin is list:
        return f"{'lists' if many else 'a list'} of {_kind(args[0], True)}"
    if origin is dict:
        return f"a table: name = {_kind(args[1])}"
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return "a table (below)"
    names = {bool: "`true` or `false`", int: "whole number", float: "number",
             str: "string"}
    name = names.get(annotation, str(annotation))
    return name if name.startswith("`") else f"{name}s" if many else f"a {name}"


def _bounds(info: FieldInfo) -> str:
    words = {Gt: ("gt", ">"), Ge: ("ge", "≥"), Lt: ("lt", "<"), Le: ("le", "≤")}
    out: list[str] = []
    for m in info.metadata:
        for kind, (attribute, sign) in words.items():
            if isinstance(m, kind):
                out.append(f"{sign} {_toml(getattr(m, attribute))}")
        if getattr(m, "pattern", None):
            out.append(f"matches `{m.pattern}`")
    low = next((m.min_length for m in info.metadata if isinstance(m, MinLen)), None)
    high = next((m.max_length for m in info.metadata if isinstance(m, MaxLen)), None)
    unit = "characters" if str in (info.annotation, *typing.get_args(info.annotation)) \
        else "items"
    if low is not None and low == high:
        out.append(f"{low} {unit}")
    elif low is not None and high is not None:
        out.append(f"{low} to {high} {unit}")
    elif low is not None:
        out.append("not empty" if low == 1 else f"at least {low} {unit}")
    elif high is not None:
        out.append(f"at most {high} {unit}")
    return ", ".join(out)


def _default(info: FieldInfo) -> str:
    if info.default is PydanticUndefined:
        return "none" if info.default_factory is not None else "required"
    return "absent" if info.default is None else f"`{_toml(info.default)}`"


def meaning(table: str, key: str, info: FieldInfo) -> str | None:
    text = info.description or MEANINGS.get(f"{table}.{key}")
    return f"{text} {UNCERTAINTY}" if text and table == "uncertainty" else text


def _row(table: str, key: str, info: FieldInfo) -> str:
    kind = _kind(info.annotation)
    bounds = _bounds(info)
    cells = (f"`{key}`", f"{kind}, {bounds}" if bounds else kind, _default(info),
             meaning(table, key, info) or "")
    return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"


def markdown() -> str:
    """docs/config-reference.md."""
    parts = [HEADER]
    for table, array, model in tables():
        head = f"[[{table}]]" if array else f"[{table}]"
        parts.append(f"\n## `{head}`\n\n| key | value | default | meaning |\n"
                     "|---|---|---|---|\n")
        parts.append("\n".join(_row(table, k, i) for k, i in model.model_fields.items())
                     + "\n")
    return "".join(parts)


if __name__ == "__main__":
    print(markdown(), end="")
