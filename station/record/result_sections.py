"""result.json's larger sections besides ``accuracy``: ``model_selection`` (docs/
design.md, "Run JSON" and "Models"), ``stands``, ``uncertainty_budget`` ("Uncertainty
budget"), ``reversal`` ("Lost motion (reversal)"), ``plunger_guard`` and
``since_last`` ("Machine history")."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from station.record.result_base import Axis3, Closed, Params

# --- model selection and the stands -------------------------------------------------


class StandEstimate(Closed):
    """Where one indicator stand was, mm off the leg's middle (L/2), when the stands
    were modelled as random effects (orthocal.stands)."""

    gauges: list[str] = Field(description='the gauges on it, leg and direction ("xy")')
    observable: bool = Field(description="whether the offsets Δρ were large enough for "
                                         "this stand to change the deviations")
    prior_sd_mm: float
    offset_mm: float | None = Field(description="null where not observable")
    std_error_mm: float | None
    note: str | None = Field(None, description="why not observable")


class StandsModelled(Closed):
    """model_selection.stands: the stands' prior and what the chosen fit made of them."""

    tolerance_mm: float = Field(description="[procedure] stand_tolerance_mm")
    prior_sd_mm: float = Field(description="tolerance/√3")
    groups: dict[str, list[str]] = Field(description="stand name → the gauges on it")
    estimates: dict[str, StandEstimate]


class CandidateAllowance(Closed):
    """What the stated errors took of a candidate's misfit (orthocal.misfit)."""

    rss_without_allowance_mm2: float
    rss_with_allowance_mm2: float
    largest_used_mm: dict[str, float] = Field(
        description='the largest error terms used, by name ("bow xz", "gauge scale yx")')
    at_bound: int = Field(description="how many terms stand at their stated bound")
    p_without_allowance: float | None = Field(description="what the noise alone would say")


class AgainstNext(Closed):
    """A candidate tested against the next size that contains it (likelihood ratio),
    with the stands modelled."""

    model: str
    F: float | None
    dof: tuple[int, float] = Field(description="(the parameters added, the noise's ν)")
    p_value: float | None


class Candidate(Closed):
    """One candidate model's lack-of-fit F test against the measured noise."""

    model: str
    identifiable: bool
    F: float | None
    dof: tuple[int, float] | None = Field(description="(K − p, the noise's ν)")
    p_value: float | None
    passed: bool
    residual_rms_mm: float | None
    note: str | None
    allowance: CandidateAllowance | None = Field(None, description="with an allowance")
    against_next: AgainstNext | None = Field(None, description="with the stands modelled")


class SelectionAllowance(Closed):
    """The stated errors the model test may excuse a misfit by, within their bounds
    and with their shapes: the uncertainty budget's inputs."""

    straightness_mm: dict[str, float] = Field(description="per gauge plane (leg, direction)")
    mpe_mm: dict[str, float] = Field(description="per gauge plane")
    mpe_span_mm: float
    plunger_angle_deg: float
    temperature_change_c: float
    joint_lead_um_per_m: dict[str, float] = Field(
        default_factory=dict,
        description="per joint x, y, z, the lead bound (µm/m): an assumed joint's "
                    "[uncertainty] joint_positioning_um_per_m, or what its table's own "
                    "uncertainty leaves of its lead; joints not named: none")
    note: str


class ModelSelection(Closed):
    """model_selection (model ``auto``): which candidate the data support, and why."""

    model: str = Field(description="the model chosen")
    test: str = Field(description="the test, in words")
    level: float
    noise_sigma_mm: float
    noise_dof: float
    noise_source: str
    supported: bool = Field(description="false: no candidate explains the data, the largest "
                                        "identifiable one is used")
    reason: str
    candidates: list[Candidate]
    stands: StandsModelled | None = Field(None, description="absent: stands not modelled")
    allowance: SelectionAllowance | None = Field(
        description="null in results from before the model test allowed for them")


# --- the uncertainty budget ---------------------------------------------------------


class BudgetSource(Closed):
    """One input of the budget and what it contributes to each Δρ (GUM 5.1.3)."""

    source: str = Field(description='"repeatability" (the Type A part, first) or the input')
    type: Literal["A", "B"]
    distribution: Literal["normal", "rectangular", "triangular"]
    value_mm: float | None = Field(description="half-width of the error it puts on one "
                                               "deviation (null when not a length)")
    u_mm: float | None = Field(description="its standard uncertainty")
    contributions_mm: Params
    dof: float | None = Field(None, description="Type A only (null: infinite)")
    inputs: dict[str, float | None] | None = Field(None, description="what it was built from")


class StatedInput(Closed):
    """A Type B input as the budget took it: given in the config, or assumed."""

    value: float | list[float]
    given: bool
    assumed: str | None = Field(None, description="why this default, where not given")


class BudgetInputs(Closed):
    leg_straightness_mm: StatedInput
    temperature_change_c: StatedInput
    plunger_angle_deg: StatedInput
    mpe_mm: dict[str, StatedInput] = Field(description="per indicator")
    resolution_mm: dict[str, StatedInput] = Field(description="per indicator")


class Instrument(Closed):
    name: str
    protocol: str
    serial: str | None
    resolution_mm: float
    mpe_mm: float


class UncertaintyBudget(Closed):
    """uncertainty_budget: the run's statement of Δρ, Type A and B combined (GUM)."""

    statement: Literal["remaining.total", "identified"] = Field(
        description="the figures the budget is of")
    sources: list[BudgetSource]
    combined_mm: Params
    effective_dof: Params = Field(description="Welch–Satterthwaite (null: infinite)")
    coverage_factor: Params
    expanded_95_mm: Params = Field(description="half-width of the 95 % interval")
    inputs: BudgetInputs
    assumed: list[str]
    instruments: list[Instrument]
    method: str


# --- lost motion, the plunger guard -------------------------------------------------


class Reversal(Closed):
    """reversal: each joint's lost motion B (ISO 230-2's reversal value), measured
    by reading Π0 approached from the other side each cycle."""

    value_mm: Axis3
    std_errors_mm: Axis3
    std_errors_dof: float | None
    n: dict[str, int] = Field(description="measurements per joint")
    approach: Literal["below", "above", "as-planned"]
    approach_overrun_mm: float
    method: str
    stated: str = Field(description="what the Δρ stated are, given the approach")


class Recovery(Closed):
    """A plunger-guard stop the run recovered from (the journal's event)."""

    where: str
    move: str
    indicator: str
    waypoints: int
    speed_mm_s: float
    zero_shift_mm: dict[str, float] | None = Field(
        None, description="only where the way back found a gauge's zero moved")


class PlungerGuard(Closed):
    """plunger_guard: what the guard did, over every session of the run."""

    stops: int
    recovered: list[Recovery]
    retakes: int = Field(description="cycles taken again")
    refused: int


# --- machine history ----------------------------------------------------------------


class Change(Closed):
    """One parameter from the earlier run to this one (station.history.compare)."""

    before: float
    after: float
    change: float
    std_error: float | None = Field(description="the change's combined standard uncertainty")
    interval_95: float | None = Field(
        description="half-width: the change's 95 % expanded uncertainty (the two runs' "
                    "statements combined as the GUM combines a difference; a run from "
                    "before the statement: k·σ, Student's t on the smaller dof)")
    significant: bool | None
    k: float | None = Field(None, description="the change's coverage factor")
    dof: float | None = Field(None, description="the change's effective dof (null: infinite)")
    before_expanded: float | None = Field(
        None, description="the 95 % expanded uncertainty the earlier run stated its value "
                          "with (null: it stated none)")
    after_expanded: float | None = Field(
        None, description="the same of this run's value")


class SinceLast(Closed):
    """What changed since the machine's last run in the history (docs/design.md,
    "Machine history"): that run's as left (as found where it verified nothing)
    against this run's as found, through station.history.compare."""

    previous_run: str = Field(description="the last earlier run of this machine id")
    previous_started: str | None
    previous_state: Literal["as left", "as found"]
    joint_error_mm: dict[str, Change] = Field(description="per axis, e = Δρ − o (mm)")
    layout: dict[str, Change] = Field(description="per tilt (mrad) and gap (mm)")


class NotCompared(Closed):
    """since_last where the two runs could not be compared (another geometry, …)."""

    previous_run: str
    previous_started: str | None
    not_compared: str = Field(description="why, in one line")
