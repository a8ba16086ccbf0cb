"""The plunger guard: what no plan can know.

The plan check keeps every plunger inside its stroke for the nominal machine.
The real machine adds the signal itself (the travel its offsets cause: up to
millimetres before calibration), and the gauge may sit with less preload or a
shorter stroke than configured. So during the moves of a mounting's first
cycle the mounted gauges are read while the axes move, and the axes stopped
(COMMAND 2) before a plunger comes within ``plunger_margin_mm`` of either end
of its stroke; later cycles of that mounting are predicted from what the
first one showed and refused before moving if they would come that close.

Travel is counted from the mounting point (the reading at the mounting's
first Π0), + pushed in; the stroke spans −preload .. stroke − preload.

Prediction while moving. Plunger travel = nominal travel (the plan's model of
the path the controller takes, known for the whole move, waypoints included)
+ signal (measured − nominal; a smooth function of the joint positions). At
each poll the positions are read just before and just after the gauges; the
signal is updated only where the nominal travel is flat over that window (on
a fast swing the gauge's sampling instant would matter). Ahead of the axes the
plunger is predicted at every remaining point of the move as nominal travel +
the signal carried along the move's progress at the slope seen so far
(median of the samples' slopes, once 15 % of the move is done); the axes are
stopped when that, or the measured travel itself, comes within the margin.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from station.config import StationConfig
from station.errors import RunFailed
from station.motion import independent_path, straight_path, trapezoid_time
from station.plan import posture_label

# Nominal travel change within one poll window below which the signal estimate is
# taken as exact (the gauge's sampling instant no longer matters).
QUIET_MM = 0.05
# The signal at a move's target is extrapolated from the part done once this
# fraction of the move is behind: a reading's noise (µm) and the sampling skew
# (tens of µm) grow by 1/progress.
MIN_PROGRESS = 0.15


class PlungerGuardStop(RunFailed):
    """A plunger would have come within the margin of an end of its stroke."""


@dataclass
class _Gauge:
    name: str
    direction: str
    low: float  # −preload
    high: float  # stroke − preload
    baseline: float  # the reading at the mounting point
    signal: float = 0.0
    seen: tuple[float, float] = (0.0, 0.0)
    start_signal: float = 0.0  # at the stop the current move started from
    samples: list[tuple[float, float]] = field(default_factory=list)  # (progress, Δsignal)


@dataclass
class _MoveRecord:
    label: str
    travel: dict[str, tuple[float, float]] = field(default_factory=dict)
    nominal: dict[str, tuple[float, float]] = field(default_factory=dict)
    polls: int = 0


class PlungerGuard:
    """One per sequencer. ``mount`` when a mounting's first Π0 has been read,
    ``watch`` for each (sub-)move of its first cycle, ``learn`` at the end of that
    cycle, ``check_cycle`` before each later one."""

    def __init__(self, config: StationConfig, nominal: Callable[..., np.ndarray],
                 positions: Callable[[], np.ndarray],
                 read: Callable[[list[str]], dict[str, list[float]]],
                 stop: Callable[[], None], journal: Callable[[dict[str, Any]], None]
                 ) -> None:
        self.config = config
        self.enabled = config.procedure.plunger_guard
        self.margin = config.procedure.plunger_margin_mm
        self._nominal = nominal  # (setup, name, direction, path) -> travel along path
        self._positions = positions
        self._read = read
        self._stop = stop
        self._journal = journal
        self._motion = "coordinated"
        self._setup: Any = None
        self._where = ""
        self._gauges: dict[str, _Gauge] = {}
        self.watching = False
        self._moves: list[_MoveRecord] = []
        # (move label, gauge) -> predicted (min, max) travel for later cycles
        self.predicted: dict[tuple[str, str], tuple[float, float]] = {}
        self.polls = 0
        # The smallest distance of a prediction from the margin so far (mm).
        self.slack = np.inf

    # --- a mounting --------------------------------------------------------------------

    def mount(self, motion: str, setup: Any, phase: str, mounted: Mapping[str, str],
              baseline: Mapping[str, float]) -> None:
        """Start watching a new mounting; ``baseline``: each gauge's Π0 reading."""
        self._motion = motion
        self._setup = setup
        self._where = f"{'verification' if phase == 'v' else 'measurement'} setup " \
                      f"{setup.index + 1} (leg {setup.leg})"
        self._gauges = {}
        for name, direction in mounted.items():
            ind = self.config.indicator(name)
            self._gauges[name] = _Gauge(name, direction, -ind.preload,
                                        ind.stroke_mm - ind.preload, float(baseline[name]))
        self._moves = []
        self.predicted = {}
        self.slack = np.inf
        self.watching = self.enabled and bool(self._gauges)

    def forget(self) -> None:
        self._gauges = {}
        self.watching = False
        self.predicted = {}

    # --- while moving ------------------------------------------------------------------

    def _model_path(self, start: np.ndarray, target: np.ndarray) -> np.ndarray:
        c = self.config.controller
        if self._motion == "independent":
            return independent_path(start, target, c.speed_mm_s, c.accel_mm_s2)
        return straight_path(start, target)

    def begin_move(self, start: Sequence[float], legs: Sequence[Sequence[float]]) -> None:
        """A move from a stop (``start``) through its sub-moves' targets ``legs``: the
        modelled path of every sub-move, its progress along the move and the nominal
        travel there; the signal at rest anchors the move."""
        if not self.watching:
            return
        a = np.asarray(start, dtype=float)
        b = np.asarray(legs[-1], dtype=float)
        self._route_a, self._route_d = a, b - a
        self._route_paths = []
        here = a
        for leg in legs:
            leg_v = np.asarray(leg, dtype=float)
            self._route_paths.append(self._model_path(here, leg_v))
            here = leg_v
        self._route_u = [self._progress(p) for p in self._route_paths]
        self._route_nominal: dict[str, list[np.ndarray]] = {
            g.name: [self._nominal(self._setup, g.name, g.direction, p)
                     for p in self._route_paths] for g in self._gauges.values()}
        for g in self._gauges.values():
            g.start_signal = g.signal
            g.samples = []
        self._leg_index = 0

    def _progress(self, p: np.ndarray) -> np.ndarray:
        """Fraction of the move done at joint position(s) p (projection on its chord)."""
        d = self._route_d
        norm = float(d @ d)
        if norm <= 0:
            return np.zeros(np.shape(p)[:-1])
        return np.clip((np.asarray(p) - self._route_a) @ d / norm, 0.0, 1.0)

    def watch(self, start: Sequence[float], target: Sequence[float], label: str
              ) -> Callable[[], None] | None:
        """The poll for the next sub-move of the move begun by begin_move (None: not
        watching)."""
        if not self.watching:
            return None
        index = self._leg_index
        self._leg_index += 1
        path = self._route_paths[index]
        nominal = {n: tracks[index] for n, tracks in self._route_nominal.items()}
        # This sub-move's samples and every later sub-move's: what is still ahead.
        ahead_t = {n: np.concatenate(tracks[index:]) for n, tracks in
                   self._route_nominal.items()}
        ahead_u = np.concatenate(self._route_u[index:])
        record = _MoveRecord(label, nominal={n: (float(t.min()), float(t.max()))
                                             for n, t in nominal.items()})
        self._moves.append(record)
        names = list(self._gauges)
        started = time.monotonic()
        c = self.config.controller
        arrival = started + trapezoid_time(float(np.max(np.abs(np.asarray(target, float)
                                                               - np.asarray(start, float)))),
                                           c.speed_mm_s, c.accel_mm_s2)
        took = [0.0]

        def nearest(p: np.ndarray) -> int:
            return int(np.argmin(np.sum((path - p) ** 2, axis=1)))

        def poll() -> None:
            began = time.monotonic()
            if record.polls and began + took[0] > arrival:
                # A poll now would end after the arrival and delay its detection; the
                # last one predicted the rest of the path.
                return
            before = np.asarray(self._positions(), dtype=float)
            values = self._read(names)
            after = np.asarray(self._positions(), dtype=float)
            took[0] = time.monotonic() - began
            k_b, k_a = nearest(before), nearest(after)
            k0, k1 = min(k_b, k_a), max(k_b, k_a)
            self.polls += 1
            record.polls += 1
            ends = np.vstack([before, after])
            u = float(np.mean(self._progress(ends)))
            for name, g in self._gauges.items():
                travel = float(values[name][0]) - g.baseline
                g.seen = (min(g.seen[0], travel), max(g.seen[1], travel))
                lo_hi = record.travel.get(name, (travel, travel))
                record.travel[name] = (min(lo_hi[0], travel), max(lo_hi[1], travel))
                # Nominal travel where the axes were just before and just after the
                # gauges were read, and along the path between: the gauge sampled
                # somewhere in there, so only a flat stretch gives the signal.
                t_b, t_a = self._nominal(self._setup, name, g.direction, ends)
                window = np.concatenate([nominal[name][k0:k1 + 1], [t_b, t_a]])
                if float(window.max() - window.min()) <= QUIET_MM:
                    g.signal = travel - 0.5 * float(t_a + t_b)
                    g.samples.append((u, g.signal - g.start_signal))
                # Ahead: nominal travel + the signal, carried from here along the move's
                # progress at the slope seen so far (the signal is a smooth function of
                # the joint positions).
                offset = k0 if k0 < len(nominal[name]) else len(nominal[name]) - 1
                t_rest = ahead_t[name][offset:]
                u_rest = ahead_u[offset:]
                predicted = t_rest + g.signal + self._slope(g) * (u_rest - u)
                hi = max(travel, float(predicted.max()))
                lo = min(travel, float(predicted.min()))
                slack = min(g.high - self.margin - hi, lo - g.low - self.margin)
                self.slack = min(self.slack, slack)
                if slack < 0:
                    self._trip(g, label, travel, hi, lo)

        return poll

    @staticmethod
    def _slope(g: _Gauge) -> float:
        """d(signal)/d(progress) from the samples once enough of the move is done
        (a reading's noise and the sampling skew grow by 1/progress); the median
        of the samples' slopes, so one knocked reading does not swing it."""
        slopes = [d / u for u, d in g.samples if u >= MIN_PROGRESS]
        return float(np.median(slopes)) if slopes else 0.0

    def at_rest(self, position: Sequence[float], means: Mapping[str, float]) -> None:
        """A stop's mean readings at ``position``: the signal there, exactly."""
        if not self.watching:
            return
        here = np.asarray(position, dtype=float)[None, :]
        for name, g in self._gauges.items():
            if name in means:
                nominal = float(self._nominal(self._setup, name, g.direction, here)[0])
                g.signal = float(means[name]) - g.baseline - nominal

    def _trip(self, g: _Gauge, label: str, travel: float, hi: float, lo: float) -> None:
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
        self._journal({"type": "event", "event": {
            "event": "plunger-guard", "indicator": g.name, "where": self._where,
            "move": label, "travel_mm": travel, "predicted_mm": predicted,
            "end_mm": end, "margin_mm": self.margin}})
        raise PlungerGuardStop(
            f"plunger guard: indicator {g.name} ({g.direction}) on {self._where}, "
            f"move to {label}: its plunger was at {travel:+.3f} mm from the mounting "
            f"point and {heading} {what} ({end:+.3f} mm; margin {self.margin:g} mm). "
            f"Re-mount it with {'less' if pushed else 'more'} preload or use a longer stroke")

    # --- later cycles --------------------------------------------------------------------

    def learn(self, stop_means: Mapping[str, Mapping[str, float]]) -> None:
        """End of the first cycle: predict each later move's travel from what this
        one showed: its polled extremes, and its nominal extremes + the signal at
        the move's two stops (``stop_means``: posture "0", "+", "-", "+30".. -> gauge -> mean
        reading there; nominal travel at a test posture is 0, the leg is parallel)."""
        if not self.watching:
            return
        self.watching = False
        stop_travel = {sign: {n: v - self._gauges[n].baseline for n, v in means.items()
                              if n in self._gauges} for sign, means in stop_means.items()}
        by_label = {posture_label(p, self._setup.leg): p for p in stop_means}
        previous = "0"
        for rec in self._moves:
            base = rec.label.split(" (waypoint")[0]
            sign = by_label.get(base, "0")
            for name in self._gauges:
                n_lo, n_hi = rec.nominal[name]
                p_lo, p_hi = rec.travel.get(name, (n_lo, n_hi))
                ends = [stop_travel.get(s, {}).get(name, 0.0) for s in (previous, sign)]
                if "0" in (previous, sign):
                    ends.append(0.0)  # the opening Π0 is the mounting point
                key = (base, name)  # the move's label: its target
                old = self.predicted.get(key, (np.inf, -np.inf))
                self.predicted[key] = (min(old[0], p_lo, n_lo + min(ends)),
                                       max(old[1], p_hi, n_hi + max(ends)))
            if base == rec.label:  # the move's last leg: its target is a stop
                previous = sign
        self._journal({"type": "event", "event": {
            "event": "plunger-guard-learned", "where": self._where,
            "polls": sum(r.polls for r in self._moves),
            "min_slack_mm": round(float(self.slack), 4),
            "predicted_mm": {f"{name} {label}": [round(lo, 4), round(hi, 4)]
                             for (label, name), (lo, hi) in self.predicted.items()}}})

    def check_cycle(self, cycle: int) -> None:
        """Refuse a later cycle, before it moves, if a move would come within the margin."""
        if not self.enabled:
            return
        for (label, name), (lo, hi) in self.predicted.items():
            g = self._gauges[name]
            if hi > g.high - self.margin or lo < g.low + self.margin:
                pushed = hi > g.high - self.margin
                end, value = (g.high, hi) if pushed else (g.low, lo)
                gap = abs(end - value)
                self._journal({"type": "event", "event": {
                    "event": "plunger-guard-refused", "indicator": g.name,
                    "where": self._where, "move": label, "cycle": cycle,
                    "predicted_mm": value, "end_mm": end, "margin_mm": self.margin}})
                raise PlungerGuardStop(
                    f"plunger guard: indicator {g.name} ({g.direction}) on {self._where}: "
                    f"cycle {cycle}'s move to {label} would bring its plunger to "
                    f"{value:+.3f} mm, within {gap:.3f} mm of the end of its stroke "
                    f"({end:+.3f} mm; margin {self.margin:g} mm), predicted from the first "
                    f"cycle; nothing has moved. Re-mount it with "
                    f"{'less' if pushed else 'more'} preload or use a longer stroke")
