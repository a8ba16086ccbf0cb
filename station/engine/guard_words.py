"""What a plunger guard stop tells the operator: what the axes did under the mounting
(which moved, from where to where, where they stand) and the likely cause, from what
the gauge showed, so that the advice fits it: preload only where the preload is what
went wrong (station.engine.guard_monitor)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from orthocal import AXES
from station.plan.guard import GuardedGauge, MoveRecord

# Below this an axis did not move (mm): a count or two of the drive.
STILL_MM = 0.002
# A move whose nominal travel spans at least this tells a reversed gauge from its
# readings (mm): well above the noise and the signal's own change over a move.
TELLS_MM = 0.02


class AxesSeen:
    """The joint positions the axes passed through under one mounting."""

    def __init__(self) -> None:
        self.low: np.ndarray | None = None
        self.high: np.ndarray | None = None
        self.first: np.ndarray | None = None
        self.now: np.ndarray | None = None

    def at(self, positions: Iterable[Sequence[float] | np.ndarray]) -> None:
        """The axes stood at, or were sent to, each of ``positions``."""
        for p in positions:
            v = np.asarray(p, dtype=float)
            if self.first is None or self.low is None or self.high is None:
                self.first, self.low, self.high = v.copy(), v.copy(), v.copy()
            else:
                self.low, self.high = np.minimum(self.low, v), np.maximum(self.high, v)
            self.now = v

    def text(self, now: Sequence[float] | np.ndarray | None = None) -> str:
        """"under this mounting axis x moved between +210.250 and +370.250 mm, y
        between …; z did not move (+310.250 mm); the axes stand at x …, y …, z … mm"."""
        here = self.now if now is None else np.asarray(now, dtype=float)
        if self.low is None or self.high is None or here is None:
            return "the axes have not moved under this mounting"
        low, high = self.low, self.high
        moved = [k for k in range(3) if high[k] - low[k] > STILL_MM]
        still = [k for k in range(3) if k not in moved]
        text = "under this mounting " + (
            "axis " + ", ".join(f"{AXES[k]} moved between {low[k]:+.3f} and {high[k]:+.3f} mm"
                                for k in moved) if moved else "no axis moved")
        if moved and still:
            text += "; " + " and ".join(AXES[k] for k in still) + " did not move (" + \
                ", ".join(f"{low[k]:+.3f}" for k in still) + " mm)"
        return text + "; the axes stand at " + ", ".join(
            f"{a} {v:+.3f}" for a, v in zip(AXES, here, strict=True)) + " mm"


def reversed_evidence(moves: Sequence[MoveRecord], name: str) -> bool:
    """Whether the gauge's travel over the moves polled ran against the nominal
    travel its configured direction predicts: a direction without its sign
    ("z" for "-z"), or a gauge mounted the other way round."""
    against = along = 0.0
    for rec in moves:
        nominal, seen = rec.nominal.get(name), rec.travel.get(name)
        if nominal is None or seen is None or nominal[1] - nominal[0] < TELLS_MM:
            continue
        n_lo, n_hi = nominal
        t_lo, t_hi = seen
        along += abs(t_lo - n_lo) + abs(t_hi - n_hi)
        against += abs(t_lo + n_hi) + abs(t_hi + n_lo)
    return against > 0.0 and against < 0.5 * along


def likely_cause(g: GuardedGauge, pushed: bool, moves: Sequence[MoveRecord],
                 stop_signal: Mapping[str, Mapping[str, float]], preload: float) -> str:
    """The likely cause of a stop of gauge ``g`` (``pushed``: toward its stop), and
    what to do about it."""
    more_less = "less" if pushed else "more"
    if reversed_evidence(moves, g.name):
        return (f"likely cause: indicator {g.name} reads against the travel its direction "
                f"'{g.direction}' predicts, so it is mounted the other way round or its "
                f"direction in [[setups]] lacks its sign ('{_flip(g.direction)}'); fix the "
                "config or the mounting, not the preload")
    signals = [abs(v.get(g.name, 0.0)) for v in stop_signal.values()]
    signal = max(signals, default=0.0)
    room = g.high if pushed else -g.low  # from the mounting point to that end
    if signal >= 0.25 * room:
        return (f"likely cause: the machine's own error (its joint offsets before "
                f"calibration) moves this plunger {signal:.3f} mm at the test postures, "
                f"{100 * signal / room:.0f} % of its {room:.3f} mm to that end; re-mount it "
                f"with {more_less} preload, nearer the middle of its stroke, or use a "
                "longer stroke")
    return (f"likely cause: the plunger sits with {'more' if pushed else 'less'} preload "
            f"than the config's preload_mm = {preload:g} mm says (the nominal travel alone "
            f"takes it there); re-mount it with {more_less} preload or correct preload_mm")


def _flip(direction: str) -> str:
    return direction[1:] if direction.startswith("-") else "-" + direction
