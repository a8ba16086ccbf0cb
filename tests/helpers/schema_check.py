"""An independent validator (jsonschema) of the record's shipped schemas, as another tool
reading the run's files would check them; shared by the record's and the history's tests."""

from __future__ import annotations

import json
from functools import cache
from typing import Any

from jsonschema import Draft202012Validator

from station.record import schema_files as schema


@cache
def validator(kind: str) -> Draft202012Validator:
    """One validator per kind (checking the schema and building its validator for
    each of a run's hundreds of journal lines cost seconds)."""
    doc = json.loads(schema.shipped(kind))
    Draft202012Validator.check_schema(doc)
    return Draft202012Validator(doc)


def errors(kind: str, doc: dict[str, Any]) -> list[str]:
    """Every way ``doc`` breaks the shipped schema of ``kind``, one line each."""
    return [f"{'/'.join(map(str, e.absolute_path))}: {e.message}"
            for e in validator(kind).iter_errors(doc)]
