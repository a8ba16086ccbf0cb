"""The journal's records (journal.jsonl, one JSON object per line) as a tagged union on
``type`` (docs/design.md, "The run record"). Every record carries ``t`` (Unix time,
s) and is fsynced before the station moves on; a resumed run replays them.

Every record is closed: its fields are declared. What is a document of its own is a
JSON object here: the header's config, plan and simulation (station.config,
station.plan, station.record.simulated read them) and an event's body (retries,
the plunger guard's stops and recoveries, …: ``{"event": name, …}``)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter

from station.record.result_base import JsonObject


class _Record(BaseModel):
    model_config = ConfigDict(extra="forbid")

    t: float = Field(description="when it was written, Unix time (s)")


class Header(_Record):
    type: Literal["header"]
    version: str = Field(description="orthocal's version")
    config: JsonObject = Field(description="the station config (config.toml's model)")
    plan: JsonObject
    simulation: JsonObject | None = Field(
        None, description="a simulated run's parameters (station.record.simulated)")
    started: str
    argv: list[str] | None = None


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
    position: list[float] | None = Field(None, description="the joints when mounted, mm")


class Reading(_Record):
    type: Literal["reading"]
    stop: str
    indicator: str
    values: list[float]


class Outlier(_Record):
    type: Literal["outlier"]
    stop: str
    indicator: str
    rejected: list[float] | None = None
    median: float | None = None


class Cycle(_Record):
    type: Literal["cycle"]
    phase: str
    setup: int
    cycle: int
    deviations: dict[str, float]
    within_std: list[float] | None = Field(None, description="each stop's reading scatter")
    reversal_mm: dict[str, float] | None = Field(None, description="per joint, measured")


class SetupDone(_Record):
    type: Literal["setup_done"]
    phase: str
    setup: int
    cycles: list[int]
    repeats: int | None = None
    spread_mm: float | None = None
    flagged: bool | None = None


class Repeat(_Record):
    type: Literal["repeat"]
    phase: str
    setup: int
    spread_mm: float | None = None
    repeat: int | None = None


class _Fit(_Record):
    """A round's identification (station.engine.results.ident_json)."""

    model: str
    method: str | None = None
    parameters: dict[str, float | None]
    std_errors: dict[str, float | None]
    std_errors_dof: float | None = None
    residual_rms_mm: float | None = None
    passes: list[str] | None = Field(None, description="a round measured again")


class Identification(_Fit):
    """The first measurement's identification."""

    type: Literal["identification"]


class Verification(_Fit):
    """A verification round's identification and its verdict."""

    type: Literal["verification"]
    round: int | None = None
    phase: str | None = None
    deviations_rms_mm: float | None = None
    significant: list[str] | None = None
    verdict: str | None = None


class Writeback(_Record):
    """One stage of a write-back round (backup, intent, done, …)."""

    type: Literal["writeback"]
    stage: str
    round: int | None = None
    reason: str | None = None
    before: dict[str, float] | None = None
    written: dict[str, float] | None = None
    file: str | None = Field(None, description="the backup file")


class Event(_Record):
    type: Literal["event"]
    event: JsonObject = Field(description='{"event": its name, and its own fields}')


class Finished(_Record):
    type: Literal["finished"]
    status: str | None = None
    message: str | None = None


class Stopped(_Record):
    """The run stopped on Ctrl-C (``aborted``) or a fault."""

    type: Literal["aborted", "fault"]
    error: str | None = None
    device: str | None = None


class Resumed(_Record):
    type: Literal["resumed"]
    version: str | None = None
    argv: list[str] | None = None


class Homed(_Record):
    type: Literal["homed"]
    position: list[float] | None = None
    elapsed_s: float | None = None


class GaugeCheck(BaseModel):
    """A gauge at Π0 after homing against its last reading there."""

    model_config = ConfigDict(extra="forbid")

    now_mm: float
    then_mm: float
    difference_mm: float
    tolerance_mm: float


class ReferenceCheck(_Record):
    type: Literal["reference-check"]
    result: str
    phase: str | None = None
    setup: int | None = None
    gauges: dict[str, GaugeCheck] | None = None
    cycles: list[int] | None = None


class SetupRedo(_Record):
    type: Literal["setup-redo"]
    phase: str
    setup: int
    reason: str | None = None
    cycles_dropped: list[int] | None = None


class Rollback(_Record):
    """The operator's rollback to the backed-up offsets."""

    type: Literal["rollback"]
    stage: Literal["intent", "done"]
    current: dict[str, float] | None = None
    restore: dict[str, float] | None = None
    restored: dict[str, float] | None = None


JournalRecord = Annotated[
    Header | Setup | Reading | Outlier | Cycle | SetupDone | Repeat | Identification
    | Verification | Writeback | Event | Finished | Stopped | Resumed | Homed
    | ReferenceCheck | SetupRedo | Rollback,
    Field(discriminator="type"),
]

#: Validates one journal line's object.
RECORD = TypeAdapter(JournalRecord)
