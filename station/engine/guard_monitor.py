"""The plunger guard's runtime monitor: gauges polled as the axes move, stopped, or refused."""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from drivers.base import Vec3
from station.config import StationConfig
from station.engine.guard_words import AxesSeen, likely_cause
from station.errors import RunFailed
from station.plan.checker import MotionChecker, PathRefused
from station.plan.guard import (
    GuardedGauge,
    MoveRecord,
    later_travel,
    signal_slope,
    stop_of,
    travel_ahead,
)
from station.plan.steps import SetupPlan, posture_label
from station.record.phase import Phase

# Nominal travel change within one poll window below which the signal estimate is
# taken as exact (the gauge's sampling instant no longer matters).
QUIET_MM = 0.05
# Positions within this of the sub-move's target: the axes have arrived.
ARRIVED_MM = 0.002
# A gauge whose signal, back where the interrupted sub-move began, differs from
# what it was there by more than this (or the config's repeatability) had its zero
# moved: the same joint positions, so the smooth part of the signal is the same.
ZERO_STEP_MM = 0.01


class PlungerGuardStop(RunFailed):
    """A plunger would have come within the margin of an end of its stroke."""


class PlungerGuardTrip(PlungerGuardStop):
    """The guard stopped the axes mid-move; the sequencer may re-plan from where
    they stand (``indicator``, ``label``: the gauge and the move)."""

    def __init__(self, message: str, indicator: str, label: str) -> None:
        super().__init__(message)
        self.indicator = indicator
        self.label = label


class GuardMonitor:
    """One per sequencer. ``mount`` when a mounting's first Π0 has been read,
    ``watch`` for each (sub-)move of its first cycle, ``learn`` at the end of that
    cycle, ``check_cycle`` before each later one."""

    def __init__(self, config: StationConfig, checker: MotionChecker,
                 positions: Callable[[], np.ndarray],
                 read: Callable[[list[str]], dict[str, list[float]]],
                 stop: Callable[[], None], journal: Callable[[dict[str, object]], None]
                 ) -> None:
        self.config = config
        self.enabled = config.procedure.plunger_guard
        self.margin = config.procedure.plunger_margin_mm
        self._move_margin = self.margin
        self._shifted = False
        # the sub-move in progress began at a stop read at rest (its leg_signal exact)
        self._at_rest = self._leg_exact = False
        self._replanned = False  # the move in progress is a re-plan after a stop
        self._checker = checker
        self._nominal = checker.nominal_travel  # (setup, name, direction, path) -> travel
        self._positions = positions
        self._read = read
        self._stop = stop
        self._journal = journal
        self._setup: SetupPlan | None = None
        self._where = ""
        self._gauges: dict[str, GuardedGauge] = {}
        self.watching = False
        self._moves: list[MoveRecord] = []
        # (move label, gauge) -> predicted (min, max) travel for later cycles
        self.predicted: dict[tuple[str, str], tuple[float, float]] = {}
        # posture ("0", "+", "-", "+30") -> gauge -> signal at that stop, learned in
        # the mounting's first cycle (route_signal)
        self.stop_signal: dict[str, dict[str, float]] = {}
        self.polls = 0
        # The smallest distance of a prediction from the margin so far (mm).
        self.slack = np.inf
        # where the axes stood under the mounting: a stop says what moved
        self.axes_seen = AxesSeen()

    # --- a mounting --------------------------------------------------------------------

    @property
    def _sp(self) -> SetupPlan:
        """The setup of the mounting watched (``mount`` sets it before any watch)."""
        if self._setup is None:
            raise RuntimeError("plunger guard: no mounting")
        return self._setup

    def mount(self, setup: SetupPlan, phase: str, mounted: Mapping[str, str],
              baseline: Mapping[str, float],
              preload_shift: Mapping[str, float] | None = None) -> None:
        """Start watching a new mounting; ``baseline``: each gauge's Π0 reading;
        ``preload_shift``: the travel a kept mounting's plungers already stand at there
        (station.engine.kept), their preload's part beyond the config's."""
        self._setup = setup
        self._where = f"{Phase.parse(phase).kind} setup {setup.index + 1} (leg {setup.leg})"
        self._gauges = {}
        for name, direction in mounted.items():
            ind = self.config.indicator(name)
            preload = ind.preload + (preload_shift or {}).get(name, 0.0)
            self._gauges[name] = GuardedGauge(name, direction, -preload,
                                        ind.stroke_mm - preload, float(baseline[name]))
        self._moves = []
        self.axes_seen = AxesSeen()
        self.predicted = {}
        # the mounting point: travel 0 by definition
        self.stop_signal = {"0": {n: 0.0 for n in self._gauges}}
        self._shifted = False
        self.slack = np.inf
        self._move_margin = self.margin
        # the mounting point is read at rest at Π0 (its signal 0 by definition)
        self._at_rest, self._leg_exact = True, False
        self.watching = self.enabled and bool(self._gauges)

    @property
    def where(self) -> str:
        """The mounting watched, in words ("measurement setup 1 (leg x)")."""
        return self._where

    def forget(self) -> None:
        self._gauges = {}
        self.watching = False
        self.predicted = {}
        self.stop_signal = {}

    def restart_cycle(self) -> None:
        """The cycle in progress is taken again (after a recovered trip): what its
        moves showed so far is no prediction of the cycle that replaces it."""
        self._moves = []
        self.slack = np.inf

    # --- while moving ------------------------------------------------------------------

    def begin_move(self, start: Vec3, legs: Sequence[Vec3],
                   signal: Mapping[str, tuple[float, float]] | None = None,
                   margin: float | None = None) -> None:
        """A move from a stop (``start``) through its sub-moves' targets ``legs``: the
        bound of the nominal travel over every sub-move and its progress along the
        move; the signal at rest anchors the move. ``signal``: the signal at the
        start and the target the move was routed with; its change is the slope
        carried ahead until the move's own samples tell it. ``margin``: this move's,
        instead of plunger_margin_mm (a re-plan from where a plunger stood closer to
        its end: it may come no closer than that)."""
        self.axes_seen.at([start])
        if not self.watching:
            return
        self._move_margin = self.margin if margin is None else margin
        self._replanned = margin is not None
        a = np.asarray(start, dtype=float)
        b = np.asarray(legs[-1], dtype=float)
        self._route_a, self._route_d = a, b - a
        self._route_legs = [np.asarray(leg, dtype=float) for leg in legs]
        starts = [a, *self._route_legs[:-1]]
        self._route_bounds = [self._checker.travel_bound(self._sp, self._mounting(), u, v)
                              for u, v in zip(starts, self._route_legs, strict=True)]
        self._route_u = [(float(self._progress(u)), float(self._progress(v)))
                         for u, v in zip(starts, self._route_legs, strict=True)]
        for name, g in self._gauges.items():
            g.start_signal = g.end_signal = g.signal
            g.samples = []
            ends = (signal or {}).get(name)
            g.prior_slope = 0.0 if ends is None else float(ends[1] - ends[0])
        self._leg_index = 0

    def _mounting(self) -> dict[str, str]:
        return {n: g.direction for n, g in self._gauges.items()}

    def _progress(self, p: np.ndarray) -> np.ndarray:
        """Fraction of the move done at joint position(s) p (projection on its chord)."""
        d = self._route_d
        norm = float(d @ d)
        if norm <= 0:
            return np.zeros(np.shape(p)[:-1])
        return np.clip((np.asarray(p) - self._route_a) @ d / norm, 0.0, 1.0)

    def watch(self, start: Vec3, target: Vec3, label: str
              ) -> Callable[[], None] | None:
        """The poll for the next sub-move of the move begun by begin_move (None: not
        watching)."""
        if not self.watching:
            return None
        index = self._leg_index
        self._leg_index += 1
        target_v = np.asarray(target, dtype=float)
        record = MoveRecord(label, nominal=dict(self._route_bounds[index]),
                             off_route=self._replanned)
        self._moves.append(record)
        names = list(self._gauges)
        mounting = self._mounting()
        arrived = [False]
        for g in self._gauges.values():
            g.leg_signal = g.signal
        # Exact only where the sub-move starts from a stop read at rest (at_rest): at a
        # waypoint it is the last poll's estimate, which may not have seen the arrival.
        self._leg_exact, self._at_rest = self._at_rest, False

        def poll() -> None:
            if arrived[0]:
                # The last poll found the axes at the target (measured, not modelled):
                # the drive is about to report it; a poll now would only delay that.
                return
            before = np.asarray(self._positions(), dtype=float)
            if np.all(np.abs(before - target_v) <= ARRIVED_MM):
                # At the target: the stop is read at rest next; a reading now costs a
                # line time and tells nothing the plan did not check there.
                arrived[0] = True
                return
            values = self._read(names)
            after = np.asarray(self._positions(), dtype=float)
            arrived[0] = bool(np.all(np.abs(after - target_v) <= ARRIVED_MM))
            self.polls += 1
            record.polls += 1
            ends = np.vstack([before, after])
            u = float(np.mean(self._progress(ends)))
            # The gauge sampled somewhere between the two positions: the nominal travel
            # over their box (a poll's few mm: one round of the bound is exact to
            # microns) says whether that instant matters.
            window = self._checker.travel_bound(self._sp, mounting, before, after,
                                                coarse=True)
            travels, slopes, within = {}, {}, {}
            u1 = self._route_u[index][1]
            for name, g in self._gauges.items():
                travel = float(values[name][0]) - g.baseline
                travels[name] = travel
                g.seen = (min(g.seen[0], travel), max(g.seen[1], travel))
                lo_hi = record.travel.get(name, (travel, travel))
                record.travel[name] = (min(lo_hi[0], travel), max(lo_hi[1], travel))
                w_lo, w_hi = window[name]
                if w_hi - w_lo <= QUIET_MM:
                    t_b, t_a = self._nominal(self._sp, name, g.direction, ends)
                    g.signal = travel - 0.5 * float(t_a + t_b)
                    g.samples.append((u, g.signal - g.start_signal))
                else:
                    # Only an interval is known: kept consistent with it (a knocked
                    # stand moves the signal at once, a swing does not).
                    g.signal = min(max(g.signal, travel - w_hi), travel - w_lo)
                slopes[name] = slope = signal_slope(g)
                g.end_signal = g.signal + slope * (1.0 - u)
                s0, s1 = g.signal, g.signal + slope * (u1 - u)
                within[name] = (g.low + self._move_margin - min(s0, s1),
                                g.high - self._move_margin - max(s0, s1))
            # What is still ahead: from here to this sub-move's target (decided: a
            # bound only as sharp as telling it keeps the margin needs), then the rest.
            here_bounds = self._checker.travel_keeps(self._sp, mounting, after, target_v,
                                                     within)
            if here_bounds is None:  # it may not: the full bound, for the trip's figures
                here_bounds = self._checker.travel_bound(self._sp, mounting, after,
                                                         target_v)
            for name, g in self._gauges.items():
                travel, slope = travels[name], slopes[name]
                ahead = [(here_bounds[name], (u, u1))] + [
                    (self._route_bounds[k][name], self._route_u[k])
                    for k in range(index + 1, len(self._route_bounds))]
                lo, hi = travel_ahead(travel, g.signal, slope, u, ahead)
                slack = min(g.high - self._move_margin - hi, lo - g.low - self._move_margin)
                self.slack = min(self.slack, slack)
                if slack < 0:
                    self._trip(g, label, travel, hi, lo)

        return poll

    def signal_envelope(self, target_sign: str | None = None
                        ) -> dict[str, tuple[float, float]]:
        """Per gauge, the signal the rest of the interrupted move adds to the nominal
        travel: (now, at the move's end: as measured there before, if it is a stop
        of this mounting already read, else as carried at the slope seen); the
        re-plan after a trip (MotionChecker.route's ``signal``)."""
        known = self.stop_signal.get(target_sign or "", {})
        return {name: (g.signal, known.get(name, g.end_signal))
                for name, g in self._gauges.items()}

    def routed(self) -> dict[str, tuple[float, float]] | None:
        """Per gauge, before a trip's way back re-routes the guard: (the signal where
        the interrupted sub-move began, the signal at the move's target it was routed
        with); :meth:`after_retreat` compares the first with what the gauge shows
        there again. None where the sub-move did not begin at a stop read at rest
        (nothing exact to compare with)."""
        if not self._leg_exact:
            return None
        return {name: (g.leg_signal, g.start_signal + g.prior_slope)
                for name, g in self._gauges.items()}

    def after_retreat(self, sign: str | None,
                      routed: Mapping[str, tuple[float, float]] | None,
                      ahead: Mapping[str, tuple[float, float]]
                      ) -> tuple[dict[str, tuple[float, float]], dict[str, float]]:
        """Back at rest where the interrupted sub-move began: the signal the rest of the
        move is re-planned with, per gauge (now, at the target), and the zero shifts
        found. At the same joint positions the smooth part of the signal is what it
        was, so a difference is a step (a knocked stand, a slipped plunger): the
        slope the trip extrapolated then mixed the step into the progress and says
        nothing of the target; the target gets the signal the move was routed with
        plus the step. A gauge with no step keeps what the trip predicted
        (``ahead``: signal_envelope before the way back)."""
        limit = max(ZERO_STEP_MM, self.config.procedure.repeatability_mm)
        signal: dict[str, tuple[float, float]] = {}
        shifts: dict[str, float] = {}
        for name, g in self._gauges.items():
            end = ahead[name][1]
            if routed is not None and name in routed:
                shift = g.signal - routed[name][0]
                if abs(shift) > limit:
                    shifts[name] = shift
                    end = routed[name][1] + shift
            signal[name] = (g.signal, end)
        if shifts and sign is not None:
            expected = self.stop_signal.setdefault(sign, {})
            for name in shifts:
                expected[name] = signal[name][1]
        return signal, shifts

    def retreat_signal(self) -> dict[str, tuple[float, float]]:
        """Per gauge, the signal on the way back after a trip: (now, at the stop the
        interrupted move started from)."""
        return {name: (g.signal, g.start_signal) for name, g in self._gauges.items()}

    def route_signal(self, start_sign: str | None, target_sign: str | None
                     ) -> dict[str, tuple[float, float]] | None:
        """The signal a later cycle's move from posture ``start_sign`` to
        ``target_sign`` adds (at its start, at its target), from what the first
        cycle measured at both stops (None: not learned yet, or a stop it did not
        see). The reversal stop is Π0's (the same joints but for their play)."""
        a = self.stop_signal.get(stop_of(start_sign))
        b = self.stop_signal.get(stop_of(target_sign))
        if a is not None and b is None and self._shifted:
            b = a
        if a is None or b is None:
            return None
        return {n: (a[n], b[n]) for n in self._gauges if n in a and n in b}


    def at_rest(self, position: Vec3, means: Mapping[str, float],
                sign: str | None = None) -> None:
        """A stop's mean readings at ``position``: the signal there, exactly. At the
        stop of posture ``sign`` it is also what moves to and from that stop are
        routed with (route_signal)."""
        self.axes_seen.at([position])
        if not self.watching:
            return
        self._at_rest = True
        here = np.asarray(position, dtype=float)[None, :]
        for name, g in self._gauges.items():
            if name in means:
                nominal = float(self._nominal(self._sp, name, g.direction, here)[0])
                g.signal = float(means[name]) - g.baseline - nominal
                g.rest_nominal = nominal
        if sign is not None:
            self.stop_signal[sign] = {n: g.signal for n, g in self._gauges.items()
                                      if n in means}

    def zero_moved(self) -> None:
        """A gauge's zero moved (a knocked stand): what was measured at the stops
        before no longer holds; until a stop is read again, a move to it is routed
        with the signal at its start held all the way (the stand's shift)."""
        self.stop_signal = {}
        self._shifted = True

    def expect_stop(self, sign: str | None) -> None:
        """After a trip on the way to posture ``sign``: until that stop is read, the
        signal there is the one the trip predicted."""
        if sign is not None and sign not in self.stop_signal:
            self.stop_signal[sign] = {n: g.end_signal for n, g in self._gauges.items()}

    def slack_now(self) -> float:
        """How far the plunger nearest an end of its stroke is from it, at the signal
        measured last (mm; at rest after a stop)."""
        here = [min(g.high - (g.signal + t), (g.signal + t) - g.low)
                for g, t in ((g, g.rest_nominal) for g in self._gauges.values())]
        return float(min(here)) if here else np.inf

    def _trip(self, g: GuardedGauge, label: str, travel: float, hi: float, lo: float) -> None:
        if self._moves:
            self._moves[-1].off_route = True
        try:
            self._stop()  # COMMAND 2 first; the sequencer's abort stops again and reports
        except Exception:
            pass  # a failed stop is the sequencer's to report (it stops again on abort)
        pushed = hi > g.high - self.margin
        end, predicted = (g.high, hi) if pushed else (g.low, lo)
        gap = (end - predicted) if pushed else (predicted - end)
        what = "its stop (pushed in)" if pushed else "the end where the leg leaves it"
        heading = f"heading within {gap:.3f} mm of" if gap >= 0 else \
            f"heading {-gap:.3f} mm past"
        try:
            self.axes_seen.at([np.asarray(self._positions(), dtype=float)])
        except Exception:
            pass  # the positions unread: what was seen before is said
        target = ", ".join(f"{a} {v:+.3f}" for a, v in zip("xyz", self._route_legs[-1],
                                                           strict=True))
        self._journal({"type": "event", "event": {
            "event": "plunger-guard", "indicator": g.name, "where": self._where,
            "move": label, "travel_mm": travel, "predicted_mm": predicted,
            "end_mm": end, "margin_mm": self.margin}})
        raise PlungerGuardTrip(
            f"plunger guard: indicator {g.name} ({g.direction}) on {self._where}, "
            f"move to {label}: its plunger was at {travel:+.3f} mm from the mounting "
            f"point and {heading} {what} ({end:+.3f} mm; margin {self.margin:g} mm); the "
            f"axes were stopped on their way to {target} mm: {self.axes_seen.text()}. "
            + self.cause(g.name, pushed), g.name, label)

    def cause(self, name: str, pushed: bool) -> str:
        """The likely cause of a stop for gauge ``name`` and what to do about it
        (station.engine.guard_words), from what this mounting showed."""
        g = self._gauges.get(name)
        if g is None:
            return f"Re-mount it with {'less' if pushed else 'more'} preload or use a " \
                   "longer stroke"
        text = likely_cause(g, pushed, self._moves, self.stop_signal,
                            self.config.indicator(name).preload)
        return text[0].upper() + text[1:]

    # --- later cycles --------------------------------------------------------------------

    def learn(self, stop_means: Mapping[str, Mapping[str, float]]) -> None:
        """End of the first cycle: the signal at each stop (``stop_means``: posture
        "0", "+", "-", "+30".. -> gauge -> mean reading there; nominal travel at a
        test posture is 0, the leg is parallel), with which every later move is
        routed (route_signal), and each move's travel as polled."""
        if not self.watching:
            return
        self.watching = False
        stop_travel = {sign: {n: v - self._gauges[n].baseline for n, v in means.items()
                              if n in self._gauges} for sign, means in stop_means.items()}
        # nominal travel at a stop is 0: its travel is the signal there
        self.stop_signal = {sign: dict(values) for sign, values in stop_travel.items()}
        self._shifted = False
        self.predicted = later_travel(self._moves, list(self._gauges), self.predicted)
        self._journal({"type": "event", "event": {
            "event": "plunger-guard-learned", "where": self._where,
            "polls": sum(r.polls for r in self._moves),
            # None: no poll came while the axes moved (a move shorter than a poll)
            "min_slack_mm": round(float(self.slack), 4) if np.isfinite(self.slack) else None,
            "stop_signal_mm": {sign: {n: round(v, 4) for n, v in values.items()}
                               for sign, values in self.stop_signal.items()},
            "predicted_mm": {f"{name} {label}": [round(lo, 4), round(hi, 4)]
                             for (label, name), (lo, hi) in self.predicted.items()}}})

    def check_cycle(self, cycle: int) -> None:
        """Refuse a later cycle, before it moves, where a move came within the margin
        in the first cycle (a move the guard stopped or re-planned aside: later
        cycles take another path), or where no route keeps the margin with the signal the first
        cycle measured at its stops (the routes found are the checker's, so the
        cycle then moves along them)."""
        if not self.enabled or not self._gauges:
            return
        for (label, name), (lo, hi) in self.predicted.items():
            g = self._gauges[name]
            if hi > g.high - self.margin or lo < g.low + self.margin:
                pushed = hi > g.high - self.margin
                end, value = (g.high, hi) if pushed else (g.low, lo)
                self._refuse(cycle, label, g, pushed, (
                    f"would bring its plunger to {value:+.3f} mm, within "
                    f"{abs(end - value):.3f} mm of the end of its stroke ({end:+.3f} mm; "
                    f"margin {self.margin:g} mm), as the first cycle showed"),
                    {"predicted_mm": value, "end_mm": end})
        sp = self._sp
        signs = [sp.signs[-1], *sp.signs]  # from where the cycle before ended
        for a, b in itertools.pairwise(signs):
            label = posture_label(b, sp.leg)
            move = sp.move(b)
            try:
                self._checker.route(sp.move(a).targets, move.targets, label, sp,
                                    self._mounting(), signal=self.route_signal(a, b),
                                    strict=True, travel=False, approach=move.approach)
            except PathRefused as exc:
                refused = self._gauges.get(exc.indicator or "")
                if refused is None:
                    raise
                self._refuse(cycle, label, refused, exc.pushed, (
                    f"cannot keep its plunger {self.margin:g} mm from the ends of its "
                    f"stroke with the travel the first cycle measured at the stops "
                    f"({exc.detail})"), {})

    def _refuse(self, cycle: int, label: str, g: GuardedGauge, pushed: bool, what: str,
                extra: dict[str, object]) -> None:
        self._journal({"type": "event", "event": {
            "event": "plunger-guard-refused", "indicator": g.name, "where": self._where,
            "move": label, "cycle": cycle, "margin_mm": self.margin, **extra}})
        raise PlungerGuardStop(
            f"plunger guard: indicator {g.name} ({g.direction}) on {self._where}: cycle "
            f"{cycle}'s move to {label} {what}; cycle {cycle} has not moved, "
            f"{self.axes_seen.text()}. {self.cause(g.name, pushed)}")

