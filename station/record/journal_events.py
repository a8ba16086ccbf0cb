"""The bodies of the journal's ``event`` records, one closed model per kind, tagged
by ``event`` (docs/design.md, "The run record"): what the drivers report
(drivers.modbus_link, drivers.indicators: retries, a lost connection or port and
its return, the reference checked after it) and what the station notes (the
plunger guard's stops, what it learned and refused, its ways back, a cycle taken
again, a failed stop, a machine found unhomed).

A field that a later version added is optional: journals written before it lack it."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid")


# --- the drivers' -------------------------------------------------------------------------


class Retry(_Body):
    """A request tried again: the controller's (``op``) or a gauge's (``indicator``)."""

    event: Literal["retry"]
    device: str
    attempt: int = Field(description="the attempt that failed (1: the first)")
    error: str
    op: str | None = Field(None, description="the controller's request")
    indicator: str | None = Field(None, description="the gauge asked")
    port: str | None = Field(None, description="the gauge's serial port")


class Reconnect(_Body):
    """The controller's connection lost: one attempt to connect again failed."""

    event: Literal["reconnect"]
    device: str
    op: str
    error: str
    attempt: int
    elapsed_s: float


class Reconnected(_Body):
    event: Literal["reconnected"]
    device: str
    op: str
    attempts: int
    elapsed_s: float


class ControllerReferenceCheck(_Body):
    """After the connection came back: whether the drive lost its reference."""

    event: Literal["reference-check"]
    device: str
    lost: bool
    why: str | None = None


class Reopen(_Body):
    """A gauge's port gone: one attempt to open it again by its path failed."""

    event: Literal["reopen"]
    device: str
    indicator: str
    port: str
    attempt: int
    error: str
    elapsed_s: float


class Reopened(_Body):
    event: Literal["reopened"]
    device: str
    indicator: str
    port: str
    attempts: int
    elapsed_s: float


# --- the station's ------------------------------------------------------------------------


class StopFailed(_Body):
    """Stopping the axes on a fault failed too."""

    event: Literal["stop-failed"]
    error: str


class NotHomed(_Body):
    """The controller was found without its reference (resume homes it)."""

    event: Literal["not-homed"]
    device: str


class GuardStop(_Body):
    """The plunger guard stopped the axes mid-move."""

    event: Literal["plunger-guard"]
    indicator: str
    where: str
    move: str
    travel_mm: float
    predicted_mm: float
    end_mm: float
    margin_mm: float


class GuardLearned(_Body):
    """A mounting's first cycle done: the signal at its stops and the travel of its moves."""

    event: Literal["plunger-guard-learned"]
    where: str
    polls: int
    predicted_mm: dict[str, tuple[float, float]] = Field(
        description='"gauge move" → the plunger travel (lo, hi) predicted, mm')
    min_slack_mm: float | None = Field(None, description="null: no poll while moving")
    stop_signal_mm: dict[str, dict[str, float]] | None = Field(
        None, description="posture → gauge → its signal there, mm")


class GuardRefused(_Body):
    """A later cycle refused before it moved."""

    event: Literal["plunger-guard-refused"]
    indicator: str
    where: str
    move: str
    cycle: int
    margin_mm: float
    predicted_mm: float | None = None
    end_mm: float | None = None


class GuardRecovery(_Body):
    """A way back after the guard stopped the axes, and how it ended (``result``:
    "recovered", or why not)."""

    event: Literal["plunger-guard-recovery"]
    indicator: str
    where: str
    move: str
    from_: list[float] = Field(alias="from", description="the joints at rest, mm")
    readings_mm: dict[str, float]
    result: str
    back_to: list[float] | None = None
    zero_shift_mm: dict[str, float] | None = None
    signal_mm: dict[str, list[float]] | None = None
    waypoints: int | None = None
    speed_mm_s: float | None = None
    route: list[list[float]] | None = None

    model_config = ConfigDict(extra="forbid", populate_by_name=True,
                              serialize_by_alias=True)


class ZeroCheck(_Body):
    """A gauge's zero compared across a cycle the guard stopped."""

    event: Literal["plunger-guard-zero-check"]
    phase: str
    setup: int
    cycle: int
    limit_mm: float
    moved: bool
    zero_change_mm: dict[str, float]


class Retake(_Body):
    """A cycle's readings taken again (a gauge's zero moved across it)."""

    event: Literal["retake"]
    phase: str
    setup: int
    cycle: int
    stops: list[str]
    why: str


class MountKept(_Body):
    """The gauges of a round's last setup left on for the next round's first (kept),
    or taken down because the write-back's shift would not hold (``why``)."""

    event: Literal["mount-kept"]
    phase: str
    setup: int
    indicators: dict[str, str] = Field(description="indicator name → its direction")
    kept: bool
    why: str | None = Field(None, description="why not kept, in the plan check's words")
    travel_mm: dict[str, float] | None = Field(
        None, description="each gauge's travel at the setup's Π0 now, from its mounting")
    offsets: list[float] | None = Field(None, description="the offsets now, x, y, z (mm)")


EventBody = Annotated[
    Retry | Reconnect | Reconnected | ControllerReferenceCheck | Reopen | Reopened
    | StopFailed | NotHomed | GuardStop | GuardLearned | GuardRefused | GuardRecovery
    | ZeroCheck | Retake | MountKept,
    Field(discriminator="event"),
]
