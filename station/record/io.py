"""The run's result document on disk: result.json, the record (station.record.result.
RunResult) validated as it is written, atomically, in the record's field order, its
deviations in the report's (station.record.keys), NaN and infinities as null."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, JsonValue

from drivers.files import write_atomic
from station.record.keys import dev_keys
from station.record.result import RunResult
from station.record.result_base import JsonObject

__all__ = ["dumps", "jsonable", "jsonable_value", "section", "validated", "write_result"]

Section = TypeVar("Section", bound=BaseModel)


def jsonable_value(value: object) -> JsonValue:
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


def section(model: type[Section], doc: Mapping[str, object]) -> Section:
    """A section the engine computes as a JSON object (accuracy, the budget, the model
    test) as the record's ``model``: numpy as lists, NaN as null, validated."""
    return model.model_validate(jsonable_value(doc))


def validated(result: RunResult) -> RunResult:
    """``result`` as result.json holds it: what was set of it, validated as strictly as
    another tool reading the file would (JSON types, no strings taken for numbers),
    its deviations in the report's order (the engine fills them in the order it
    measured). A field missing that every run writes, or a value of another type,
    raises pydantic's ValidationError: a bug of the engine, never a run's fault."""
    record = RunResult.model_validate_json(result.model_dump_json(exclude_unset=True),
                                           strict=True)
    if record.deviations is not None:
        record.deviations = {k: record.deviations[k] for k in dev_keys(record.deviations)}
    if record.verification is not None:
        devs = record.verification.deviations
        record.verification.deviations = {k: devs[k] for k in dev_keys(devs)}
    return record


def dumps(result: RunResult, indent: int | None = 2) -> str:
    """result.json's text (:func:`validated`), without its final newline."""
    return validated(result).model_dump_json(indent=indent, exclude_unset=True)


def jsonable(result: RunResult) -> JsonObject:
    """The result as written to result.json, as JSON values, for callers that print
    it (``--json``) or file it (the history), so they and the file agree."""
    data = json.loads(dumps(result, indent=None))
    assert isinstance(data, dict)
    return data


def write_result(result: RunResult, run_dir: Path) -> Path:
    """Write ``run_dir/result.json`` atomically, validated (:func:`validated`)."""
    path = Path(run_dir) / "result.json"
    write_atomic(path, dumps(result) + "\n")
    return path
