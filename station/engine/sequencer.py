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
belong to a mounting that may have moved.

On any fault or Ctrl-C the axes are stopped (the stop itself guarded), the
fault journaled, and the exception re-raised for the command to report.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from drivers.base import AxisController
from station.config import StationConfig
from station.errors import BadInput, RunFailed
from station.guard import PlungerGuard, PlungerGuardStop, PlungerGuardTrip
from station.journal import Journal
from station.operator import Operator
from station.plan import (
    SIGNAL_PAD_MM,
    Checkpoint,
    MotionChecker,
    Move,
    PathRefused,
    Plan,
    Prompt,
    Read,
    Settle,
    SetupPlan,
    Step,
    stop_id,
)

MAD_SCALE = 1.4826  # MAD of a normal sample × this ≈ σ
# The plunger guard's second line: after a trip the rest of the move is re-planned
# from where the axes stopped, at this fraction of the speed (again at each trip of
# the same mounting, down to MIN_SPEED_FRACTION), at most MAX_RECOVERIES times per
# mounting; the cycle the trip touched is taken again (at most MAX_RETAKES times)
# when its closing Π0 shows a gauge's zero moved by more than ZERO_MOVED_MM (or the
# repeatability limit, if larger): a knocked stand.
RECOVERY_SPEED_FACTOR = 0.5
MIN_SPEED_FRACTION = 0.1
MAX_RECOVERIES = 6
MAX_RETAKES = 2
ZERO_MOVED_MM = 0.005
# Waypoints a re-plan may use: from a plunger stopped close to its end the first
# sub-moves must be short (their box small), growing as it gets away.
RECOVERY_WAYPOINTS = 40
# How long the axes may take to come to rest after the guard's stop (COMMAND 2).
STOP_TIMEOUT_S = 10.0


def split_key(key: str) -> tuple[str, str, str]:
    """A JSON deviation key ("+xy", "+30xy", "-50.5zx") as (posture, leg, direction)."""
    return key[:-2], key[-2], key[-1]


class ReadingSource(Protocol):
    """What the sequencer needs of an indicator group (drivers.indicators.IndicatorGroup)."""

    def read(self, n: int = 1, names: Sequence[str] | None = None) -> dict[str, list[float]]: ...


Progress = Callable[..., None]


def _no_progress(event: str, **info: Any) -> None:
    del event, info


def reject_outliers(
    values: Sequence[float], k: float, floor: float, scale: float | None = None
) -> list[bool]:
    """Mask of kept readings: |r − median| ≤ max(k·1.4826·MAD, k·scale, floor).

    ``scale`` is the gauge's pooled robust scatter about its stop medians over the
    run so far (see :class:`NoiseScale`). With five readings per stop the stop's own
    MAD is often near zero by chance (and exactly zero on quantised data), which
    alone would reject a few percent of perfectly normal readings; the pooled
    scale keeps the bound at k·σ while a knock of tenths of a mm still stands out.
    """
    v = np.asarray(values, dtype=float)
    if v.size < 3:
        return [True] * int(v.size)
    med = float(np.median(v))
    mad = float(np.median(np.abs(v - med)))
    bound = max(k * MAD_SCALE * mad, k * (scale or 0.0), floor)
    return [bool(abs(x - med) <= bound + 1e-12) for x in v]


class NoiseScale:
    """Robust σ of one gauge's readings, pooled over every stop so far:
    1.4826 · median |r| with r the residuals about each stop's mean scaled by
    sqrt(n/(n−1)) (unbiased for normal noise). Residuals about the stop *median*
    would read low: one reading of every odd-sized stop is the median itself.
    A knocked stop contributes n residuals to a pool of hundreds, so the median
    ignores it."""

    def __init__(self) -> None:
        self._abs_dev: list[float] = []

    def add(self, values: Sequence[float]) -> None:
        v = np.asarray(values, dtype=float)
        if v.size >= 3:
            scale = math.sqrt(v.size / (v.size - 1))
            self._abs_dev.extend((np.abs(v - v.mean()) * scale).tolist())

    @property
    def sigma(self) -> float | None:
        return MAD_SCALE * float(np.median(self._abs_dev)) if self._abs_dev else None


# Consecutive cycles share their Π0 stop: with independent noise at every stop,
# a deviation P_k − (Z_{k−1} + Z_k)/2 has variance 1.5·s² and covariance s²/4
# with the next cycle's, a lag-1 correlation of 1/6.
SHARED_P0_CORRELATION = 1.0 / 6.0


def cycle_std_error(cycles: Sequence[Mapping[str, float]]) -> float:
    """Standard error of a deviation's mean over ``cycles`` (one setup's per-cycle
    deviations, ≥ 2 cycles), from their scatter across cycles.

    The variance is pooled over the setup's deviations (same gauges, same
    machine): a per-deviation estimate has one degree of freedom at two cycles,
    and requiring all four of them below a target stops late on the largest
    draw. The shared Π0 makes the scatter understate the per-cycle variance by
    (1 − 2ρ/c) while the mean's variance exceeds variance/c by (1 + 2ρ(c−1)/c);
    uncorrected, a setup stops ~18 % above its target."""
    c = len(cycles)
    if c < 2:
        return math.inf
    var = float(np.mean([np.var([cy[k] for cy in cycles], ddof=1) for k in cycles[0]]))
    rho = SHARED_P0_CORRELATION
    factor = (c + 2.0 * (c - 1) * rho) / (c - 2.0 * rho)
    return math.sqrt(var * factor / c)


@dataclass
class StopStat:
    mean: float
    std: float | None  # of the kept readings
    kept: int
    rejected: list[float]


@dataclass
class SetupOutcome:
    index: int
    leg: str
    indicators: dict[str, str]
    cycles_used: int
    cycles_max: int
    repeats: int
    flagged: bool
    spread_mm: float
    cycles: list[int] = field(default_factory=list)


@dataclass
class Measurement:
    phase: str
    # key "+xy" -> per-cycle deviations (the used pass of its setup)
    deviations: dict[str, list[float]]
    setups: list[SetupOutcome]
    within_std: list[float]  # std of the readings at each stop, for the noise estimate

    def stats(self) -> dict[str, dict[str, Any]]:
        out = {}
        for key, vals in self.deviations.items():
            arr = np.asarray(vals)
            out[key] = {"mean": float(arr.mean()),
                        "std": float(arr.std(ddof=1)) if arr.size > 1 else None,
                        "n": int(arr.size)}
        return out

    @property
    def noise_mm(self) -> float | None:
        if not self.within_std:
            return None
        return float(math.sqrt(np.mean(np.square(self.within_std))))

    def for_identify(self) -> dict[tuple[str, str, str], list[float]]:
        return {split_key(k): list(v) for k, v in self.deviations.items()}


@dataclass
class Counters:
    moves: int = 0
    readings: int = 0
    rejected: int = 0
    guard_recoveries: int = 0
    retakes: int = 0


def _phase_name(phase: str) -> str:
    return "verification" if phase.startswith("v") else "measurement"


class Sequencer:
    def __init__(
        self,
        *,
        config: StationConfig,
        plan: Plan,
        controller: AxisController,
        indicators: ReadingSource,
        journal: Journal,
        operator: Operator,
        checker: MotionChecker,
        done_cycles: Mapping[tuple[str, int, int], dict[str, Any]] | None = None,
        done_setups: set[tuple[str, int]] | None = None,
        progress: Progress | None = None,
    ) -> None:
        self.config = config
        self.plan = plan
        self.controller = controller
        self.indicators = indicators
        self.journal = journal
        self.operator = operator
        self.checker = checker
        # (phase, setup, cycle) -> the journal's "cycle" record
        self.done_cycles = dict(done_cycles or {})
        self.done_setups = set(done_setups or set())
        self.progress = progress or _no_progress
        self.counters = Counters()
        # Why the stop after a fault did not reach the drive (None: it did, or no
        # fault), so that the operator is never told the axes stopped when unknown.
        self.stop_error: str | None = None
        self._position: np.ndarray | None = None
        self._mounted: dict[str, str] = {}
        self._setup: SetupPlan | None = None
        self._live_setup = False
        self._stops: dict[str, dict[str, StopStat]] = {}
        self._all_names = [ind.name for ind in config.indicators]
        self._noise: dict[str, NoiseScale] = {n: NoiseScale() for n in self._all_names}
        self.guard = PlungerGuard(
            config, checker, controller.read_positions,
            lambda names: indicators.read(1, names), controller.stop, self._journal_safe)
        # The guard arms at a mounting's first Π0 reading and watches the cycle after it.
        self._guard_pending = False
        self._guard_cycle: int | None = None
        # The posture the axes last arrived at ("0", "+", "-", "+30"; None: unknown),
        # the speed factor and recoveries of the current mounting, and whether the
        # guard stopped the axes in the cycle in progress.
        self._at: str | None = None
        self._touched = False
        self._leg_start: np.ndarray | None = None  # where the sub-move in progress began
        self._speed_factor = 1.0
        self._recoveries = 0
        #: Recovered guard events (the summary and the report list them).
        self.recovered: list[dict[str, Any]] = []

    # --- the procedure ---------------------------------------------------------------

    def measure(self, phase: str) -> Measurement:
        """All setups of one phase ("m" or "v"). Faults stop the axes and propagate."""
        try:
            return self._measure(phase)
        except BaseException as exc:
            self.abort(exc)
            raise

    def abort(self, exc: BaseException) -> None:
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

    def _journal_safe(self, record: dict[str, Any]) -> None:
        try:
            self.journal.append(record)
        except Exception:
            pass  # the journal itself failed (disk full?); keep reporting the fault

    def _measure(self, phase: str) -> Measurement:
        deviations: dict[str, list[float]] = {}
        outcomes: list[SetupOutcome] = []
        within: list[float] = []
        for sp in self.plan.setups:
            outcome, devs, w = self._run_setup(phase, sp)
            outcomes.append(outcome)
            deviations.update(devs)
            within.extend(w)
        return Measurement(phase, deviations, outcomes, within)

    def _run_setup(self, phase: str, sp: SetupPlan
                   ) -> tuple[SetupOutcome, dict[str, list[float]], list[float]]:
        proc = self.config.procedure
        self._setup = sp
        self._live_setup = False
        self._mounted = {}  # a new setup: nothing of ours is mounted until its prompt
        self.guard.forget()
        self._guard_pending, self._guard_cycle = False, None
        cycle = 0
        repeats = 0
        passes: list[list[tuple[int, dict[str, float], list[float]]]] = []
        while True:
            this_pass: list[tuple[int, dict[str, float], list[float]]] = []
            for _ in range(proc.cycles):
                cycle += 1
                devs, w = self._cycle(phase, sp, cycle)
                this_pass.append((cycle, devs, w))
                if self._converged([d for _, d, _ in this_pass]):
                    break
            passes.append(this_pass)
            spread = self._spread([d for _, d, _ in this_pass])
            if spread <= proc.repeatability_mm or repeats >= proc.max_repeats:
                break
            repeats += 1
            if (phase, sp.index, cycle + 1) not in self.done_cycles:
                self.journal.append({"type": "repeat", "phase": phase, "setup": sp.index,
                                     "spread_mm": spread, "repeat": repeats})
            self.progress("repeat", phase=phase, setup=sp.index, spread=spread)
        used = passes[-1]
        spread = self._spread([d for _, d, _ in used])
        keys = list(used[0][1])
        devs_by_key = {k: [d[k] for _, d, _ in used] for k in keys}
        within = [s for _, _, w in used for s in w]
        outcome = SetupOutcome(
            index=sp.index, leg=sp.leg, indicators=dict(sp.indicators),
            cycles_used=len(used), cycles_max=proc.cycles, repeats=repeats,
            flagged=spread > proc.repeatability_mm, spread_mm=spread,
            cycles=[c for c, _, _ in used])
        if (phase, sp.index) not in self.done_setups:
            self.journal.append({"type": "setup_done", "phase": phase, "setup": sp.index,
                                 "cycles": outcome.cycles, "repeats": repeats,
                                 "spread_mm": spread, "flagged": outcome.flagged})
        self.progress("setup_done", phase=phase, setup=sp.index, outcome=outcome)
        return outcome, devs_by_key, within

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
               ) -> tuple[dict[str, float], list[float]]:
        done = self.done_cycles.get((phase, sp.index, cycle))
        if done is not None:
            self.progress("cycle_replayed", phase=phase, setup=sp.index, cycle=cycle)
            return dict(done["deviations"]), list(done.get("within_std", []))
        if not self._live_setup:
            # Going live in this setup: mount (or remount after a resume) at Π0 and
            # read the Π0 that opens this cycle under the current mounting.
            self._live_setup = True
            for step in sp.start_steps(phase, cycle - 1, self.plan.settle_s,
                                       self.plan.readings):
                self._execute(phase, step)
        if self._guard_cycle is not None and cycle > self._guard_cycle:
            self.guard.check_cycle(cycle)
        retakes = 0
        while True:
            self._touched = False
            for step in sp.cycle_steps(phase, cycle, self.plan.settle_s, self.plan.readings):
                self._execute(phase, step)
            moved = self._zero_moved(phase, sp, cycle) if self._touched else None
            if moved is None:
                return self._finish_cycle(phase, sp, cycle)
            retakes += 1
            if retakes > MAX_RETAKES:
                raise RunFailed(
                    f"plunger guard: {_phase_name(phase)} setup {sp.index + 1} (leg "
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
            stop_id(phase, sp.index, cycle, p) for p in (*sp.order, "0")]
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

    def _finish_cycle(self, phase: str, sp: SetupPlan, cycle: int
                      ) -> tuple[dict[str, float], list[float]]:
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
                devs[f"{posture}{sp.leg}{axis}"] = sign * (stop[name].mean - base)
            for st in (*(stop[name] for _, stop in tests), end[name]):
                if st.std is not None:
                    within.append(st.std)
        self.journal.append({"type": "cycle", "phase": phase, "setup": sp.index,
                             "cycle": cycle, "deviations": devs, "within_std": within})
        self.progress("cycle", phase=phase, setup=sp.index, cycle=cycle, deviations=devs)
        return devs, within

    # --- steps -------------------------------------------------------------------------

    def _execute(self, phase: str, step: Step) -> None:
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
            pass  # the cycle record written by _finish_cycle is the checkpoint

    def _move(self, step: Move) -> None:
        target = np.asarray(step.targets, dtype=float)
        sign = self._sign_of(step)
        # Always ask the drive: a write-back shifts the counted position of a carriage
        # that has not moved, and a resumed run starts wherever the machine stopped.
        self._position = np.asarray(self.controller.read_positions(), dtype=float)
        if np.allclose(self._position, target, atol=1e-3):
            self._at = sign
            return  # already there: consecutive setups share Π0
        # The plan was checked from nominal postures; the actual start may differ
        # (first move, resumed run, new offsets), so the move is checked again from
        # here and its waypoints (if any) derived from here; once the guard has
        # learned the mounting's signal, it is part of the check.
        signal = self._route_signal(sign)
        # Where the guard no longer watches, the route must keep its margin.
        strict = bool(self._mounted) and self.guard.enabled and not self.guard.watching
        try:
            legs = self.checker.route(self._position, target, step.label, self._setup,
                                      self._mounted, signal=signal, strict=strict)
        except PathRefused as exc:
            if not (self._mounted and signal is not None):
                raise  # the plan's own check, from where the machine stands: bad input
            raise PlungerGuardStop(
                f"plunger guard: with the travel measured under this mounting, "
                f"{str(exc).removeprefix('plan: ')}. Re-mount the gauge with "
                f"{'less' if exc.pushed else 'more'} preload or use a longer stroke"
            ) from None
        self.progress("move", label=step.label, targets=step.targets)
        self._at = None
        self.guard.begin_move(self._position, legs, signal)
        touched = False
        trip: PlungerGuardTrip | None = None
        while True:
            try:
                if trip is not None:  # inside the try: a trip on the way back is caught
                    legs = self._recover(step, trip, sign)
                    trip = None
                self._sub_moves(step, legs)
                break
            except PlungerGuardTrip as exc:
                trip, touched = exc, True
        self._at = sign
        if touched:
            self._touched = True

    def _route_signal(self, sign: str | None) -> dict[str, tuple[float, float]] | None:
        """The travel beyond the nominal model a move of this mounting is routed with
        (at its start, at its target): what the guard measured at both stops (None:
        a stop not read yet under this mounting)."""
        if not self._mounted:
            return None
        return self.guard.route_signal(self._at, sign)

    def _sign_of(self, step: Move) -> str | None:
        """The posture a move goes to, from the setup's postures (None: not one)."""
        if self._setup is None:
            return "0" if step.label == "Π0" else None
        for sign, targets in self._setup.postures.items():
            if tuple(targets) == tuple(step.targets):
                return sign
        return None

    def _sub_moves(self, step: Move, legs: Sequence[np.ndarray], watched: bool = False
                   ) -> None:
        """One COMMAND 1 per target of ``legs`` (``watched``: a way back after a
        trip, labelled so)."""
        speed = self.config.controller.speed_mm_s * self._speed_factor
        for number, leg in enumerate(legs, start=1):
            # Each waypoint is a move of its own (COMMAND 1, a deadline from its own
            # length); none is a reading stop, so the journal and resume ignore them.
            label = step.label if number == len(legs) and not watched else \
                f"{step.label} ({'way back' if watched else 'waypoint'} {number}/" \
                f"{len(legs) - (0 if watched else 1)})"
            start = self._position
            self._leg_start = start
            self._position = None  # unknown until the move has arrived
            watch = None if start is None else self.guard.watch(start, leg, label)
            extra = {} if watch is None else {"watch": watch}
            actual = self.controller.move_and_wait(
                list(leg), speed_mm_s=speed, start=start, **extra)
            self._position = np.asarray(actual, dtype=float)
            self.counters.moves += 1

    def _recover(self, step: Move, trip: PlungerGuardTrip, sign: str | None
                 ) -> list[np.ndarray]:
        """The guard stopped the axes mid-move: wait until they rest and measure the
        gauges there; back to where the interrupted sub-move began (its box lies
        inside the one just travelled, and there the leg is parallel again), measure
        again, and re-plan the rest of the move from there with what the gauges
        showed (more waypoints where needed), at a lower speed. Where the way back
        does not hold, the rest is re-planned from where the axes stand. Raises the
        trip (the run stops) when no safe path is left; returns the sub-moves on."""
        self._recoveries += 1
        here, means = self._at_rest_after_stop()
        record: dict[str, Any] = {
            "event": "plunger-guard-recovery", "indicator": trip.indicator,
            "where": self.guard.where, "move": trip.label, "from": [float(v) for v in here],
            "readings_mm": means}
        if self._recoveries > MAX_RECOVERIES:
            record["result"] = f"stopped: {MAX_RECOVERIES} recoveries on this mounting"
            self._journal_safe({"type": "event", "event": record})
            raise PlungerGuardStop(
                f"{trip} (the guard stopped this mounting's axes {self._recoveries} times; "
                "check the stand)") from None
        self._speed_factor = max(MIN_SPEED_FRACTION,
                                 self._speed_factor * RECOVERY_SPEED_FACTOR)
        speed = self.config.controller.speed_mm_s * self._speed_factor
        target = np.asarray(step.targets, dtype=float)
        # what the trip predicted at the target, before the way back moves the guard on
        ahead = self.guard.signal_envelope(sign)
        self.guard.expect_stop(sign)
        back = self._leg_start
        if back is not None and np.max(np.abs(back - here)) > 1e-3:
            try:
                retreat = self._replan(here, back, step.label, self.guard.retreat_signal())
            except BadInput:
                retreat = None  # no safe way back: on from here
            if retreat is not None:
                record["back_to"] = [float(v) for v in back]
                self._sub_moves(step, retreat, watched=True)  # a trip here: caught by _move
                here, means = self._at_rest_after_stop()
        signal = {n: (now, ahead[n][1]) for n, (now, _) in
                  self.guard.signal_envelope(sign).items()}
        record["signal_mm"] = {n: list(v) for n, v in signal.items()}
        try:
            legs = self._replan(here, target, step.label, signal)
        except BadInput as exc:
            record["result"] = f"no safe path: {exc}"
            self._journal_safe({"type": "event", "event": record})
            raise PlungerGuardStop(
                f"{trip}; no safe path from where the axes stopped: "
                f"{str(exc).removeprefix('plan: ')}") from None
        record.update(result="recovered", waypoints=len(legs) - 1, speed_mm_s=speed,
                      route=[[float(v) for v in leg] for leg in legs])
        self.journal.append({"type": "event", "event": record})
        self.recovered.append(record)
        self.counters.guard_recoveries += 1
        self.progress("guard_recovered", label=step.label, indicator=trip.indicator)
        return legs

    def _at_rest_after_stop(self) -> tuple[np.ndarray, dict[str, float]]:
        """Positions once the axes rest, and the mounted gauges' mean readings there
        (what the guard's signal is then measured from)."""
        here = self._wait_stopped()
        self._position = here
        names = list(self._mounted)
        values = self.indicators.read(max(1, self.plan.readings), names)
        means = {n: float(np.mean(values[n])) for n in names}
        self.guard.at_rest(here, means)
        return here, means

    def _replan(self, here: np.ndarray, target: np.ndarray, label: str,
                signal: dict[str, tuple[float, float]]) -> list[np.ndarray]:
        """A route from where a plunger may stand inside the margin: it may come no
        closer to its end than it is (less a reading's pad), never past it; the guard
        watches it with that margin. Raises BadInput when none holds."""
        margin = min(self.guard.margin, self.guard.slack_now() - SIGNAL_PAD_MM)
        if margin < 0:
            raise BadInput(f"plan: a plunger stands within {SIGNAL_PAD_MM:g} mm of the end "
                           "of its stroke")
        legs = self.checker.route(here, target, label, self._setup, self._mounted,
                                  signal=signal, strict=True, margin=margin,
                                  max_waypoints=RECOVERY_WAYPOINTS)
        self.guard.begin_move(here, legs, signal, margin=margin)
        return legs

    def _wait_stopped(self) -> np.ndarray:
        """Positions once the drive reports no motion (finite wait: STOP_TIMEOUT_S)."""
        deadline = time.monotonic() + STOP_TIMEOUT_S
        while True:
            status = self.controller.read_status()
            if not status.moving:
                return np.asarray(self.controller.read_positions(), dtype=float)
            if time.monotonic() >= deadline:
                raise RunFailed(f"plunger guard: the axes still move {STOP_TIMEOUT_S:g} s "
                                "after the stop; check the drive")
            time.sleep(0.01)

    def _prompt(self, phase: str, step: Prompt) -> None:
        indicators = dict(step.indicators)
        self.progress("prompt", phase=phase, setup=step.setup)
        self.operator.mount(phase, step.setup, step.leg, indicators, self._all_names)
        self._mounted = indicators
        self.guard.forget()
        self._guard_pending, self._guard_cycle = True, None
        self._speed_factor, self._recoveries = 1.0, 0
        self.journal.append({"type": "setup", "phase": phase, "setup": step.setup,
                             "leg": step.leg, "indicators": indicators,
                             "position": None if self._position is None
                             else [float(v) for v in self._position]})

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
        if self._position is not None:
            self.guard.at_rest(self._position, {n: st.mean for n, st in stats.items()},
                               step.sign)
        if self._guard_pending and step.sign == "0" and self._setup is not None:
            # The mounting point: travel is counted from these readings.
            self._guard_pending = False
            self._guard_cycle = step.cycle + 1
            self.guard.mount(self._setup, step.stop.split(":")[0],
                             self._mounted, {n: st.mean for n, st in stats.items()})
        self.progress("read", phase=step.stop.split(":")[0], stop=step.stop, setup=step.setup,
                      cycle=step.cycle, sign=step.sign, values=values)
