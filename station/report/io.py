"""The run's result document on disk: result.json, validated against the record
(station.record.result.RunResult) as it is written, atomically, in the record's
field order, NaN and infinities as null."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from drivers.files import write_atomic
from station.report.boundary import ResultLike, as_result, jsonable_value
from station.report.format import dev_keys

__all__ = ["jsonable", "jsonable_value", "write_result"]


def jsonable(result: ResultLike) -> dict[str, Any]:
    """The result as written to result.json (the record's field order, NaN → None),
    for callers that print it, e.g. ``--json``, so stdout and the file agree.
    Validated against the record: a field it does not declare, or a value of another
    type, raises pydantic's ValidationError (a bug of the engine, never a run's fault)."""
    record = as_result(result)
    data = record.model_dump(mode="json", exclude_unset=True)
    # The deviations in the report's order: the record keeps a map's order, and the
    # engine fills them in the order it measured.
    if record.deviations is not None:
        data["deviations"] = _in_order(data["deviations"])
    if record.verification is not None:
        data["verification"]["deviations"] = _in_order(data["verification"]["deviations"])
    return data


def _in_order(devs: dict[str, Any]) -> dict[str, Any]:
    return {k: devs[k] for k in dev_keys(devs)}


def write_result(result: ResultLike, run_dir: Path) -> Path:
    """Write ``run_dir/result.json`` atomically, validated (:func:`jsonable`); NaN
    and infinities become null."""
    path = Path(run_dir) / "result.json"
    data = jsonable(result)
    write_atomic(path, json.dumps(data, indent=2, ensure_ascii=False, allow_nan=False) + "\n")
    return path
