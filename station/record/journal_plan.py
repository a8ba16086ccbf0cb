"""The journal header's ``plan``: the checked plan as station.plan.steps.Plan.to_json
writes it, every field declared (docs/design.md, "The run record"). Its steps are the
measurement phase's, tagged by ``kind``.

A field that a later version added is optional: journals written before it lack it
(soft limits' ``source``, the controller's path model ``motion``, a move's
``approach`` and ``via``, a prompt's ``at``, ``test_postures``, ``station_test``)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from station.record.result_base import Closed

JointTriple = tuple[float, float, float]  # x, y, z, mm



class SoftLimits(Closed):
    lower: list[float]
    upper: list[float]
    source: str | None = Field(None, description="whose limits: the controller's, the config's")


class SetupPostures(Closed):
    index: int
    leg: str
    indicators: dict[str, str] = Field(description="gauge → its direction (y, -z, …)")
    postures: dict[str, JointTriple] = Field(description='posture ("0", "+", "-", "+30") → joints')


class PromptStep(Closed):
    """The operator mounts the setup's gauges."""

    kind: Literal["prompt"]
    setup: int
    leg: str
    indicators: list[tuple[str, str]] = Field(description="(gauge, direction) as mounted")
    at: float | None = Field(None, description="the gauges' place along the leg")


class MoveStep(Closed):
    kind: Literal["move"]
    targets: JointTriple
    label: str
    approach: JointTriple | None = Field(None, description="where the last short leg starts")
    via: list[JointTriple] | None = Field(None, description="the waypoints the check put on it")


class SettleStep(Closed):
    kind: Literal["settle"]
    seconds: float


class ReadStep(Closed):
    kind: Literal["read"]
    stop: str
    setup: int
    cycle: int
    sign: str
    indicators: list[str]
    n: int


class CheckpointStep(Closed):
    kind: Literal["checkpoint"]
    setup: int
    cycle: int
    label: str


PlanStep = Annotated[PromptStep | MoveStep | SettleStep | ReadStep | CheckpointStep,
                     Field(discriminator="kind")]


class JointTestPlanRecord(Closed):
    """One joint's own test as planned and checked (station.plan.joint_test_plan)."""

    axis: str
    gauge: str
    reference: str
    plunger: str
    targets_mm: list[float] = Field(description="in the order read, the datum first")
    faces_mm: list[float] = Field(description="set at each target, from the datum face")
    sides: list[tuple[bool, bool]] = Field(description="approached from below, from above")
    overrun_mm: float
    repeats: int
    readings: int
    needed_mm: tuple[float, float] = Field(description="the travel the run needs")
    travel_mm: tuple[float, float] | None = Field(description="the plunger's push-in from "
                                                              "its mounting, least and most")
    window_mm: tuple[float, float] | None = Field(description="the preload window")


class StationTestPlanRecord(Closed):
    """The station's own test of the joints, before the first measurement."""

    joints: list[JointTestPlanRecord]


class PlanRecord(Closed):
    """The plan every move of the run was checked against."""

    cycles: int
    readings: int
    settle_s: float
    soft_limits: SoftLimits | None
    setups: list[SetupPostures]
    travel_mm: dict[str, tuple[float, float]] = Field(
        default_factory=dict, description="per gauge and setup: (min, max) plunger travel")
    motion: str | None = Field(None, description="the controller's path model")
    steps: list[PlanStep]
    test_postures: list[str] | None = Field(
        None, description="a cycle's postures, where [procedure] strokes names them")
    station_test: StationTestPlanRecord | None = Field(
        None, description="the station's own test of the joints ([joints] station_test)")
    passes: dict[str, list[int]] | None = Field(
        None, description="the setups (1-based, in order) the run's first pass (first), its "
        "second (second) and every later one (later) measure, where a second gauge plane "
        "makes them differ")
