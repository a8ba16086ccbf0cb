"""One run's steps against the devices (:class:`Flow`): measure, identify, write back,
verify, each replayed from the journal when a resumed run already did it (through
station.engine.replay's :class:`~station.engine.replay.Steps`), filling the result as
it goes; :class:`Run`, what a run holds. station.engine.procedure drives it.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from drivers.files import write_atomic
from orthocal import Identification, carry
from orthocal.geometry import params_vector
from orthocal.loop import (
    WRITABLE,
    after_correction,
    correction,
)
from orthocal.lost_motion import Reversal, band_middle, edge_of
from station.analysis import accuracy_statement as accuracy
from station.analysis import joint_fit, joints, reversal, verdict
from station.analysis import run_budget as budget
from station.analysis.joint_readings import details_of, tables_of
from station.analysis.statistics import Measurement, pooled
from station.config import StationConfig
from station.console.operator import Operator
from station.engine import results
from station.engine.closed_loop import extra_passes_allowed, round_phase
from station.engine.devices import Devices
from station.engine.layouts import Layouts
from station.engine.replay import RoundFit, Steps
from station.engine.run_record import RunRecord
from station.engine.sequencer import Sequencer
from station.engine.writeback import WritebackOutcome, write_back
from station.errors import say, storage_message
from station.plan.checker import MotionChecker
from station.plan.steps import Plan
from station.record.io import jsonable_value
from station.record.journal import JointTested
from station.record.journal_file import Journal
from station.record.model import MachineModel
from station.record.result import Iteration, Joined, Loop, Status
from station.record.result_base import JsonObject
from station.record.run_dir import MODEL_NAME
from station.record.state import RunState
from station.statement.conclude import conclude
from station.statement.known_machine import DRHO
from station.statement.snapshot import Rounds, Written


@dataclass
class Run:
    run_dir: Path
    config: StationConfig
    plan: Plan
    journal: Journal
    devices: Devices
    operator: Operator
    sim: JsonObject | None
    started_iso: str
    checker: MotionChecker | None = None
    t0: float = field(default_factory=time.monotonic)

    @property
    def state(self) -> RunState:
        """The journal so far, every session's (station.record.state)."""
        return self.journal.state

    @cached_property
    def steps(self) -> Steps:
        """Takes each step the journal does not hold yet (station.engine.replay)."""
        return Steps(self.journal)


class Flow:
    """The steps of station.engine.closed_loop against the devices, each one replayed from the
    journal when a resumed run already did it; fills the result as it goes."""

    def __init__(self, ctx: Run, seq: Sequencer, record: RunRecord) -> None:
        self.ctx, self.seq, self.record = ctx, seq, record
        self.idents: list[Identification] = []  # identification of each round, in order
        self.measurements: list[Measurement] = []  # each round's, its passes pooled
        self.reversal: Reversal | None = None  # the joints' lost motion
        # what no offset changes, round by round: the axes' layout and the legs' bows
        self.layouts = Layouts(ctx.config.machine.geometry(),
                               lambda m, model: _identify(ctx, m, model, self._leads())[0])
        # each joint's error as the run knows it (station.analysis.joints), once the
        # first round is identified: its tables correct the deviations (joint_fit)
        self.known: joints.JointKnowledge | None = None
        # the Δρ the offsets written last aim at: 0 for objective joints; for tool,
        # the joint errors that leave the least tool error (engine.accuracy)
        self.target: dict[str, float] = dict.fromkeys(WRITABLE, 0.0)
        self._grid: np.ndarray | None = None
        self.model: MachineModel | None = None  # model.json, once the run stops
        self.outcomes: list[WritebackOutcome] = []
        self.iterations: list[Iteration] = []
        record.rounds(self.iterations)  # filled round by round
        # each round's Δρ̂ and standard errors joined with the rounds before (_joined)
        self.joined: list[verdict.JoinedRounds] = []
        # the station's own test of the joints, by axis (station.engine.joint_station)
        self.joint_tests: dict[str, JointTested] = {}

    def measure(self, phase: str) -> str:
        """Measure (or replay) a round's first pass and identify it: its verdict
        (station.engine.closed_loop; the first round's correction is written only
        where it stands out of the noise, as every round's)."""
        self._expect(written=True)
        m = self.seq.measure(phase)
        self.measurements.append(m)
        return self._identify_round(m, [phase])

    def extend(self, phase: str) -> str:
        """A further pass of the last round's verification (its noise could not show
        the machine converged, nor a correction worth writing): measured (or
        replayed) and pooled with the round's passes, identified again, decided
        again."""
        self._expect(written=False)
        m = pooled(self.measurements[-1], self.seq.measure(phase))
        self.measurements[-1] = m
        last = self.iterations[-1]
        return self._identify_round(m, [*(last.passes or [last.phase]), phase])

    def _expect(self, written: bool) -> None:
        """Tell the sequencer the machine the next pass should find (it sizes a
        verification's cycles by it): the last fit, with the offsets at their aim
        after a write-back (``written``); none before the first round."""
        if not self.idents:
            return
        ident = self.idents[-1]
        values = after_correction(ident.parameters, self.target) if written \
            else ident.parameters
        self.seq.sizing.expected = (ident.model, params_vector(values))

    def _joined(self, n: int, ident: Identification, phase: str) -> verdict.JoinedRounds:
        """Round ``n``'s Δρ̂ joined with the rounds before it (verdict.joined_round),
        with the error it shares with them through what it carried; kept per round."""
        outcome = self.outcomes[n - 1] if 0 < n <= len(self.outcomes) else None
        earlier = zip(self.iterations[:n], self.idents[:n], strict=True)
        shared = self.layouts.shared(phase, [(it.phase, i) for it, i in earlier])
        fresh = bool(n) and _tilted(ident) and not _tilted(self.idents[n - 1])
        joined = verdict.joined_round(ident, self.joined[n - 1] if n else None,
                                      outcome.before if outcome else None,
                                      outcome.written if outcome else None, shared, fresh)
        del self.joined[n:]
        self.joined.append(joined)
        return joined

    def _identify_round(self, m: Measurement, passes: list[str]) -> str:
        ctx = self.ctx
        again = len(passes) > 1
        n = len(self.idents) - 1 if again else len(self.idents)  # the round's index
        phase = round_phase(passes[0])
        # The joints' tables: what they make of the deviations is taken out before the
        # fit and the model test (station.analysis.joint_fit; the raw m is the record's)
        self.known = joints.of_run_config(ctx.config, tables_of(self.joint_tests))
        # and what the drive's count makes of them: each stop stood at a whole count (J15)
        fit = joint_fit.corrected(ctx.config, m,
                                  joints.round_tables(self.known, self._moved(n)),
                                  ctx.devices.controller.target_resolution_mm())
        m = fit.measurement
        # With auto, every round chooses its model again: misplaced stands bias the
        # first round by (stand error × leg tilt), a misfit no model explains that
        # can push the choice to a tilt model on a square machine; it vanishes with
        # the offsets, so a later round's choice sees the machine as it is.
        # At the middles alone after a round that read the second gauge plane: that
        # round's widest layout fit, bows and all, carried (model_choice.carried_form).
        carried = self.layouts.carry_form(phase, ctx.config, m)
        ident, selection = (carried, None) if carried is not None else \
            _identify(ctx, m, leads=self._leads())
        if n == 0 and selection is not None:
            self.record.model_selection(selection)
        # Lost motion: the joints' reversal from every round so far; every stop was
        # approached from one side, so the fit found Δρ at that edge of each band:
        # what is stated and written is its middle.
        rev = reversal.estimate(ctx.config, self.measurements)
        self.record.lost_motion(reversal.fields(ctx.config, rev))
        self.record.joints(joints.fields(  # the measured B wins over a table's reversal
            self.known.with_reversal(rev.value), details_of(self.joint_tests),
            joint_fit.words(self.known, fit)))
        reversal.check_overrun(ctx.config, rev)
        self.reversal = rev
        if carried is None:  # a carried round's layout is the earlier rounds' own
            self.layouts.add(phase, m, ident)
            if n and selection is not None:  # auto: the tilts the rounds show are held
                ident = self.layouts.with_shown_tilts(
                    phase, m, ident, budget.allowance(ctx.config).straightness)
            ident = self.layouts.carried(phase, ident) if n else ident
        ident = band_middle(ident, rev, ctx.config.procedure.approach)
        if again:
            self.idents[-1] = ident
        else:
            self.idents.append(ident)
        fields = results.measurement_fields(ctx.config, m, ident)
        prev = self.idents[n - 1] if n else None
        proc = ctx.config.procedure
        count = ctx.devices.controller.offset_resolution_mm()
        joined = self._joined(n, ident, phase)
        floor = carry.prior_floor(ident, ctx.config.machine.geometry())
        left = extra_passes_allowed(n, proc.max_extra_passes, proc.max_iterations,
                                    proc.verify) - (len(passes) - 1)
        type_b = _type_b(ctx.config, ident, phase, self._leads())
        limit = verdict.converge_limit(proc.converge_mm, count)
        judged = verdict.judge(ident, prev, limit, self.target,
                               passes_left=left > 0, joined=joined if n else None,
                               floor=floor, passes=(len(passes), left), type_b=type_b)
        sig = judged.significant
        entry = fields.iteration(phase, judged)
        verdict.annotate(entry, ident, ctx.config.machine.geometry(), floor, type_b)
        if n:
            entry.joined = Joined(drho_mm=joined[0], std_errors_mm=joined[1])
        if again:
            entry.passes = passes
            self.iterations[-1] = entry
        else:
            self.iterations.append(entry)
        if n == 0:
            self.record.first_round(fields, None)
            ctx.steps.once(RoundFit(0, len(passes)),
                           {"type": "identification", **results.ident_json(ident),
                            **({"passes": [*passes]} if again else {})})
            return judged.verdict
        self.record.verification(results.verification_fields(
            ctx.config, fields, self.idents[n - 1], self.target,
            edge=edge_of(rev, ctx.config.procedure.approach)))
        ctx.steps.once(RoundFit(n, len(passes)),
                       {"type": "verification", "round": n, "phase": phase,
                        **({"passes": [*passes]} if again else {}), **results.ident_json(ident),
                        "deviations_rms_mm": fields.deviations_rms_mm,
                        "significant": [*sig], "verdict": judged.verdict})
        return judged.verdict

    def _leads(self) -> joints.LeadInputs:
        """The joints' leads the fit cannot see, as bounded inputs (joints.lead_inputs)."""
        return joints.lead_inputs(self.known)

    def _moved(self, n: int) -> dict[str, float]:
        """How far the offsets held in round ``n`` lie from the run's start (mm)."""
        start = self.outcomes[0].before if self.outcomes else None
        held = start
        for o in self.outcomes[:n]:
            held = o.written if o.written is not None else held
        return joint_fit.moved(start, held)

    def write(self, round: int) -> str:
        """Write-back ``round`` (1-based) of the correction the last measurement found."""
        ctx = self.ctx
        ident = self.idents[round - 1]
        first = self.outcomes[0] if self.outcomes else None
        self.target = self._aim()
        note = self._objective_note(ident)
        # What is written is the round's Δρ̂ joined with the rounds before it (the
        # first round's own): the least error results.known, where the rounds agree
        # (orthocal.loop.joined_with_previous keeps a round's own where they do not).
        values = {**ident.parameters, **self.joined[round - 1][0]}
        outcome = write_back(
            controller=ctx.devices.controller,
            identified=correction(values, self.target), note=note,
            max_abs_offset_mm=ctx.config.writeback.max_abs_offset_mm, run_dir=ctx.run_dir,
            journal=ctx.journal, operator=ctx.operator, round=round,
            offsets_at_start=first.before if first is not None else None)
        self.outcomes.append(outcome)
        entry = self.iterations[round - 1]
        entry.offsets_written = None if outcome.written is None else dict(outcome.written)
        entry.writeback = outcome.status
        if ctx.config.writeback.objective != "joints":
            entry.target_drho = dict(self.target)
        self.record.wrote(outcome, round, ctx.devices.controller)
        self.record.totals(self.iterations)
        return outcome.status

    def stopped(self, reason: str) -> None:
        """Status, message and the loop's verdict once station.engine.closed_loop says
        finish; the end of the run (the statement and what reads it) from
        station.statement.conclude."""
        proc = self.ctx.config.procedure
        first = self.outcomes[0] if self.outcomes else None
        last = self.outcomes[-1] if self.outcomes else None
        status, message = _status_of(first) if first is not None else ("ok", None)
        if last is not None and last is not first:
            if last.status == "failed-restored":
                status, message = "failed", f"closed loop, round {len(self.outcomes)}: " \
                    f"{last.reason}"
            elif last.status in ("refused", "declined"):
                message = (f"closed loop stopped before round {len(self.outcomes)}: "
                           f"write-back {last.reason}")
        detail = last.reason if last is not None and reason != "converged" \
            and reason in ("refused", "declined", "failed") else None
        count = self.ctx.devices.controller.offset_resolution_mm()
        remedy = None
        if reason == "max_iterations":
            message = (f"closed loop did not converge: {proc.max_iterations} write-back(s) "
                       "done, the last verification's correction still significant")
            remedy = ("the loop wrote all it may ([procedure] max_iterations): run again "
                      "from the offsets now held, or, if each round finds a new correction, "
                      "look for what the model lacks (a loose gauge or stand, lost motion "
                      "beyond the approach's overrun, a leg or an axis out of its model)")
        if reason == "not-converged":
            detail, remedy = verdict.not_converged(self.iterations[-1], proc.converge_mm,
                                                   count, self.iterations)
            message = f"closed loop did not converge: {detail}"
        if last is None:
            # nothing written: the offsets as found are the run's before and after
            self.record.nothing_written({a: float(v) for a, v in zip(
                "xyz", self.ctx.devices.controller.read_offsets(), strict=True)})
        loop = Loop(
            stopped=reason, detail=detail,
            write_backs=sum(1 for o in self.outcomes if o.status == "written"),
            max_iterations=proc.max_iterations, converge_mm=proc.converge_mm,
            converged_within_mm=verdict.converge_limit(proc.converge_mm, count),
            extra_passes=sum(len(it.passes) - 1 for it in self.iterations if it.passes),
            max_extra_passes=proc.max_extra_passes,
        )
        self._conclude(loop, remedy)
        converged = bool(self.record.result.converged)
        if converged and last is None:
            limit = verdict.converge_limit(proc.converge_mm, count)
            message = (f"within tolerance, nothing written: every joint offset is shown within "
                       f"{1000 * limit:.1f} µm at 95 % and no correction stands out of the "
                       "noise")
        self.record.status(status, message)

    def _conclude(self, loop: Loop, remedy: str | None) -> None:
        """The run's end from its rounds (station.statement.conclude), once, into the
        record; a run whose model holds no Δρ states the loop and the rounds only."""
        if not self.idents or not any(n in self.idents[0].parameters for n in WRITABLE):
            remaining = results.remaining_fields(self.iterations, self.record.result)
            self.record.ended_without_drho(loop, remaining, budget.of_run(
                self.ctx.config, self.idents, remaining))
            return
        end = conclude(self._rounds(loop.stopped), loop, remedy)
        self.record.concluded(end)
        if end.model is not None:
            self._write_model(end.model)

    def _rounds(self, stopped: str) -> Rounds:
        """The snapshot of the rounds the statement is built from."""
        c = self.seq.checker
        before = self.record.result.offsets_before
        return Rounds(
            config=self.ctx.config, idents=tuple(self.idents), joined=tuple(self.joined),
            iterations=tuple(self.iterations),
            layout_rounds=tuple(self.layouts.layout_rounds),
            layout_fits=dict(self.layouts.layout_fits),
            writes=tuple(Written(o.status, o.reason, o.before, o.written)
                         for o in self.outcomes),
            target=dict(self.target), reversal=self.reversal, joints=self.known,
            offsets_before=None if before is None else results.known(before),
            offset_count_mm=self.ctx.devices.controller.offset_resolution_mm(),
            target_count_mm=joint_fit.three_counts(
                self.ctx.devices.controller.target_resolution_mm()),
            limits=(c.lo, c.hi), stopped=stopped)

    # --- accuracy at the tool ------------------------------------------------------

    def _points(self) -> np.ndarray:
        if self._grid is None:
            c = self.seq.checker
            self._grid = accuracy.grid(self.ctx.config, (c.lo, c.hi)).points
        return self._grid

    def _aim(self) -> dict[str, float]:
        """The Δρ the next write aims at (objective joints: 0)."""
        if self.ctx.config.writeback.objective == "joints":
            return dict.fromkeys(WRITABLE, 0.0)
        return self._tool_target()

    def _tool_target(self) -> dict[str, float]:
        """Objective tool's Δρ for the pooled layout, only as far as the model chosen
        for the last round has it: aiming the offsets at tilts or gaps the data do
        not show would chase noise (on a square machine whose axes meet, objective
        tool then writes what objective joints does)."""
        last = self.idents[-1] if self.idents else None
        pooled = accuracy.pool_layout(self.layouts.layout_rounds)
        return accuracy.tool_target(self.ctx.config, pooled, self._points(),
                                    () if last is None else last.names)

    def _objective_note(self, ident: Identification) -> str:
        """What the write-back prompt says of the objective and what each buys."""
        cfg = self.ctx.config
        layout = accuracy.pool_layout(self.layouts.layout_rounds)
        tv = layout.vector() if layout is not None else np.zeros(6)
        points, frame = self._points(), cfg.writeback.frame
        geometry = cfg.machine.geometry()
        figures = {}
        for name, aim in (("joints", dict.fromkeys(WRITABLE, 0.0)),
                          ("tool", self._tool_target())):
            fld = accuracy.error_field(points, geometry, accuracy.params(aim, tv),
                                       np.zeros(3), frame)
            figures[name] = 1000 * fld.rms_mm
        what = {"joints": "the paper's Δρ, legs parallel", "tool": "the least tool error"}
        chosen = cfg.writeback.objective
        other = "tool" if chosen == "joints" else "joints"
        return (f"objective {chosen} ({what[chosen]}): predicted tool error "
                f"{figures[chosen]:.1f} µm RMS over the workspace ({frame} frame); "
                f"objective {other} would leave {figures[other]:.1f} µm")

    def _write_model(self, model: MachineModel) -> None:
        """model.json: the machine identified, through its record (station.record.model):
        what another tool validates model.json against is what the engine writes."""
        self.model = model
        try:
            write_atomic(self.ctx.run_dir / MODEL_NAME,
                         json.dumps(jsonable_value(model.model_dump(mode="json")),
                                    indent=1, allow_nan=False) + "\n")
        except OSError as exc:  # a full disk: result.json says so too, if it can
            say(f"orthocal: {MODEL_NAME} not written ({storage_message(self.ctx.run_dir, exc)})")


def _status_of(outcome: WritebackOutcome) -> tuple[Status, str | None]:
    if outcome.status in ("written", "skipped"):
        return "ok", None
    if outcome.status == "refused":
        return "refused", f"write-back {outcome.reason}"
    if outcome.status == "declined":
        return "aborted", f"write-back {outcome.reason}"
    return "failed", outcome.reason


def _type_b(config: StationConfig, ident: Identification, phase: str,
            leads: joints.LeadInputs) -> dict[str, float]:
    """Each Δρ's Type B standard uncertainty in round ``phase`` (the stated inputs and
    the joints' ``leads`` through the round's sensitivity:
    station.analysis.run_budget.round_columns), as the statement will carry it."""
    held = [d for d in DRHO if d in ident.names]
    if not held:
        return {}
    columns = budget.round_columns(config, ident, phase, leads).pick(held)
    return {d: columns.marginal(d).u_b for d in held}


def _tilted(ident: Identification) -> bool:
    """Whether a round's model holds the axes' tilts."""
    return "tilt" in ident.model.split("+")


def _identify(ctx: Run, m: Measurement, model: str | None = None,
              leads: joints.LeadInputs | None = None
              ) -> tuple[Identification, JsonObject | None]:
    from station.analysis.model_choice import identify_measurement

    return identify_measurement(ctx.config, m, model, leads)


