"""The journal's records (journal.jsonl, one JSON object per line) as a tagged union on
``type`` (docs/design.md, "The run record"). Every record carries ``t`` (Unix time,
s) and is fsynced before the station moves on; a resumed run replays them.

Every record is closed, and so is every object in it: its fields are declared, down
to the header's config (station.config's StationConfig), plan
(station.record.journal_plan) and simulation (station.record.simulated), an event's
body (station.record.journal_events, tagged by ``event``) and each stage of a
write-back or a rollback (tagged by ``stage``). The only open-ended objects are maps
keyed by data (a gauge, an axis, a parameter) with typed values.

The journal's shape has only grown: a field a later version added is optional where
it is declared, so a journal an older version wrote reads as it is
(tests/station/record/test_record.py reads one from the first version that ran). A
change that is not a field added would migrate the older lines in one place,
read_records (station.record.journal_file), before they are parsed."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter

from station.config import StationConfig
from station.record.journal_events import EventBody
from station.record.journal_plan import PlanRecord
from station.record.result_joints import StationTestRecord
from station.record.simulated import SimulationParams

Offsets = dict[str, float]  # axis (x, y, z) → zero offset, mm


class _Record(BaseModel):
    model_config = ConfigDict(extra="forbid")

    t: float = Field(description="when it was written, Unix time (s)")


class Header(_Record):
    type: Literal["header"]
    version: str = Field(description="orthocal's version")
    config: StationConfig = Field(description="the station config (config.toml's model)")
    plan: PlanRecord
    simulation: SimulationParams | None = Field(
        None, description="a simulated run's parameters (station.record.simulated)")
    started: str
    argv: list[str] | None = None


class SetupRecord(_Record):
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


class VerificationRecord(_Fit):
    """A verification round's identification and its verdict."""

    type: Literal["verification"]
    round: int | None = None
    phase: str | None = None
    deviations_rms_mm: float | None = None
    significant: list[str] | None = None
    verdict: str | None = None


class WritebackRecord(_Record):
    """One stage of a write-back round (its kinds below, each tagged by ``stage``);
    ``round``: k of the closed loop (absent before the closed loop: round 1)."""

    type: Literal["writeback"]
    stage: str
    round: int | None = None


class WritebackBackup(WritebackRecord):
    """The offsets the round starts from (round 1 also saves them to ``file``)."""

    stage: Literal["backup"]
    before: Offsets
    file: str | None = Field(None, description="the backup file")


class WritebackIntent(WritebackRecord):
    """The offsets the operator confirmed, journaled before any is written."""

    stage: Literal["intent"]
    before: Offsets
    written: Offsets


class WritebackDone(WritebackRecord):
    """Written, and ``written`` as read back."""

    stage: Literal["done"]
    before: Offsets
    written: Offsets


class WritebackSkipped(WritebackRecord):
    """Nothing to write (the model identifies no joint offsets)."""

    stage: Literal["skipped"]
    reason: str


class WritebackUnchanged(WritebackRecord):
    """Nothing written: the correction refused (beyond max_abs_offset_mm) or declined."""

    stage: Literal["refused", "declined"]
    reason: str
    before: Offsets


class WritebackFailed(WritebackRecord):
    """The write failed: ``failed-restored``, the backup written back; ``failed``, that
    failed too (the offsets are uncertain)."""

    stage: Literal["failed", "failed-restored"]
    reason: str
    before: Offsets


class WritebackInterrupted(WritebackRecord):
    """Ctrl-C during the write: the backup written back, the intent kept for resume."""

    stage: Literal["interrupted-restored"]
    before: Offsets


AnyWriteback = Annotated[
    WritebackBackup | WritebackIntent | WritebackDone | WritebackSkipped
    | WritebackUnchanged | WritebackFailed | WritebackInterrupted,
    Field(discriminator="stage"),
]


class Event(_Record):
    type: Literal["event"]
    event: EventBody = Field(description='{"event": its kind, and its own fields}')


class Finished(_Record):
    type: Literal["finished"]
    status: str | None = None
    message: str | None = None


class StoppedRecord(_Record):
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


class JointMounted(_Record):
    """The station's own test of ``joint``: the operator clamped ``gauge`` to its
    carriage against the reference's datum face and took every other gauge off."""

    type: Literal["joint-mount"]
    joint: str
    gauge: str
    operator_s: float | None = None
    position: list[float] | None = Field(None, description="the joints when mounted, mm")


class JointFace(_Record):
    """The operator set the reference's face ``face_mm`` (from its datum) at the plunger
    for the test's target ``target`` (its count of targets: the datum again)."""

    type: Literal["joint-face"]
    joint: str
    target: int
    face_mm: float
    operator_s: float | None = None


class JointUnmounted(_Record):
    """The operator took the test's gauge and reference off."""

    type: Literal["joint-unmount"]
    joint: str
    gauge: str
    operator_s: float | None = None


class JointTested(_Record):
    """A joint's own test done: its table as found (targets ascending, deviations
    actual − target from below and from above relative to the datum, their expanded
    uncertainty), not yet referred to Π0, and how it was found."""

    type: Literal["joint-test"]
    joint: str
    targets_mm: list[float]
    forward_um: list[float]
    reverse_um: list[float]
    u95_um: list[float]
    test: StationTestRecord


class Rollback(_Record):
    """A stage of the operator's rollback to the backed-up offsets."""

    type: Literal["rollback"]
    stage: str


class RollbackIntent(Rollback):
    stage: Literal["intent"]
    current: Offsets = Field(description="the offsets before the rollback")
    restore: Offsets = Field(description="the backed-up offsets it writes")


class RollbackDone(Rollback):
    stage: Literal["done"]
    restored: Offsets = Field(description="the offsets as read back")


AnyRollback = Annotated[RollbackIntent | RollbackDone, Field(discriminator="stage")]


JournalRecord = Annotated[
    Header | SetupRecord | Reading | Outlier | Cycle | SetupDone | Repeat | Identification
    | VerificationRecord | AnyWriteback | Event | Finished | StoppedRecord | Resumed | Homed
    | ReferenceCheck | SetupRedo | AnyRollback | JointMounted | JointFace | JointUnmounted
    | JointTested,
    Field(discriminator="type"),
]

#: Validates one journal line's object.
RECORD = TypeAdapter(JournalRecord)
