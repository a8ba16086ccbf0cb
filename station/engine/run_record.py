"""The run's record as the run fills it (:class:`RunRecord`): the one place a run's
``RunResult`` is begun and each of its fields set (docs/design.md, "The run record").
The flow and the procedure hand it what happened (a round's fields, a write-back's
outcome, the end from station.statement.conclude, the timing); the record's models
come from station.engine.results, the statement's from station.statement. result.json
is this record validated (station.record.io)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path

from drivers.base import ZeroOffsets
from orthocal import AXES
from orthocal.loop import WRITABLE
from station.config import StationConfig
from station.engine import results
from station.engine.writeback import WritebackOutcome
from station.record.io import section
from station.record.result import (
    Iteration,
    Loop,
    PlungerGuard,
    Remaining,
    RolledBack,
    RunResult,
    Setup,
    Status,
    Timing,
    Verification,
)
from station.record.result_base import JsonObject, NotStated
from station.record.result_joints import Joints
from station.record.result_sections import (
    ModelSelection,
    NotCompared,
    Reversal,
    SinceLast,
    UncertaintyBudget,
)
from station.record.result_statement import AdviceItem
from station.record.state import RunState
from station.report.first_screen import ROLLED_BACK_TODO
from station.statement.conclude import Conclusion


class RunRecord:
    """result.json as a run fills it, begun failed until the run says otherwise
    (results.base_result); ``result`` the record, read by the flow where it must know
    what is recorded (the offsets before), set only here."""

    def __init__(self, run_dir: Path, config: StationConfig, sim: JsonObject | None,
                 started_iso: str) -> None:
        self.result = results.base_result(run_dir, config, sim, started_iso)

    # --- round by round ----------------------------------------------------------------

    def rounds(self, iterations: list[Iteration]) -> None:
        """The rounds' entries: the flow's own list, filled round by round."""
        self.result.iterations = iterations

    def first_round(self, fields: results.Measured, selection: JsonObject | None) -> None:
        """The first round's fields at the top level (its model: with auto, the one the
        model test chose) and the model test's account."""
        for name in type(fields).model_fields:
            setattr(self.result, name, getattr(fields, name))
        if selection is not None:
            self.result.model_selection = section(ModelSelection, selection)

    def model_selection(self, selection: JsonObject) -> None:
        self.result.model_selection = section(ModelSelection, selection)

    def lost_motion(self, reversal: Reversal) -> None:
        self.result.reversal = reversal

    def joints(self, joints: Joints) -> None:
        self.result.joints = joints

    def verification(self, verification: Verification) -> None:
        self.result.verification = verification

    def wrote(self, outcome: WritebackOutcome, round: int, controller: ZeroOffsets) -> None:
        """A write-back's outcome: the first's offsets before and written, a later one's
        written, each one's status."""
        if round == 1:
            self.result.offsets_before = dict(outcome.before) if outcome.before is not None \
                else {a: float(v) for a, v in zip(AXES, controller.read_offsets(), strict=True)}
            self.result.offsets_written = None if outcome.written is None \
                else dict(outcome.written)
        elif outcome.written is not None:
            self.result.offsets_written = dict(outcome.written)
        self.result.writeback = results.writeback_record(outcome, round)

    def totals(self, iterations: list[Iteration]) -> None:
        """Top-level ``identified``: the total Δρ written since the run started (the
        other parameters as the first identification found them)."""
        total = dict(iterations[0].identified)
        written = [it for it in iterations if it.offsets_written is not None]
        if written:
            for name in WRITABLE:
                if name in total:
                    total[name] = sum(results.known(it.identified).get(name, 0.0)
                                      - results.known(it.target_drho or {}).get(name, 0.0)
                                      for it in written)
        self.result.identified = total

    def nothing_written(self, offsets: Mapping[str, float]) -> None:
        """Nothing was written: the offsets as found are the run's before and after."""
        self.result.offsets_before = dict(offsets)
        self.result.offsets_written = None

    # --- the end -------------------------------------------------------------------------

    def concluded(self, end: Conclusion) -> None:
        """The end of a run that identified Δρ (station.statement.conclude)."""
        r = self.result
        r.converged, r.loop = end.converged, end.loop
        r.remaining, r.uncertainty_budget = end.remaining, end.uncertainty_budget
        r.statement, r.advice = end.statement, end.advice
        r.acceptance, r.accuracy = end.acceptance, end.accuracy

    def ended_without_drho(self, loop: Loop, remaining: Remaining | None,
                           budget: UncertaintyBudget | NotStated | None) -> None:
        """The end of a run whose model holds no Δρ: its loop, and what is left."""
        r = self.result
        r.converged = loop.stopped == "converged"
        r.loop, r.remaining, r.uncertainty_budget = loop, remaining, budget

    def status(self, status: Status, message: str | None) -> None:
        self.result.status, self.result.message = status, message

    def since_last(self, since: SinceLast | NotCompared) -> None:
        self.result.since_last = since

    def finished(self, *, finished_iso: str, duration_s: float, timing: Timing,
                 state: RunState, setups: list[Setup] | None,
                 controller: ZeroOffsets) -> None:
        """What every run's end records, however it ends: when, how long, its timing,
        the plunger guard, the setups (where no identification listed them: what was
        measured), and where the offsets live and what they are now."""
        r = self.result
        r.finished, r.duration_s, r.timing = finished_iso, duration_s, timing
        r.plunger_guard = PlungerGuard.model_validate(asdict(state.guard))
        if not r.setups and setups is not None:
            r.setups = setups
        r.offsets_held_by, final, note = results.offsets_now(r, controller, state)
        r.offsets_final = None if final is None else dict(final)
        if note is not None:
            r.offsets_note = note


def rolled_back(record: RunResult, back: RolledBack) -> RunResult:
    """A finished run's record after ``orthocal rollback``: the rollback appended to
    ``rollbacks``, ``rolled_back`` this one, ``offsets_final`` the restored offsets, and
    the advice (for the machine the run left) replaced by the one thing that stands."""
    out = record.model_copy(deep=True)
    out.rollbacks = [*record.rollback_history(), back]
    out.rolled_back = back
    out.offsets_final = dict(back.restored)
    if out.advice is not None:
        out.advice = [AdviceItem(id="rolled-back", text=ROLLED_BACK_TODO, rests_on=[])]
    return out
