"""The run's result document on disk: result.json, the record (station.record.result.
RunResult) validated as it is written, atomically, in the record's field order, its
deviations in the report's (station.record.keys), NaN and infinities as null; and
read back, of any version, through the one way in (:func:`read_result`,
:func:`parse_result`): migrated to the current version, then validated."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, JsonValue, ValidationError

from drivers.files import write_atomic
from station.record.keys import dev_keys
from station.record.migrate import migrate
from station.record.result import SCHEMA_VERSION, RunResult
from station.record.result_base import JsonObject

__all__ = ["UnreadableResult", "dumps", "jsonable", "jsonable_value", "parse_result",
           "read_result", "section", "validated", "write_result"]

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
    if record.deviations is not None:  # a copy in the report's order, not a field set
        record = record.model_copy(update={"deviations": {
            k: record.deviations[k] for k in dev_keys(record.deviations)}})
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


class UnreadableResult(ValueError):
    """A result.json that is not a run's record this version can read, in one line
    naming the file (a command's bad input, exit 2)."""


def parse_result(doc: Mapping[str, object]) -> RunResult:
    """``doc`` (a result.json's object, of any version; numpy and NaN taken as JSON
    takes them) as the record: migrated (station.record.migrate) and validated as
    strictly as another tool reading the file would (JSON types, no strings taken for
    numbers). pydantic's ValidationError where it is not one; ``doc`` is left as it
    was."""
    values = jsonable_value(doc)
    assert isinstance(values, dict)
    return RunResult.model_validate_json(json.dumps(migrate(values), allow_nan=False),
                                         strict=True)


def read_result(path: Path) -> RunResult:
    """The record in the result.json at ``path``, of any version (:func:`parse_result`);
    UnreadableResult (one line naming the file) where it cannot be read, is not JSON,
    is of a later version than this one reads, or is not a run's record."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise UnreadableResult(f"{path}: cannot read ({exc.strerror})") from None
    except ValueError as exc:
        raise UnreadableResult(f"{path}: not a result document ({exc})") from None
    if not isinstance(doc, dict):
        raise UnreadableResult(f"{path}: not a result document (not a JSON object)")
    version = doc.get("schema_version")
    if isinstance(version, int) and not isinstance(version, bool) and version > SCHEMA_VERSION:
        raise UnreadableResult(f"{path}: schema_version {version}, written by a later "
                               f"orthocal (this one reads up to {SCHEMA_VERSION})")
    try:
        return parse_result(doc)
    except ValidationError as exc:  # edited by hand, or not a run's record
        raise UnreadableResult(f"{path}: not a result document ({first_error(exc)})") \
            from None


def first_error(exc: ValidationError) -> str:
    """The first of the record's complaints, in one line ("timing.wall_s: Field
    required, and 2 more")."""
    errors = exc.errors()
    first = errors[0]
    where = ".".join(str(p) for p in first["loc"])
    more = f", and {len(errors) - 1} more" if len(errors) > 1 else ""
    return f"{where}: {first['msg']}{more}"
