"""result.json as pydantic models (docs/design.md, "Run JSON" and "The run record").

Every field of every section is declared and every section is closed: a field the
engine adds and these models do not know fails as result.json is written
(station.record.io.write_result validates it). Floats that were NaN or infinite are
written as null. The larger sections live beside this file: ``accuracy`` in
result_accuracy.py; ``model_selection``, ``stands``, ``uncertainty_budget``,
``reversal``, ``plunger_guard`` and ``since_last`` in result_sections.py; ``joints``
in result_joints.py. Files
written by an older version are read through station.record.migrate.

schema_version, bumped when a field changes meaning, goes away, or a file of the
older version no longer validates (adding an optional field does not):

- 1: the top level declared, its larger sections open objects.
- 2: every section typed and closed; a field the engine always writes is required
  (nullable where it may be null), so older files are read through
  ``migrate()``, which fills what they lack.

Optional fields added within version 2 (a file without them reads as it is):
``rollbacks``, every rollback in turn, where ``rolled_back`` alone kept the last.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from station.record.result_acceptance import Acceptance
from station.record.result_accuracy import Accuracy, Compensated
from station.record.result_base import Axis3, Closed, NotStated, Params
from station.record.result_joints import Joints
from station.record.result_sections import (
    ModelSelection,
    NotCompared,
    PlungerGuard,
    Reversal,
    SinceLast,
    StandEstimate,
    UncertaintyBudget,
)
from station.record.result_statement import AdviceItem, Quantity

__all__ = ["SCHEMA_VERSION", "Compensated", "Gauge", "RolledBack", "RunResult", "Setup",
           "Status"]

SCHEMA_VERSION: Literal[2] = 2

Stopped = Literal["converged", "max_iterations", "not-converged", "refused", "declined",
                  "failed", "skipped", "not-verified"]
Verdict = Literal["significant", "converged", "suspected", "unproven", "ambiguous",
                  "form-limited", "budget-limited"]
Status = Literal["ok", "failed", "refused", "aborted"]


class Machine(Closed):
    id: str | None = Field(description="[machine] id, the machine's serial (null: none)")
    leg_length: float
    rho_min: float
    rho_max: float


class Gauge(Closed):
    """gauges[]: a dial indicator of the run, named by what identifies it (its
    serial, [[indicators]] serial), not by the port it was on."""

    name: str
    protocol: str
    serial: str | None = Field(description="[[indicators]] serial (null: not given)")


class Simulation(Closed):
    """simulation: the hidden machine of a simulated run, named for the report."""

    seed: int | None
    true_drho: Axis3
    true_dl: Axis3
    true_tilt: Params = Field(description="tilt_yx, tilt_zx, tilt_zy, mrad")
    true_gap: Params = Field(description="gap_xy, gap_xz, gap_yz: how far the axes pass "
                                         "each other, mm")
    noise_mm: float
    mount_error_mm: float = Field(description="stands placed by eye: each mounting off the "
                                              "leg's middle by up to this, mm")
    backlash_mm: Axis3 = Field(description="each joint's lost motion (ISO 230-2's reversal "
                                           "value), mm")
    leg_bow_mm: Axis3 = Field(description="each leg's bow, the sagitta at its middle, mm")
    gauge_scale: dict[str, float] = Field(description="each gauge's scale error, relative")
    joint_lead_um_per_m: Axis3 = Field(
        default_factory=lambda: dict.fromkeys(("x", "y", "z"), 0.0),  # type: ignore[arg-type]
        description="each joint's lead error, µm per metre of travel from home (0: exact)")
    joint_pitch_um: float = Field(0.0, description="the joints' periodic error: amplitude, "
                                                   "µm (0: none)")
    joint_pitch_period_mm: float = Field(0.0, description="its period, mm (0: none)")


class Timing(Closed):
    wall_s: float = Field(description="the run's wall time in this process, s")
    moves: int
    readings: int
    retries: int
    outliers_rejected: int
    mountings: int | None = Field(description="setup records: the operator mounted gauges")
    operator_s: float | None = Field(description="time waited at the mounting prompts, s")


class Loop(Closed):
    """loop: how the closed loop stopped (docs/design.md, "Closed loop")."""

    stopped: Stopped
    detail: str | None
    write_backs: int
    max_iterations: int
    converge_mm: float
    converged_within_mm: float | None = Field(
        description="converge_mm plus half a count of the drive's offsets: what "
                    '"converged" claims at 95 %')
    extra_passes: int = Field(description="further passes of a verification measured")
    max_extra_passes: int


class Writeback(Closed):
    status: Literal["written", "refused", "declined", "skipped", "failed-restored"]
    reason: str | None
    round: int | None = Field(None, description="the write-back round, from 1")


class Joined(Closed):
    """A verification's Δρ joined with the rounds before it, each moved by the offsets
    written since: what shown_within_95_mm and the verdict rest on."""

    drho_mm: Params
    std_errors_mm: Params


class Ambiguity(Closed):
    """What a round's data cannot decide: another model explains its deviations as
    well (docs/model.md, "Tilts or bows")."""

    explained_by: str = Field(description="the other model: the legs' bows where the fit "
                                          "has the axes' tilts")
    apart_mm: Params = Field(description="how far the two explanations lie from each value "
                                         "stated: half their distance for Δρ, stated and "
                                         "written at their midpoint; all of it for the others")


class Iteration(Closed):
    """iterations[]: one identification round."""

    phase: str = Field(description='"m", then "v", "v2", … one per write-back')
    model: str
    identified: Params
    std_errors: Params
    std_errors_dof: float | None
    offsets_written: Axis3 | None = Field(description="null: nothing written after it")
    writeback: str | None = Field(description="the write-back's status")
    deviations_rms_mm: float | None
    residual_rms_mm: float | None
    noise_floor_mm: float | None
    fit_ok: bool | None
    significant: list[str] = Field(description="the corrections beyond the noise")
    shown_within_95_mm: Params | None = Field(
        description="per axis, how far the machine may be off at 95 %")
    verdict: Verdict | None
    passes: list[str] | None = Field(None, description="a verification measured again")
    joined: Joined | None = Field(None, description="from the second round on")
    stands_part_mm: Params | None = Field(
        None, description="of each Δρ standard error, the part the stands set by eye make "
                          "(more cycles in a mounting do not shrink it, more mountings do)")
    target_drho: Params | None = Field(None, description="the Δρ aimed at, objective tool")
    ambiguity: Ambiguity | None = Field(
        None, description="where the data cannot tell the axes' tilts from the legs' bows")
    form_floor_mm: Params | None = Field(
        None, description="of each Δρ standard error, the part the legs' bows carried from "
                          "the pass that read a second gauge plane leave however often the "
                          "legs' middles are read again (orthocal.carry.prior_floor)")
    inputs_part_mm: Params | None = Field(
        None, description="of each Δρ's uncertainty, the standard part the stated inputs "
                          "make (Type B: [uncertainty], the gauges' MPE), the same in every "
                          "round: no pass shrinks it")


class Remaining(Closed):
    """remaining: what the last verification found left of Δρ and did not write."""

    phase: str
    round: int
    estimate: Params
    total: Params = Field(description="the correction the controller holds plus the "
                                      "estimate: the machine's Δρ at the start of the run")
    std_errors: Params
    std_errors_dof: float | None
    coverage_factor_95: float | None


class RolledBack(Closed):
    """One ``orthocal rollback``: it restored the offsets saved before the run's first
    write-back (``rolled_back``, the last; ``rollbacks``, each in turn)."""

    at: str = Field(description="when, ISO 8601")
    replaced: Axis3 = Field(description="the offsets the controller held before, mm")
    restored: Axis3 = Field(description="the offsets restored (read back), mm")


class Setup(Closed):
    """One setup of a measurement: how many cycles it used of how many it could, its
    repeats, and whether its spread was flagged (built by the engine as
    station.analysis.statistics.SetupOutcome, which adds what the record leaves out)."""

    leg: str
    indicators: dict[str, str] = Field(description="indicator name → its direction")
    cycles_used: int
    cycles_max: int
    repeats: int
    flagged: bool
    spread_mm: float | None


class Deviation(Closed):
    """A deviation key's cycles ("+xy", "+30xy", "+@0.75xy"), mm."""

    mean: float
    std: float | None = Field(description="over the cycles (null: one cycle)")
    n: int = Field(description="cycles")
    model: float | None = Field(description="the identified model's value")


class VerifiedDeviation(Deviation):
    expected: float = Field(description="what the model predicts once Δρ is written")


class Correlation(Closed):
    names: list[str]
    matrix: list[list[float | None]]


class Verification(Closed):
    """verification: the last round, judged against what the model predicts once Δρ
    is written (ΔL, tilts and gaps cannot be written and still show)."""

    identified: Params
    std_errors: Params
    std_errors_dof: float | None
    residual_rms_mm: float | None
    deviations_rms_mm: float | None
    expected_rms_mm: float | None
    vs_expected_rms_mm: float | None
    noise_floor_mm: float | None
    deviations: dict[str, VerifiedDeviation]
    setups: list[Setup]


class RunResult(Closed):
    """result.json: one calibration run, as written at its end (or when it stopped).
    Required fields are those every run writes; the others are absent where the run
    did not get that far (no identification, no write-back, …)."""

    schema_version: Literal[2]
    run_dir: str
    status: Status
    message: str | None
    started: str
    finished: str | None
    duration_s: float | None
    simulated: bool
    simulation: Simulation | None
    machine: Machine
    operator: str | None = Field(None, description="[station] operator or run --operator "
                                                   "(null: not given)")
    gauges: list[Gauge] | None = Field(None, description="the run's indicators")
    model: str
    method: Literal["linear", "nonlinear"]
    model_selection: ModelSelection | None = Field(None, description="model auto")
    identified: Params = Field(description="the total Δρ written since the run started (the "
                                           "other parameters as the first round found them)")
    std_errors: Params
    std_errors_dof: float | None = None
    correlation: Correlation | None = None
    residual_rms_mm: float | None = None
    sigma_mm: float | None = None
    condition_number: float | None = None
    noise_mm: float | None = None
    noise_floor_mm: float | None = None
    fit_ok: bool | None = None
    fit_note: str | None = None
    deviations: dict[str, Deviation] | None = None
    deviations_rms_mm: float | None = None
    not_identifiable: list[str] | None = None
    setups: list[Setup] | None = None
    stands: dict[str, StandEstimate] | None = Field(None, description="stands modelled")
    offsets_before: Axis3 | None
    offsets_written: Axis3 | None
    offsets_final: Axis3 | None = Field(description="the journal's last write-back or "
                                                    "rollback, else the offsets before")
    offsets_held_by: Literal["controller", "station"] | None
    rolled_back: RolledBack | None = Field(
        None, description="the last rollback, whose restored offsets are offsets_final; "
                          "absent unless rolled back")
    rollbacks: list[RolledBack] | None = Field(
        None, description="every rollback of the run, oldest first (the last is "
                          "rolled_back); absent unless rolled back, and in a record "
                          "written before rollbacks were kept, where rolled_back is the one")
    offsets_note: str | None = Field(None, description="offsets the station holds")
    writeback: Writeback | None
    verification: Verification | None
    iterations: list[Iteration] | None = None
    converged: bool | None = None
    loop: Loop | None = None
    remaining: Remaining | None = None
    accuracy: Accuracy | NotStated | None = None
    uncertainty_budget: UncertaintyBudget | NotStated | None = None
    reversal: Reversal | None = None
    joints: Joints | None = Field(
        None, description="each joint's positioning error as the run took it: tested, "
                          "measured by the station or assumed (absent in older runs)")
    plunger_guard: PlungerGuard
    timing: Timing
    acceptance: Acceptance | None = Field(
        None, description="the tool against [acceptance] at 95 %; absent without it")
    since_last: SinceLast | NotCompared | None = Field(
        None, description="absent without [machine] id or an earlier run in the history")
    statement: list[Quantity] | None = Field(
        None, description="every quantity the run states, once, at 95 % (docs/design.md, "
                          "\"The statement of the machine\"); absent before an "
                          "identification of Δρ")
    advice: list[AdviceItem] | None = Field(
        None, description="what to do, each from the decisions it rests on (docs/design.md, "
                          "\"The decision table\")")

    def rollback_history(self) -> list[RolledBack]:
        """Every rollback of the run, oldest first: ``rollbacks``, or in a record
        written before they were kept, ``rolled_back`` alone."""
        if self.rollbacks:
            return list(self.rollbacks)
        return [] if self.rolled_back is None else [self.rolled_back]
