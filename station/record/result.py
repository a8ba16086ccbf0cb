"""result.json as pydantic models (docs/design.md, "The run record").

Every top-level field is declared (a field the engine adds and this model does not
know fails the test that validates real runs against it); sections whose inner
shape is documented elsewhere (accuracy, the budget, model selection, lost motion,
the plunger guard) are typed as objects here and described in docs/design.md.
Floats that were NaN or infinite are written as null."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

#: Bumped when a field changes meaning or goes away (adding one does not).
SCHEMA_VERSION = 1

Axis3 = dict[str, float | None]  # {"x": …, "y": …, "z": …}, mm
Params = dict[str, float | None]  # parameter name (docs/model.md) → value


class _Open(BaseModel):
    """A section whose further fields are documented, not yet modelled."""

    model_config = ConfigDict(extra="allow")


class Timing(_Open):
    wall_s: float = Field(description="the run's wall time in this process, s")
    moves: int
    readings: int
    retries: int
    outliers_rejected: int
    mountings: int | None = Field(None, description="setup records: the operator mounted gauges")
    operator_s: float | None = Field(None, description="time waited at the mounting prompts, s")


class Loop(_Open):
    stopped: Literal["converged", "max_iterations", "not-converged", "refused", "declined",
                     "failed", "skipped", "not-verified"]
    detail: str | None = None
    write_backs: int
    max_iterations: int
    converge_mm: float
    converged_within_mm: float | None = None
    extra_passes: int = 0
    max_extra_passes: int = 0


class Writeback(_Open):
    status: str
    reason: str | None = None
    round: int | None = None


class Iteration(_Open):
    phase: str = Field(description='"m", then "v", "v2", … one per write-back')
    model: str
    identified: Params
    std_errors: Params
    std_errors_dof: float | None = None
    offsets_written: Axis3 | None = None
    writeback: str | None = None
    verdict: Literal["significant", "converged", "suspected", "unproven"] | None = None
    significant: list[str] = []
    passes: list[str] | None = None
    joined: dict[str, Params] | None = Field(
        None, description="a verification's Δρ joined with the rounds before it, each moved "
                          "by the offsets written since (drho_mm, std_errors_mm): what "
                          "shown_within_95_mm and the verdict's converged rest on")
    stands_part_mm: Params | None = Field(
        None, description="of each Δρ standard error, the part the stands set by eye make "
                          "(more cycles in a mounting do not shrink it, more mountings do)")


class Remaining(_Open):
    phase: str
    round: int
    estimate: Params
    total: Params
    std_errors: Params
    std_errors_dof: float | None = None
    coverage_factor_95: float | None = None


class Setup(_Open):
    """One setup of a measurement: how many cycles it used of how many it could, its
    repeats, and whether its spread was flagged (built by the engine as
    station.engine.statistics.SetupOutcome, which adds what the record leaves out)."""

    leg: str
    indicators: dict[str, str]
    cycles_used: int
    cycles_max: int
    repeats: int
    flagged: bool
    spread_mm: float | None = None


class Machine(_Open):
    leg_length: float
    rho_min: float
    rho_max: float


class SinceLast(_Open):
    """What changed since the machine's last run in the history (docs/design.md,
    "Machine history"): that run's as left (as found where it verified nothing)
    against this run's as found, through station.history.compare."""

    previous_run: str = Field(description="the last earlier run of this machine id")
    previous_started: str | None = None
    previous_state: Literal["as left", "as found"] | None = None
    joint_error_mm: dict[str, dict[str, Any]] | None = Field(
        None, description="per axis e = Δρ − o: before, after, change, std_error, "
        "interval_95 (mm), significant")
    layout: dict[str, dict[str, Any]] | None = Field(
        None, description="per tilt (mrad) and gap (mm), the same fields")
    not_compared: str | None = Field(
        None, description="why the two runs could not be compared (then no changes)")


class Compensated(BaseModel):
    """accuracy.compensated: the tool error with the identified machine in the
    controller's kinematics (orthoglidekins) or in the program (``orthocal
    compensate``), beside "offsets only" (accuracy.after) (docs/design.md, "The
    geometry in the controller"; docs/model.md, (K3))."""

    model_config = ConfigDict(extra="forbid")

    rms_mm: float = Field(description="RMS of |E| expected over the parameters' error "
                                      "(their statistical covariance), mm")
    max_mm: float = Field(description="max of |E|, the median over the parameters' error, mm")
    rms_interval_95_mm: tuple[float, float] = Field(
        description="95 % interval of the RMS, the stated systematic errors included")
    max_interval_95_mm: tuple[float, float]
    offsets_only_rms_mm: float = Field(description="accuracy.after's RMS, for comparison")
    offsets_only_max_mm: float
    told: list[str] = Field(description="the parameters the controller is told, "
                                        "PARAM_NAMES (Δρ: what the offsets did not correct)")
    nominal: dict[str, str] = Field(description="the parameters left at their nominal "
                                                "values, and why")
    routes: list[str] = Field(description="how to put the machine into the controller")
    method: str
    assumes: list[str]
    field_rms_mm: list[float] = Field(
        description="per grid point (accuracy.field.points_mm), the |E| expected, mm")


class Accuracy(_Open):
    """accuracy: the run's statement at the tool (docs/design.md, "Accuracy at the tool");
    its older sections are documented there, the compensated route is modelled."""

    compensated: Compensated | None = None


class RunResult(BaseModel):
    """result.json: one calibration run, as written at its end (or when it stopped)."""

    model_config = ConfigDict(extra="forbid")

    schema_version: Literal[1] | None = Field(
        None, description="absent in results written before the schema")
    run_dir: str
    status: Literal["ok", "failed", "refused", "aborted"]
    message: str | None
    started: str
    finished: str | None
    duration_s: float | None
    simulated: bool
    simulation: dict[str, Any] | None
    machine: Machine
    model: str
    method: Literal["linear", "nonlinear"]
    model_selection: dict[str, Any] | None = None
    identified: Params
    std_errors: Params
    std_errors_dof: float | None = None
    correlation: dict[str, Any] | None = None
    residual_rms_mm: float | None = None
    sigma_mm: float | None = None
    condition_number: float | None = None
    noise_mm: float | None = None
    noise_floor_mm: float | None = None
    fit_ok: bool | None = None
    fit_note: str | None = None
    deviations: dict[str, dict[str, Any]] | None = None
    deviations_rms_mm: float | None = None
    not_identifiable: list[str] | None = None
    setups: list[Setup] | None = None
    stands: dict[str, dict[str, Any]] | None = None
    offsets_before: Axis3 | None
    offsets_written: Axis3 | None
    offsets_final: Axis3 | None = None
    offsets_held_by: Literal["controller", "station"] | None = None
    offsets_note: str | None = None
    writeback: Writeback | None
    verification: dict[str, Any] | None
    iterations: list[Iteration] | None = None
    converged: bool | None = None
    loop: Loop | None = None
    remaining: Remaining | None = None
    accuracy: Accuracy | None = None
    uncertainty_budget: dict[str, Any] | None = None
    reversal: dict[str, Any] | None = None
    plunger_guard: dict[str, Any] | None = None
    timing: Timing | None = None
    since_last: SinceLast | None = Field(
        None, description="absent without [machine] id or an earlier run in the history")
