"""The JSON Schema of the run's documents, as ``orthocal schema`` prints it and as the
package ships it (station/record/schemas/*.schema.json, kept equal by a test)."""

from __future__ import annotations

import json
from pathlib import Path

from station.record.journal import RECORD
from station.record.model import MachineModel
from station.record.result import SCHEMA_VERSION, RunResult
from station.record.result_base import JsonObject

KINDS = ("result", "journal", "model")
SHIPPED = Path(__file__).parent / "schemas"


def json_schema(kind: str) -> JsonObject:
    """The JSON Schema (2020-12) of ``kind``: "result" (result.json), "journal" (one
    line of journal.jsonl) or "model" (model.json)."""
    if kind == "result":
        body: JsonObject = RunResult.model_json_schema()
    elif kind == "model":
        body = MachineModel.model_json_schema()
    elif kind == "journal":
        body = RECORD.json_schema()
        body["title"] = "JournalRecord"
    else:
        raise ValueError(f"schema: one of {', '.join(KINDS)}, got {kind!r}")
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": f"https://orthocal.invalid/schema/{kind}/v{SCHEMA_VERSION}",
            "schema_version": SCHEMA_VERSION, **body}


def dumps(kind: str) -> str:
    return json.dumps(json_schema(kind), indent=2, ensure_ascii=False, sort_keys=True) + "\n"


def shipped(kind: str) -> str:
    return (SHIPPED / f"{kind}.schema.json").read_text(encoding="utf-8")
