"""result.json's ``accuracy``: the run's statement at the tool (docs/design.md,
"Accuracy at the tool"), built by station.analysis.accuracy_statement.statement,
station.analysis.compensated and station.analysis.reversal.at_the_tool."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from station.record.result_base import Axis3, Closed, Interval, Params

Objective = Literal["joints", "tool"]


class ErrorStats(Closed):
    """The tool-point error field over the workspace grid, after the frame's fit."""

    rms_mm: float
    max_mm: float


class AfterInterval(ErrorStats):
    """``after``: the field once the offsets written act, with 95 % intervals from the
    covariance of Δρ now and of the pooled layout (and the legs' form)."""

    rms_interval_95_mm: Interval
    max_interval_95_mm: Interval


class Grid(Closed):
    points_per_axis: int
    points: int = Field(description="grid points inside the soft limits")
    excluded: int = Field(description="grid points outside the soft limits, left out")


class ObjectiveFigures(Closed):
    """What an objective's offsets, written exactly, would leave."""

    after: ErrorStats
    offsets_mm: Axis3 | None = Field(description="the offset registers it would write")
    target_drho_mm: Params = Field(description="the Δρ it aims at")


class Objectives(Closed):
    joints: ObjectiveFigures
    tool: ObjectiveFigures


class Alternative(ObjectiveFigures):
    """The objective not chosen."""

    objective: Objective


class SquarenessDecision(Closed):
    """When an axis counts as leaning: beyond ``k`` standard errors (Student's t, one
    false alarm in a thousand square machines); never when the model kept no tilt."""

    k: float | None = Field(description="null: the model test kept no tilt")
    rule: str


class ErrorField(Closed):
    """The field at each grid point: the point (mm) and the error vector there (mm)."""

    points_mm: list[list[float]]
    before_mm: list[list[float]]
    after_mm: list[list[float]]


class ToolReversal(Closed):
    """``accuracy.reversal``: what the joints' lost motion leaves at the tool (docs/
    design.md, "Lost motion (reversal)")."""

    value_mm: Axis3 = Field(description="each joint's reversal value B, mm")
    tool_max_mm: float | None = Field(
        description="what a point reached from an unknown side can be off beyond the error "
                    "field, worst over the workspace, mm")
    repair_above_mm: float = Field(description="a reversal above this: repair the mechanics")
    advice: str
    assumes: str


class Compensated(Closed):
    """accuracy.compensated: the tool error with the identified machine in the
    controller's kinematics (orthoglidekins) or in the program (``orthocal
    compensate``), beside "offsets only" (accuracy.after) (docs/design.md, "The
    geometry in the controller"; docs/model.md, (K3))."""

    rms_mm: float = Field(description="RMS of |E| expected over the parameters' error "
                                      "(their statistical covariance), mm")
    max_mm: float = Field(description="max of |E|, the median over the parameters' error, mm")
    rms_interval_95_mm: Interval = Field(
        description="95 % interval of the RMS, the stated systematic errors included")
    max_interval_95_mm: Interval
    offsets_only_rms_mm: float = Field(description="accuracy.after's RMS, for comparison")
    offsets_only_max_mm: float
    told: list[str] = Field(description="the parameters the controller is told, "
                                        "PARAM_NAMES (Δρ: what the offsets did not correct)")
    nominal: dict[str, str] = Field(description="the parameters left at their nominal "
                                                "values, and why")
    routes: list[str] = Field(description="how to put the machine into the controller")
    route: str | None = Field(
        None, description='which route the figures rest on (a key of orthocal.'
                          'joint_compensation.ROUTES): "kinematics+tables" where the run '
                          'has a joint table, else "kinematics" (null: a record from '
                          "before the joints)")
    takes_into_account: str | None = Field(
        None, description="what that route takes into account, in the words every "
                          "export's header says")
    method: str
    assumes: list[str]
    field_rms_mm: list[float] = Field(
        description="per grid point (accuracy.field.points_mm), the |E| expected, mm")


class DriveCount(Closed):
    """What the drive's count does at the tool (docs/model.md, "The drive's count",
    (J17)): a point commanded between counts is reached with each joint up to half a
    count off. The tool's figures are the geometry's and leave this out."""

    target_mm: Axis3 = Field(description="each joint's target count, mm")
    rms_mm: float = Field(description="RMS |δP| over the stated grid, each joint uniform "
                                      "within ±half its count")
    max_mm: float = Field(description="the largest |δP| over the grid, the joints at the "
                                      "corners of ±half their counts")


class Accuracy(Closed):
    """accuracy: the tool-point error over the workspace box before and after the
    calibration, for the machine all rounds measured (docs/design.md, "Accuracy at
    the tool")."""

    workspace_mm: list[Interval] = Field(description="the box, [lo, hi] per axis")
    grid: Grid
    frame: Literal["translation", "rigid"] = Field(
        description="what is fitted away before the error is stated")
    objective: Objective = Field(description="[writeback] objective, the one chosen")
    before: ErrorStats = Field(description="Δρ at the start (remaining.total)")
    after: AfterInterval
    after_method: str = Field(description="how the after-figures' intervals were propagated")
    objectives: Objectives
    alternative: Alternative
    best_offsets_can_do: ErrorStats | None = Field(
        description="the field the best offsets leave for the pooled tilts and gaps: what "
                    "no offsets can improve on (null in results from before it was stated)")
    squareness_mm_per_m: dict[str, float | None] = Field(
        description="squareness of the tool's motions xy, xz, yz (ISO 230-1), mm/m")
    squareness_std_errors: dict[str, float | None]
    squareness_decision: SquarenessDecision | None = Field(
        description="null where the tilts were not identified (or in results from "
                    "before the rule was stated)")
    squareness_advice: list[str]
    tilts: Params | None = Field(description="the pooled tilts, mrad")
    tilt_std_errors: Params | None
    tilt_interval_95: dict[str, Interval] | None = Field(
        description="only when the model kept no tilt")
    gaps: Params | None = Field(description="the pooled gaps, mm; null where no round's fit "
                                            "had them")
    gap_std_errors: Params | None
    gap_interval_95: dict[str, Interval] | None
    gap_advice: list[str] | None = Field(description="null in results from before the gaps")
    field: ErrorField
    compensated: Compensated | None = Field(
        description="null in results from before the geometry could be put in the "
                    "controller")
    reversal: ToolReversal | None = Field(None, description="absent without a reversal "
                                                            "estimate")
    drive_count: DriveCount | None = Field(
        None, description="absent where the joints are taken as continuous (results "
                          "from before the drive's count was modelled)")
    assumes: list[str] = Field(description="what the figures take as known, in words")
