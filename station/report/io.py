"""The run's result document on disk: result.json, validated against the record
(station.record.result.RunResult) as it is written, atomically, in the record's
field order, NaN and infinities as null."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from drivers.files import write_atomic
from station.record.result import RunResult
from station.report.format import dev_keys

# --------------------------------------------------------------------------- json


def jsonable_value(value: Any) -> Any:
    """Plain JSON types; NaN/inf become None because json.dumps would emit the
    invalid tokens NaN/Infinity that strict parsers (jq, JavaScript) reject."""
    if isinstance(value, Mapping):
        return {str(k): jsonable_value(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable_value(v) for v in value]
    if isinstance(value, bool) or value is None or isinstance(value, str | int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    # numpy scalars and arrays come from the identification; no numpy import needed.
    if hasattr(value, "tolist"):
        return jsonable_value(value.tolist())
    if hasattr(value, "isoformat"):
        return value.isoformat()
    raise TypeError(f"result field of type {type(value).__name__} is not JSON-serialisable")


def jsonable(result: Mapping[str, Any]) -> dict[str, Any]:
    """The result as written to result.json (the record's field order, NaN → None),
    for callers that print it, e.g. ``--json``, so stdout and the file agree.
    Validated against the record: a field it does not declare, or a value of another
    type, raises pydantic's ValidationError (a bug of the engine, never a run's fault)."""
    return as_record(result).model_dump(mode="json", exclude_unset=True)


def as_record(result: Mapping[str, Any]) -> RunResult:
    """The result as the record's model, validated as strictly as another tool reading
    the file would (JSON types, no coercion of strings to numbers)."""
    text = json.dumps(jsonable_value(_ordered(result)), allow_nan=False)
    return RunResult.model_validate_json(text, strict=True)


def _ordered(result: Mapping[str, Any]) -> dict[str, Any]:
    """The deviations in the report's order (the record keeps a map's order)."""
    out = dict(result)
    verification = out.get("verification")
    if isinstance(verification, dict):
        out["verification"] = verification = dict(verification)
    for section in (out, verification):
        if isinstance(section, dict) and isinstance(section.get("deviations"), dict):
            devs = section["deviations"]
            section["deviations"] = {k: devs[k] for k in dev_keys(devs)}
    return out


def write_result(result: dict, run_dir: Path) -> Path:
    """Write ``run_dir/result.json`` atomically, validated (:func:`jsonable`); NaN
    and infinities become null."""
    path = Path(run_dir) / "result.json"
    data = jsonable(result)
    write_atomic(path, json.dumps(data, indent=2, ensure_ascii=False, allow_nan=False) + "\n")
    return path
