"""Executes the plan: per setup, mount, then cycles Π0 → Π_i^+ → Π_i^− → Π0
(or through the configured strokes Π_i(s)).

Deviation of a cycle = mean at Π_i^s − mean of the two Π0 stops bracketing it
(cancels linear drift of gauge and machine); a reversed mount ("-y") flips the
sign. Within a stop, a reading far from its siblings (median ± k·1.4826·MAD,
floored at the gauge resolution) is rejected and journaled. Across cycles, a
spread above ``repeatability_mm`` repeats the setup's cycles (at most
``max_repeats`` times) and is reported. With ``target_std_error_mm`` a setup
stops as soon as its deviations' standard error reaches it (≥ 2 cycles; see
:func:`cycle_std_error`).

Resume: each completed cycle is journaled with its deviations; replaying the
journal gives the same decisions (repeats, adaptive stop) without touching a
device, and the run goes live at the first cycle the journal does not hold. A
cycle interrupted half-way is redone whole after remounting: its readings
belong to a mounting that may have moved. Which cycles, repeats and setup ends are
journaled is station.engine.replay's to say (:class:`~station.engine.replay.Steps`),
never this module's.

On any fault or Ctrl-C the axes are stopped (the stop itself guarded), the
fault journaled, and the exception re-raised for the command to report.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from drivers.base import GaugeReadings, Moves, ZeroOffsets
from orthocal.lost_motion import reversal_gain
from orthocal.postures import MIDDLE, plane_at
from station.analysis.statistics import (
    Measurement,
    NoiseScale,
    SetupOutcome,
    StopStat,
    cycle_std_error,
    reject_outliers,
)
from station.config import StationConfig
from station.console.operator import Operator
from station.engine import kept
from station.engine.guard_monitor import GuardMonitor
from station.engine.mover import Mover, MoverAxes
from station.engine.replay import CycleStep, RepeatStep, SetupEnd, Steps
from station.engine.sizing import VerificationSizing
from station.errors import RunFailed, check_interrupted
from station.plan.checker import MotionChecker
from station.plan.steps import (
    REVERSAL,
    Checkpoint,
    Move,
    Plan,
    Prompt,
    Read,
    Settle,
    SetupPlan,
    Step,
    stop_id,
)
from station.record.journal_file import Journal
from station.record.phase import Phase

# A cycle the guard stopped is taken again (at most MAX_RETAKES times) when its
# closing Π0 shows a gauge's zero moved by more than ZERO_MOVED_MM (or the
# repeatability limit, if larger): a knocked stand.
MAX_RETAKES = 2
ZERO_MOVED_MM = 0.005


ProgressSink = Callable[..., None]


def _no_progress(event: str, **info: object) -> None:
    del event, info


class SequencedAxes(MoverAxes, Moves, ZeroOffsets, Protocol):
    """What a sequencer asks of the axes: the mover's, the stop (after a fault, and the
    guard's), and their offsets: their count, by which a verification is sized, and
    their values, whose change shifts the stops under gauges kept mounted."""


@dataclass
class Counters:
    moves: int = 0
    readings: int = 0
    rejected: int = 0
    guard_recoveries: int = 0
    retakes: int = 0


class Sequencer:
    def __init__(
        self,
        *,
        config: StationConfig,
        plan: Plan,
        controller: SequencedAxes,
        indicators: GaugeReadings,
        journal: Journal,
        operator: Operator,
        checker: MotionChecker,
        progress: ProgressSink | None = None,
    ) -> None:
        self.config = config
        self.plan = plan
        self.controller = controller
        self.indicators = indicators
        self.journal = journal
        self.operator = operator
        self.checker = checker
        # a cycle, a repeat or a setup's end the journal holds is not taken again
        self.steps = Steps(journal)
        self.progress = progress or _no_progress
        self.counters = Counters()
        self.passes = 0  # measured or replayed so far: the next's setups, Plan.setups_of
        # Why the stop after a fault did not reach the drive (None: it did, or no
        # fault), so that the operator is never told the axes stopped when unknown.
        self.stop_error: str | None = None
        self._setup: SetupPlan | None = None
        self._live_setup = False
        self._stops: dict[str, dict[str, StopStat]] = {}
        self._all_names = [ind.name for ind in config.indicators]
        self._noise: dict[str, NoiseScale] = {n: NoiseScale() for n in self._all_names}
        self._gains: dict[tuple[str, str, float], float] = {}  # (leg, axis, at) -> gain
        # how many cycles a verification's mounting takes (the flow tells it the
        # machine the verification expects)
        self.sizing = VerificationSizing(config, plan, controller)
        # The guard's records are the run's like any other: one that cannot be saved
        # stops the run (a swallowed error once lost a record that had an infinity).
        self.guard = GuardMonitor(
            config, checker, controller.read_positions,
            lambda names: indicators.read(1, names), controller.stop, journal.append)
        # The guard arms at a mounting's first Π0 reading and watches the cycle after it.
        self._guard_pending = False
        self._guard_cycle: int | None = None
        # The gauges on the machine, kept for the next pass's first setup where the
        # plan check holds (station.engine.kept).
        self.keeper = kept.Keeper(config, plan, checker, controller, journal, self.progress)
        self.mover = Mover(config=config, plan=plan, controller=controller,
                           indicators=indicators, checker=checker, guard=self.guard,
                           journal=journal.append, journal_safe=self._journal_safe,
                           progress=self.progress)

    # --- the procedure ---------------------------------------------------------------

    def measure(self, phase: str) -> Measurement:
        """All setups of one phase ("m" or "v"). Faults stop the axes and propagate."""
        try:
            return self._measure(phase)
        except BaseException as exc:
            self.abort(exc)
            raise

    def abort(self, exc: BaseException) -> None:
        self.keeper.still = None  # what a fault left on the machine is mounted again
        try:
            self.controller.stop()
        except Exception as stop_exc:  # the fault is what matters; note the failed stop
            self.stop_error = str(stop_exc)
            self._journal_safe({"type": "event", "event": {
                "event": "stop-failed", "error": str(stop_exc)}})
        kind = "aborted" if isinstance(exc, KeyboardInterrupt) else "fault"
        self._journal_safe({"type": kind, "error": f"{type(exc).__name__}: {exc}",
                            "device": getattr(exc, "device", None)})
        try:
            self.journal.flush()
        except Exception:
            pass  # nothing more can be saved; the original fault is re-raised

    def _journal_safe(self, record: dict[str, object]) -> None:
        try:
            self.journal.append(record)
        except Exception:
            pass  # the journal itself failed (disk full?); keep reporting the fault

    def _measure(self, phase: str) -> Measurement:
        deviations: dict[str, list[float]] = {}
        outcomes: list[SetupOutcome] = []
        within: list[float] = []
        reversal: dict[str, list[float]] = {}
        index, self.passes = self.passes, self.passes + 1
        self.sizing.pass_index = index
        for sp in kept.order(self.plan.setups_of(index), self.keeper.last):
            outcome, devs, w, rev = self._run_setup(phase, sp)
            outcomes.append(outcome)
            deviations.update(devs)
            within.extend(w)
            for axis, values in rev.items():
                reversal.setdefault(axis, []).extend(values)
        mounts = {k: [len(v)] for k, v in deviations.items()}
        # a pass whose first setup kept the gauges on: its keys go on with that mounting
        kept_on = [o.index for o in outcomes[:1] if (phase, o.index) in self.journal.state.kept]
        continued = tuple(k for i in kept_on for k in kept.keys_of(self.plan.setups[i]))
        return Measurement(phase, deviations, outcomes, within, reversal, mounts, continued)

    def _run_setup(self, phase: str, sp: SetupPlan
                   ) -> tuple[SetupOutcome, dict[str, list[float]], list[float],
                              dict[str, list[float]]]:
        proc = self.config.procedure
        self._setup = sp
        self._live_setup = False
        self.mover.setup = sp
        self.mover.mounted = {}  # a new setup: nothing of ours is mounted until its prompt
        self.checker.preload_shift = {}
        self.guard.forget()
        self._guard_pending, self._guard_cycle = False, None
        cycle = 0
        repeats = 0
        passes: list[list[tuple[int, dict[str, float], list[float], dict[str, float]]]] = []
        while True:
            this_pass: list[tuple[int, dict[str, float], list[float], dict[str, float]]] = []
            for _ in range(proc.cycles):
                cycle += 1
                devs, w, rev = self._cycle(phase, sp, cycle)
                this_pass.append((cycle, devs, w, rev))
                if self._converged([d for _, d, _, _ in this_pass]):
                    break
            # A verification that cannot yet show its verdict: more cycles on the
            # gauges already mounted, not another mounting (replayed alike on resume).
            while (len(this_pass) < self.sizing.cycle_limit(phase)
                   and not self._converged([d for _, d, _, _ in this_pass])
                   and not self.sizing.decided(phase, [d for _, d, _, _ in this_pass])):
                cycle += 1
                devs, w, rev = self._cycle(phase, sp, cycle)
                this_pass.append((cycle, devs, w, rev))
            passes.append(this_pass)
            spread = self._spread([d for _, d, _, _ in this_pass])
            if spread <= proc.repeatability_mm or repeats >= proc.max_repeats:
                break
            repeats += 1
            self.steps.once(RepeatStep(phase, sp.index, repeats),
                            {"type": "repeat", "phase": phase, "setup": sp.index,
                             "spread_mm": spread, "repeat": repeats})
            self.progress("repeat", phase=phase, setup=sp.index, spread=spread)
        used = passes[-1]
        spread = self._spread([d for _, d, _, _ in used])
        keys = list(used[0][1])
        devs_by_key = {k: [d[k] for _, d, _, _ in used] for k in keys}
        within = [s for _, _, w, _ in used for s in w]
        reversal: dict[str, list[float]] = {}
        for *_, rev in used:
            for axis, value in rev.items():
                reversal.setdefault(axis, []).append(value)
        outcome = SetupOutcome(
            index=sp.index, leg=sp.leg, indicators=dict(sp.indicators),
            cycles_used=len(used), cycles_max=self.sizing.cycle_limit(phase), repeats=repeats,
            flagged=spread > proc.repeatability_mm, spread_mm=spread,
            cycles=[c for c, *_ in used])
        self.steps.once(SetupEnd(phase, sp.index),
                        {"type": "setup_done", "phase": phase, "setup": sp.index,
                         "cycles": outcome.cycles, "repeats": repeats,
                         "spread_mm": spread, "flagged": outcome.flagged})
        self.progress("setup_done", phase=phase, setup=sp.index, outcome=outcome)
        self.keeper.ended(phase, sp.index, self._live_setup)
        return outcome, devs_by_key, within, reversal

    def _converged(self, cycles: list[dict[str, float]]) -> bool:
        target = self.config.procedure.target_std_error_mm
        if target is None or len(cycles) < 2:
            return False
        return cycle_std_error(cycles) <= target

    @staticmethod
    def _spread(cycles: list[dict[str, float]]) -> float:
        if len(cycles) < 2:
            return 0.0
        return max(max(c[k] for c in cycles) - min(c[k] for c in cycles) for k in cycles[0])

    # --- one cycle ---------------------------------------------------------------------

    def _cycle(self, phase: str, sp: SetupPlan, cycle: int
               ) -> tuple[dict[str, float], list[float], dict[str, float]]:
        """The cycle's deviations, the readings' scatter at its stops and its reversal,
        from its record: journaled before, or by its Checkpoint now."""
        done = self.steps.take(
            CycleStep(phase, sp.index, cycle), lambda: self._measure_cycle(phase, sp, cycle),
            replayed=lambda _: self.progress("cycle_replayed", phase=phase, setup=sp.index,
                                             cycle=cycle))
        assert done is not None, "a cycle measured is journaled by its checkpoint"
        return (dict(done.deviations), list(done.within_std or []),
                dict(done.reversal_mm or {}))

    def _measure_cycle(self, phase: str, sp: SetupPlan, cycle: int) -> None:
        if not self._live_setup:
            # Going live in this setup: mount (or remount after a resume) at Π0 and
            # read the Π0 that opens this cycle under the current mounting.
            self._live_setup = True
            steps = sp.start_steps(phase, cycle - 1, self.plan.settle_s, self.plan.readings)
            if cycle == 1 and self._keep(phase, sp):
                steps = [s for s in steps if not isinstance(s, Prompt)]
            for step in steps:
                self._execute(phase, step)
        if self._guard_cycle is not None and cycle > self._guard_cycle:
            self.guard.check_cycle(cycle)
        retakes = 0
        while True:
            self.mover.touched = False
            *stops, checkpoint = sp.cycle_steps(phase, cycle, self.plan.settle_s,
                                                self.plan.readings)
            for step in stops:
                self._execute(phase, step)
            moved = self._zero_moved(phase, sp, cycle) if self.mover.touched else None
            if moved is None:
                # the cycle's readings stand: its checkpoint journals the cycle
                self._execute(phase, checkpoint)
                return
            retakes += 1
            if retakes > MAX_RETAKES:
                raise RunFailed(
                    f"plunger guard: {Phase.parse(phase).kind} setup {sp.index + 1} (leg "
                    f"{sp.leg}), cycle {cycle}: {moved} again after {MAX_RETAKES} retakes "
                    "of the cycle; check the stands, then orthocal resume")
            self._retake(phase, sp, cycle, moved)

    def _zero_moved(self, phase: str, sp: SetupPlan, cycle: int) -> str | None:
        """After the guard stopped the axes in this cycle: did a gauge's zero move
        (its Π0 before and after the cycle disagree)? Said in words, or None."""
        start = self._stops[stop_id(phase, sp.index, cycle - 1, "0")]
        end = self._stops[stop_id(phase, sp.index, cycle, "0")]
        limit = max(ZERO_MOVED_MM, self.config.procedure.repeatability_mm)
        moved = {n: end[n].mean - start[n].mean for n in sp.indicators
                 if abs(end[n].mean - start[n].mean) > limit}
        verdict = None if not moved else "the zero of " + ", ".join(
            f"indicator {n} moved by {v:+.3f} mm" for n, v in moved.items()) + (
            f" across a cycle the guard stopped (limit {limit:g} mm): the stand moved")
        self.journal.append({"type": "event", "event": {
            "event": "plunger-guard-zero-check", "phase": phase, "setup": sp.index,
            "cycle": cycle, "limit_mm": limit, "moved": verdict is not None,
            "zero_change_mm": {n: end[n].mean - start[n].mean for n in sp.indicators}}})
        return verdict

    def _retake(self, phase: str, sp: SetupPlan, cycle: int, why: str) -> None:
        """Back to Π0 and its reading again: the readings of a cycle across which a
        gauge's zero moved are taken again (a cycle must not mix readings from
        before and after a knock)."""
        stops = [stop_id(phase, sp.index, cycle - 1, "0")] + [
            stop_id(phase, sp.index, cycle, p) for p in sp.signs]
        self.journal.append({"type": "event", "event": {
            "event": "retake", "phase": phase, "setup": sp.index, "cycle": cycle,
            "stops": stops, "why": why}})
        self.counters.retakes += 1
        for stop in stops[1:]:
            self._stops.pop(stop, None)
        self.guard.restart_cycle()
        self.guard.zero_moved()
        names = tuple(sp.indicators)
        for step in (Settle(self.plan.settle_s),
                     Read(stops[0], sp.index, cycle - 1, "0", names, self.plan.readings)):
            self._execute(phase, step)

    def _finish_cycle(self, phase: str, sp: SetupPlan, cycle: int) -> None:
        start = self._stops[stop_id(phase, sp.index, cycle - 1, "0")]
        tests = [(p, self._stops[stop_id(phase, sp.index, cycle, p)]) for p in sp.order]
        end = self._stops[stop_id(phase, sp.index, cycle, "0")]
        if cycle == self._guard_cycle:
            self.guard.learn({posture: {n: st.mean for n, st in stops.items()}
                              for posture, stops in (*tests, ("0", end))})
        devs: dict[str, float] = {}
        within: list[float] = []
        for name, direction in sp.indicators.items():
            sign = -1.0 if direction.startswith("-") else 1.0
            axis = direction.lstrip("-")
            base = 0.5 * (start[name].mean + end[name].mean)
            for posture, stop in tests:
                devs[f"{sp.key_posture(posture)}{sp.leg}{axis}"] = sign * (stop[name].mean - base)
            for st in (*(stop[name] for _, stop in tests), end[name]):
                if st.std is not None:
                    within.append(st.std)
        reversal = self._reversal(phase, sp, cycle, end)
        self.journal.append({"type": "cycle", "phase": phase, "setup": sp.index,
                             "cycle": cycle, "deviations": devs, "within_std": within,
                             **({"reversal_mm": reversal} if reversal else {})})
        self.progress("cycle", phase=phase, setup=sp.index, cycle=cycle, deviations=devs)

    def _reversal(self, phase: str, sp: SetupPlan, cycle: int,
                  end: Mapping[str, StopStat]) -> dict[str, float]:
        """This cycle's measurement of each joint's reversal (mm), from its reversal
        stop (Π0 from the other side) against its closing Π0: the gauge along j
        sees joint j's shift through the leg (orthocal.lost_motion)."""
        if sp.reversal_overrun is None:
            return {}
        other = self._stops.get(stop_id(phase, sp.index, cycle, REVERSAL))
        if other is None:
            return {}
        side = 1.0 if sp.reversal_overrun > 0 else -1.0  # the reversal stop from above
        out = {}
        for name, direction in sp.indicators.items():
            sign = -1.0 if direction.startswith("-") else 1.0
            axis = direction.lstrip("-")
            gain = self._gain(sp.leg, axis, sp.at)
            out[axis] = side * sign * (other[name].mean - end[name].mean) / gain
        return out

    def _gain(self, leg: str, axis: str, at: float) -> float:
        if (leg, axis, at) not in self._gains:
            geometry = self.config.machine.geometry()
            plane = geometry.mount_plane + plane_at(at, geometry)  # x_leg of the gauges
            self._gains[(leg, axis, at)] = reversal_gain(leg, axis, geometry, mount=plane)
        return self._gains[(leg, axis, at)]

    # --- steps -------------------------------------------------------------------------

    def _execute(self, phase: str, step: Step) -> None:
        check_interrupted()  # a Ctrl-C whose KeyboardInterrupt was lost (station.errors)
        if isinstance(step, Move):
            self._move(step)
        elif isinstance(step, Prompt):
            self._prompt(phase, step)
        elif isinstance(step, Settle):
            if step.seconds > 0:
                time.sleep(step.seconds)
        elif isinstance(step, Read):
            self._read(step)
        elif isinstance(step, Checkpoint):
            # The cycle's record (its deviations, fsynced) is what a resumed run
            # replays the cycle from: once it is on disk, the cycle is done.
            assert self._setup is not None and self._setup.index == step.setup
            self._finish_cycle(phase, self._setup, step.cycle)

    def _keep(self, phase: str, sp: SetupPlan) -> bool:
        """Whether ``sp`` goes on with its gauges still on from the pass before
        (station.engine.kept.Keeper), armed as a mounting if so."""
        if not self.keeper.keep(phase, sp):
            return False
        self.mover.mount(dict(sp.indicators))
        self.guard.forget()
        self._guard_pending, self._guard_cycle = True, None
        return True

    def _move(self, step: Move) -> None:
        self.mover.move(step)
        self.counters.moves = self.mover.moves
        self.counters.guard_recoveries = self.mover.guard_recoveries

    def _prompt(self, phase: str, step: Prompt) -> None:
        indicators = dict(step.indicators)
        self.progress("prompt", phase=phase, setup=step.setup)
        # The operator's time is what a calibration costs (a minute or two per
        # mounting): journaled with the mounting, so a resumed run still counts it.
        asked = time.monotonic()
        self.operator.mount(phase, step.setup, step.leg, indicators, self._all_names,
                            at=step.at, **self.keeper.prompt_words(phase, step))
        operator_s = time.monotonic() - asked
        self.keeper.mounted(step.setup, indicators)
        self.mover.mount(indicators)
        self.guard.forget()
        self._guard_pending, self._guard_cycle = True, None
        self.journal.append({"type": "setup", "phase": phase, "setup": step.setup,
                             "leg": step.leg, "indicators": indicators,
                             **({} if step.at == MIDDLE else {"at": step.at}),
                             "operator_s": round(operator_s, 3),
                             "position": None if self.mover.position is None
                             else [float(v) for v in self.mover.position]})

    def _read(self, step: Read) -> None:
        proc = self.config.procedure
        values = self.indicators.read(step.n, list(step.indicators))
        stats: dict[str, StopStat] = {}
        for name in step.indicators:
            vals = [float(v) for v in values[name]]
            self.journal.append({"type": "reading", "stop": step.stop, "indicator": name,
                                 "values": vals})
            ind = self.config.indicator(name)
            self._noise[name].add(vals)
            keep = reject_outliers(vals, proc.outlier_k, 3.0 * ind.resolution_mm,
                                   self._noise[name].sigma)
            kept = [v for v, k in zip(vals, keep, strict=True) if k]
            rejected = [v for v, k in zip(vals, keep, strict=True) if not k]
            if rejected:
                self.journal.append({"type": "outlier", "stop": step.stop, "indicator": name,
                                     "rejected": rejected, "median": float(np.median(vals))})
                self.counters.rejected += len(rejected)
            arr = np.asarray(kept)
            stats[name] = StopStat(float(arr.mean()),
                                   float(arr.std(ddof=1)) if arr.size > 1 else None,
                                   int(arr.size), rejected)
            self.counters.readings += len(vals)
        self._stops[step.stop] = stats
        if self.mover.position is not None:
            self.guard.at_rest(self.mover.position, {n: st.mean for n, st in stats.items()},
                               step.sign)
        if self._guard_pending and step.sign == "0" and self._setup is not None:
            # The mounting point: travel is counted from these readings.
            self._guard_pending = False
            self._guard_cycle = step.cycle + 1
            self.guard.mount(self._setup, step.stop.split(":")[0],
                             self.mover.mounted, {n: st.mean for n, st in stats.items()},
                             preload_shift=self.checker.preload_shift)
        self.progress("read", phase=step.stop.split(":")[0], stop=step.stop, setup=step.setup,
                      cycle=step.cycle, sign=step.sign, values=values)
