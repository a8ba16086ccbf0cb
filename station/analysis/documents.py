"""The JSON objects the engine builds: journal records, driver events, the result
document and its sections, model.json.

They stay open dicts, values of any JSON type: a record carries fields of its own
(an event's, a write-back stage's), and what reads them back validates them against
the typed models of station.record (the journal's tagged union, the run result)."""

from __future__ import annotations

from typing import Any

#: One JSON object as the engine builds it or reads it back from the journal.
JsonObject = dict[str, Any]
