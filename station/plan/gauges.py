"""The gauges mounted on a setup's leg as the path check sees them, with the signal's range."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.plan.motion import NotCrossing, reachable_points
from station.plan.steps import SetupPlan

__all__ = ["SIGNAL_BULGE", "Gauges", "NotCrossing"]

# The signal is a smooth function of the joints, not of the progress along a move:
# between two stops it may leave their straight ramp by this fraction of its change.
SIGNAL_BULGE = 0.5


@dataclass(frozen=True)
class Gauges:
    """The gauges mounted on a setup's leg, as arrays over the gauges."""

    setup: SetupPlan
    names: list[str]
    directions: list[str]
    low: np.ndarray  # −preload
    high: np.ndarray  # stroke − preload
    # Travel beyond the nominal model (the signal) at the chord's start and end,
    # linear in the progress along the chord in between, ± pad.
    sig0: np.ndarray
    sig1: np.ndarray
    pad: float = 0.0
    chord: tuple[np.ndarray, np.ndarray] | None = None

    def signal_range(self, start: np.ndarray, end: np.ndarray, motion: str
                     ) -> tuple[np.ndarray, np.ndarray]:
        """(m,) lowest and highest signal over the progress that the joint positions a
        sub-move from ``start`` to ``end`` can pass through (reachable_points, by the
        ``motion`` model) span along the chord: the ramp, ± the pad, ± SIGNAL_BULGE ×
        the ramp's change where the progress is away from both ends (4u(1 − u)).
        Without a chord there is no signal, and no points are spread."""
        if self.chord is None:
            zero = np.zeros(len(self.names))
            return zero, zero
        points = reachable_points(start, end, motion, n=2)
        a, b = self.chord
        d = b - a
        norm = float(d @ d)
        u = np.zeros(len(points)) if norm <= 0 else np.clip((points - a) @ d / norm, 0.0, 1.0)
        lo_u, hi_u = float(u.min()), float(u.max())
        ends = [self.sig0 + (self.sig1 - self.sig0) * v for v in (lo_u, hi_u)]
        middle = 1.0 if lo_u <= 0.5 <= hi_u else max(4 * v * (1 - v) for v in (lo_u, hi_u))
        widen = self.pad + SIGNAL_BULGE * np.abs(self.sig1 - self.sig0) * middle
        return np.minimum(*ends) - widen, np.maximum(*ends) + widen
