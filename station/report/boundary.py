"""The report's one way in: whatever the caller hands it (the record, or a
result.json read from disk, of any version) becomes the record's model,
station.record.result.RunResult, here and only here. Everything behind the public
entry points (summary_text, render_html, write_html, write_result, jsonable,
not_converged) reads the typed record; a document that is not one raises pydantic's
ValidationError before a line of the report is drawn. result.json itself is written
by the record (station.record.io)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from station.record import io
from station.record.result import RunResult
from station.record.result_base import JsonObject

#: What a public entry point of the report takes: the record, or a document that
#: becomes it (a result.json's object of any version).
ResultLike = RunResult | Mapping[str, object]


def as_result(doc: ResultLike) -> RunResult:
    """``doc`` as the record: the record itself as it is; a mapping through the
    record's one way in (station.record.io.parse_result): as JSON values (numpy to
    lists, NaN and infinities to null), migrated from its version and validated as
    strictly as another tool reading the file would. ``doc`` is left as it was."""
    if isinstance(doc, RunResult):
        return doc
    return io.parse_result(doc)


def jsonable(result: ResultLike) -> JsonObject:
    """The result as result.json holds it (station.record.io.jsonable)."""
    return io.jsonable(as_result(result))


def write_result(result: ResultLike, run_dir: Path) -> Path:
    """``run_dir/result.json`` (station.record.io.write_result)."""
    return io.write_result(as_result(result), run_dir)
