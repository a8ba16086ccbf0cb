"""Old result.json files read as the current version (station.record.result's
SCHEMA_VERSION): every reader of a result.json takes it through :func:`migrate`.

A file without ``schema_version`` was written before the schema (read as version 1,
which only added the field). Version 1 → 2 renames nothing: version 2 requires the
fields every run now writes, and a file of an older version lacks those that did
not exist when it was written. They are filled with what that run had where that is
known (a simulation without tilts, gaps, lost motion, bowed legs or gauge scale
errors had none of them: 0, as station.record.simulated reads its journal; a loop
without extra passes had none; a simulation of any version without the joints'
screws had exact ones: 0) and with null where it is not (a verdict, a
squareness rule, a figure not computed then). Nothing present is changed, and a
document missing whole sections (a fragment, a run that stopped early) is migrated
as far as it goes: migrate() never validates."""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping

from pydantic import JsonValue

from station.record.result import SCHEMA_VERSION
from station.record.result_base import JsonObject

_AXES = ("x", "y", "z")
#: Version 2's fields per section that version 1 files may lack, filled with null.
_NULL_IN_V1 = {
    "timing": ("mountings", "operator_s"),
    "loop": ("converged_within_mm",),
    "model_selection": ("allowance",),
    "accuracy": ("best_offsets_can_do", "squareness_decision", "gaps", "gap_std_errors",
                 "gap_interval_95", "gap_advice", "compensated"),
}
_ITERATION_NULLS = ("fit_ok", "shown_within_95_mm", "verdict")
_TOP_NULLS = ("offsets_final", "offsets_held_by")


def migrate(doc: Mapping[str, object]) -> JsonObject:
    """``doc`` (a result.json's object, of any version) as version SCHEMA_VERSION; a
    copy: ``doc`` is left as it was. A file of a later version is returned as it is."""
    out: JsonObject = copy.deepcopy(dict(doc))  # type: ignore[arg-type]
    version = out.get("schema_version") or 1
    if not isinstance(version, int) or version > SCHEMA_VERSION:
        return out
    for step in _STEPS[version - 1:]:
        step(out)
    _fill(out)
    return out


def _fill(doc: JsonObject) -> None:
    """What the current version added as optional fields, filled where a file of it
    (or of an older one) lacks them: a simulation's screws were exact."""
    sim = doc.get("simulation")
    if isinstance(sim, dict):
        exact: tuple[tuple[str, JsonValue], ...] = (
            ("joint_lead_um_per_m", dict.fromkeys(_AXES, 0.0)), ("joint_pitch_um", 0.0),
            ("joint_pitch_period_mm", 0.0))
        for key, none in exact:
            if sim.get(key) is None:
                sim[key] = none


def _to_2(doc: JsonObject) -> None:
    """Version 1 → 2: fill what version 2 requires and version 1 files may lack."""
    if doc.get("status") is not None:  # a run's record, not a fragment of one
        for key in _TOP_NULLS:
            doc.setdefault(key, None)
    machine = doc.get("machine")
    if isinstance(machine, dict):
        machine.setdefault("id", None)
    for name, keys in _NULL_IN_V1.items():
        section = doc.get(name)
        if isinstance(section, dict) and "error" not in section:
            for key in keys:
                section.setdefault(key, None)
    loop = doc.get("loop")
    if isinstance(loop, dict):
        loop.setdefault("extra_passes", 0)
        loop.setdefault("max_extra_passes", 0)
    for entry in _objects(doc.get("iterations")):
        for key in _ITERATION_NULLS:
            entry.setdefault(key, None)
    if isinstance(doc.get("simulation"), dict):
        _simulation_to_2(doc)
    doc["schema_version"] = 2


def _simulation_to_2(doc: JsonObject) -> None:
    """A simulation of an older version: each hidden error it does not name (or names
    as null) was not simulated."""
    sim = doc["simulation"]
    assert isinstance(sim, dict)
    gauges = sorted({name for setup in _objects(doc.get("setups"))
                     for name in _object(setup.get("indicators"))})
    zeros: dict[str, JsonObject | float] = {
        "true_tilt": dict.fromkeys(("tilt_yx", "tilt_zx", "tilt_zy"), 0.0),
        "true_gap": dict.fromkeys(("gap_xy", "gap_xz", "gap_yz"), 0.0),
        "mount_error_mm": 0.0,
        "backlash_mm": dict.fromkeys(_AXES, 0.0),
        "leg_bow_mm": dict.fromkeys(_AXES, 0.0),
        "gauge_scale": dict.fromkeys(gauges, 0.0),
    }
    for key, none in zeros.items():
        if sim.get(key) is None:
            sim[key] = none
    sim.setdefault("seed", None)


def _object(value: JsonValue) -> JsonObject:
    return value if isinstance(value, dict) else {}


def _objects(value: JsonValue) -> list[JsonObject]:
    """The objects of a list (an absent list: none)."""
    return [v for v in value if isinstance(v, dict)] if isinstance(value, list) else []


#: _STEPS[n - 1] takes a version n document to version n + 1.
_STEPS: tuple[Callable[[JsonObject], None], ...] = (_to_2,)
