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
the path the controller takes, known for the whole move) + signal (measured −
nominal; a smooth function of the joint positions, so it changes slowly). At
each poll the positions are read before and after the gauges; the signal is
updated only when the nominal travel barely changed during that window (a
fast nominal swing would make the gauge's sampling instant matter), and is
extrapolated over the time to the next poll plus half the braking time. The
predicted extremes are the remaining nominal extremes + that signal; the
measured travel itself also counts.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from station.config import StationConfig
from station.errors import RunFailed
from station.motion import independent_path, straight_path

# Nominal travel change within one poll window below which the signal estimate is
# taken as exact (the gauge's sampling instant no longer matters).
QUIET_MM = 0.02


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
    rate: float = 0.0
    t_signal: float = 0.0
    seen: tuple[float, float] = (0.0, 0.0)


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
        c = config.controller
        self._brake_s = c.speed_mm_s / c.accel_mm_s2
        self._motion = "coordinated"
        self._setup: Any = None
        self._where = ""
        self._gauges: dict[str, _Gauge] = {}
        self.watching = False
        self._moves: list[_MoveRecord] = []
        # (move label, gauge) -> predicted (min, max) travel for later cycles
        self.predicted: dict[tuple[str, str], tuple[float, float]] = {}
        self.polls = 0

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

    def watch(self, start: Sequence[float], target: Sequence[float], label: str
              ) -> Callable[[], None] | None:
        """The poll for one (sub-)move from ``start`` to ``target`` (None: not watching)."""
        if not self.watching:
            return None
        path = self._model_path(np.asarray(start, float), np.asarray(target, float))
        nominal = {g.name: self._nominal(self._setup, g.name, g.direction, path)
                   for g in self._gauges.values()}
        # Remaining extremes from each sample on: what the rest of the move will add.
        rest_hi = {n: np.maximum.accumulate(t[::-1])[::-1] for n, t in nominal.items()}
        rest_lo = {n: np.minimum.accumulate(t[::-1])[::-1] for n, t in nominal.items()}
        record = _MoveRecord(label, nominal={n: (float(t.min()), float(t.max()))
                                             for n, t in nominal.items()})
        self._moves.append(record)
        names = list(self._gauges)
        last_poll = [time.monotonic()]

        def nearest(p: np.ndarray) -> int:
            return int(np.argmin(np.sum((path - p) ** 2, axis=1)))

        def poll() -> None:
            before = np.asarray(self._positions(), dtype=float)
            values = self._read(names)
            after = np.asarray(self._positions(), dtype=float)
            now = time.monotonic()
            k_b, k_a = nearest(before), nearest(after)
            k = min(k_b, k_a)
            horizon = (now - last_poll[0]) + 0.5 * self._brake_s
            last_poll[0] = now
            self.polls += 1
            record.polls += 1
            for name, g in self._gauges.items():
                travel = float(values[name][0]) - g.baseline
                g.seen = (min(g.seen[0], travel), max(g.seen[1], travel))
                lo_hi = record.travel.get(name, (travel, travel))
                record.travel[name] = (min(lo_hi[0], travel), max(lo_hi[1], travel))
                t_b, t_a = nominal[name][k_b], nominal[name][k_a]
                if abs(t_a - t_b) <= QUIET_MM:
                    signal = travel - 0.5 * (t_a + t_b)
                    if now > g.t_signal and g.t_signal > 0:
                        g.rate = (signal - g.signal) / (now - g.t_signal)
                    g.signal, g.t_signal = signal, now
                ahead = max(0.0, now - g.t_signal) + horizon
                hi = max(travel, float(rest_hi[name][k]) + g.signal + max(g.rate, 0.0) * ahead)
                lo = min(travel, float(rest_lo[name][k]) + g.signal + min(g.rate, 0.0) * ahead)
                if hi > g.high - self.margin or lo < g.low + self.margin:
                    self._trip(g, label, travel, hi, lo)

        return poll

    def _trip(self, g: _Gauge, label: str, travel: float, hi: float, lo: float) -> None:
        try:
            self._stop()
        finally:
            pushed = hi > g.high - self.margin
            end, predicted = (g.high, hi) if pushed else (g.low, lo)
            gap = (end - predicted) if pushed else (predicted - end)
            what = "its stop (pushed in)" if pushed else "the end where the leg leaves it"
            self._journal({"type": "event", "event": {
                "event": "plunger-guard", "indicator": g.name, "where": self._where,
                "move": label, "travel_mm": travel, "predicted_mm": predicted,
                "end_mm": end, "margin_mm": self.margin}})
            raise PlungerGuardStop(
                f"plunger guard: indicator {g.name} ({g.direction}) on {self._where}, "
                f"move to {label}: its plunger was at {travel:+.3f} mm from the mounting "
                f"point and heading within {gap:.3f} mm of {what} ({end:+.3f} mm; margin "
                f"{self.margin:g} mm). Re-mount it with "
                f"{'less' if pushed else 'more'} preload or use a longer stroke")

    # --- later cycles --------------------------------------------------------------------

    def learn(self, stop_means: Mapping[str, Mapping[str, float]]) -> None:
        """End of the first cycle: predict each later move's travel from what this
        one showed: its polled extremes, and its nominal extremes + the signal at
        the move's two stops (``stop_means``: sign "0" "+" "-" -> gauge -> mean
        reading there; nominal travel at a test posture is 0, the leg is parallel)."""
        if not self.watching:
            return
        self.watching = False
        stop_travel = {sign: {n: v - self._gauges[n].baseline for n, v in means.items()
                              if n in self._gauges} for sign, means in stop_means.items()}
        previous = "0"
        for rec in self._moves:
            base = rec.label.split(" (")[0]
            sign = "0" if base == "Π0" else base[-1]
            for name in self._gauges:
                n_lo, n_hi = rec.nominal[name]
                p_lo, p_hi = rec.travel.get(name, (n_lo, n_hi))
                ends = [stop_travel.get(s, {}).get(name, 0.0) for s in (previous, sign)]
                if "0" in (previous, sign):
                    ends.append(0.0)  # the opening Π0 is the mounting point
                key = (base, name)
                old = self.predicted.get(key, (np.inf, -np.inf))
                self.predicted[key] = (min(old[0], p_lo, n_lo + min(ends)),
                                       max(old[1], p_hi, n_hi + max(ends)))
            if base == rec.label:  # the move's last leg: its target is a stop
                previous = sign
        self._journal({"type": "event", "event": {
            "event": "plunger-guard-learned", "where": self._where,
            "polls": sum(r.polls for r in self._moves),
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
