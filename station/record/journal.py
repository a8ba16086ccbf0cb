"""The journal's records (journal.jsonl, one JSON object per line) as a tagged union on
``type`` (docs/design.md, "The run record"). Every record carries ``t`` (Unix time,
s) and is fsynced before the station moves on; a resumed run replays them.

The fields every consumer relies on are typed; a record may carry more (an event's
own fields, a write-back stage's), which the models keep."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter


class _Record(BaseModel):
    model_config = ConfigDict(extra="allow")

    t: float = Field(description="when it was written, Unix time (s)")


class Header(_Record):
    type: Literal["header"]
    config: dict[str, Any]
    plan: dict[str, Any]
    simulation: dict[str, Any] | None = None
    started: str


class Setup(_Record):
    """The operator mounted ``indicators`` (name → direction) on ``leg``, at the
    fraction ``at`` of its length from the carriage's joint (absent: the middle)."""

    type: Literal["setup"]
    phase: str
    setup: int
    leg: str
    indicators: dict[str, str]
    operator_s: float | None = None
    at: float | None = Field(None, description="a second gauge plane: the fraction of "
                             "the leg from its carriage's joint (absent: 0.5, the middle)")


class Reading(_Record):
    type: Literal["reading"]
    stop: str
    indicator: str
    values: list[float]


class Outlier(_Record):
    type: Literal["outlier"]
    stop: str
    indicator: str


class Cycle(_Record):
    type: Literal["cycle"]
    phase: str
    setup: int
    cycle: int
    deviations: dict[str, float]


class SetupDone(_Record):
    type: Literal["setup_done"]
    phase: str
    setup: int
    cycles: list[int]


class Repeat(_Record):
    type: Literal["repeat"]
    phase: str
    setup: int


class Identification(_Record):
    type: Literal["identification", "verification"]
    model: str
    parameters: dict[str, float | None]
    std_errors: dict[str, float | None]


class Writeback(_Record):
    type: Literal["writeback"]
    stage: str
    round: int | None = None


class Event(_Record):
    type: Literal["event"]
    event: dict[str, Any]


class Stopped(_Record):
    """The run ended (``finished``) or stopped on a fault or Ctrl-C."""

    type: Literal["finished", "aborted", "fault"]


class Other(_Record):
    """Records of the run's recovery and the operator's rollback."""

    type: Literal["resumed", "homed", "reference-check", "setup-redo", "rollback"]


JournalRecord = Annotated[
    Header | Setup | Reading | Outlier | Cycle | SetupDone | Repeat | Identification
    | Writeback | Event | Stopped | Other,
    Field(discriminator="type"),
]

#: Validates one journal line's object.
RECORD = TypeAdapter(JournalRecord)
