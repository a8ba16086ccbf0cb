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
from station.guard import PlungerGuard
from station.journal import Journal
from station.operator import Operator
from station.plan import (
    Checkpoint,
    MotionChecker,
    Move,
    Plan,
    Prompt,
    Read,
    Settle,
    SetupPlan,
    Step,
    stop_id,
)

MAD_SCALE = 1.4826  # MAD of a normal sample × this ≈ σ


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
            config, checker.nominal_travel, controller.read_positions,
            lambda names: indicators.read(1, names), controller.stop, self._journal_safe)
        # The guard arms at a mounting's first Π0 reading and watches the cycle after it.
        self._guard_pending = False
        self._guard_cycle: int | None = None

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
        for step in sp.cycle_steps(phase, cycle, self.plan.settle_s, self.plan.readings):
            self._execute(phase, step)
        return self._finish_cycle(phase, sp, cycle)

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
        # Always ask the drive: a write-back shifts the counted position of a carriage
        # that has not moved, and a resumed run starts wherever the machine stopped.
        self._position = np.asarray(self.controller.read_positions(), dtype=float)
        if np.allclose(self._position, target, atol=1e-3):
            return  # already there: consecutive setups share Π0
        # The plan was checked from nominal postures; the actual start may differ
        # (first move, resumed run, new offsets), so the path really taken from here
        # is checked again and its waypoints (if any) derived from here.
        legs = self.checker.route(self._position, target, step.label, self._setup,
                                  self._mounted)
        self.progress("move", label=step.label, targets=step.targets)
        self.guard.begin_move(self._position, legs)
        for number, leg in enumerate(legs, start=1):
            # Each waypoint is a move of its own (COMMAND 1, a deadline from its own
            # length); none is a reading stop, so the journal and resume ignore them.
            label = step.label if number == len(legs) else \
                f"{step.label} (waypoint {number}/{len(legs) - 1})"
            start = self._position
            self._position = None  # unknown until the move has arrived
            watch = None if start is None else self.guard.watch(start, leg, label)
            extra = {} if watch is None else {"watch": watch}
            actual = self.controller.move_and_wait(
                list(leg), speed_mm_s=self.config.controller.speed_mm_s, start=start, **extra)
            self._position = np.asarray(actual, dtype=float)
            self.counters.moves += 1

    def _prompt(self, phase: str, step: Prompt) -> None:
        indicators = dict(step.indicators)
        self.progress("prompt", phase=phase, setup=step.setup)
        self.operator.mount(phase, step.setup, step.leg, indicators, self._all_names)
        self._mounted = indicators
        self.guard.forget()
        self._guard_pending, self._guard_cycle = True, None
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
            self.guard.at_rest(self._position, {n: st.mean for n, st in stats.items()})
        if self._guard_pending and step.sign == "0" and self._setup is not None:
            # The mounting point: travel is counted from these readings.
            self._guard_pending = False
            self._guard_cycle = step.cycle + 1
            self.guard.mount(self.checker.motion, self._setup, step.stop.split(":")[0],
                             self._mounted, {n: st.mean for n, st in stats.items()})
        self.progress("read", phase=step.stop.split(":")[0], stop=step.stop, setup=step.setup,
                      cycle=step.cycle, sign=step.sign, values=values)
