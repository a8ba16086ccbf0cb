"""The report's one way in: whatever the caller hands it (the engine's result as it
builds it, a result.json read from disk, of any version, or the record itself)
becomes the record's model, station.record.result.RunResult, here and only here.
Everything behind the public entry points (summary_text, render_html, write_html,
write_result, jsonable, not_converged) reads the typed record; a document that is
not one raises pydantic's ValidationError before a line of the report is drawn."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from typing import Any

from station.record.migrate import migrate
from station.record.result import RunResult

#: What a public entry point of the report takes: the record, or a document that
#: becomes it (the engine's dict, a result.json's object of any version).
ResultLike = RunResult | Mapping[str, Any]


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


def as_result(doc: ResultLike) -> RunResult:
    """``doc`` as the record: the record itself as it is; a mapping as JSON values
    (numpy to lists, NaN and infinities to null), migrated from its version
    (station.record.migrate: a no-op for the current one) and validated as strictly
    as another tool reading the file would (JSON types, no strings taken for
    numbers). ``doc`` is left as it was."""
    if isinstance(doc, RunResult):
        return doc
    text = json.dumps(migrate(jsonable_value(doc)), allow_nan=False)
    return RunResult.model_validate_json(text, strict=True)
