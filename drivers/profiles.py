"""The rest-to-rest trapezoid, in one place: the motion profile the station's
move deadlines assume (:meth:`drivers.axes.ModbusAxisController.move_timeout`),
the one the simulated drive runs by default (:mod:`drivers.sim.drive_motion`) and the
one ``bench/cycle.py`` times its floor with. Kept apart from both so that the
real driver never imports the simulator, and a deadline and the move it bounds
cannot drift apart.

(Motion profiles, not register-map profiles: those are :mod:`drivers.registers`.)
"""

from __future__ import annotations

import math

import numpy as np


class AccelProfile:
    """1-D path s(τ) as phases of constant acceleration: (duration, s0, v0, a)."""

    def __init__(self, phases: list[tuple[float, float, float, float]]) -> None:
        self.phases = phases
        self.duration = sum(p[0] for p in phases)
        if phases:
            d, s0, v0, a = phases[-1]
            self.length = s0 + v0 * d + 0.5 * a * d * d
        else:
            self.length = 0.0

    @classmethod
    def trapezoid(cls, distance: float, v_max: float, accel: float) -> AccelProfile:
        """Rest-to-rest over ``distance`` (a triangle when too short to cruise)."""
        if distance <= 0:
            return cls([])
        t_acc = v_max / accel
        d_acc = 0.5 * v_max * t_acc
        if 2 * d_acc >= distance:
            v_peak = math.sqrt(distance * accel)
            t = v_peak / accel
            return cls([(t, 0.0, 0.0, accel), (t, distance / 2, v_peak, -accel)])
        cruise = (distance - 2 * d_acc) / v_max
        return cls([(t_acc, 0.0, 0.0, accel), (cruise, d_acc, v_max, 0.0),
                    (t_acc, distance - d_acc, v_max, -accel)])

    @classmethod
    def braking(cls, s0: float, v0: float, accel: float) -> AccelProfile:
        """Decelerate from (s0, v0) to rest."""
        if v0 <= 0:
            return cls([(0.0, s0, 0.0, 0.0)])
        return cls([(v0 / accel, s0, v0, -accel)])

    def at(self, tau: float) -> tuple[float, float]:
        """(s, v) at time τ after the start; rest at the end after the last phase."""
        for d, s0, v0, a in self.phases:
            if tau <= d:
                t = max(tau, 0.0)
                return s0 + v0 * t + 0.5 * a * t * t, v0 + a * t
            tau -= d
        return self.length, 0.0

    def s_many(self, tau: np.ndarray) -> np.ndarray:
        """s at many τ at once (dense sampling), phase by phase as :meth:`at`."""
        out = np.full(tau.shape, self.length)
        rem = np.array(tau, dtype=float)
        done = np.zeros(tau.shape, dtype=bool)
        for d, s0, v0, a in self.phases:
            here = ~done & (rem <= d)
            t = np.maximum(rem[here], 0.0)
            out[here] = s0 + v0 * t + 0.5 * a * t * t
            done |= here
            rem = rem - d
        return out


def move_time(distance_mm: float, speed_mm_s: float, accel_mm_s2: float) -> float:
    """Duration of a rest-to-rest trapezoidal move (a triangle when too short): the
    duration of :meth:`AccelProfile.trapezoid`, so a deadline derived from it and
    the simulated move it bounds are the same profile."""
    if distance_mm <= 0:
        return 0.0
    if speed_mm_s <= 0 or accel_mm_s2 <= 0:
        raise ValueError("speed and acceleration must be > 0")
    return AccelProfile.trapezoid(distance_mm, speed_mm_s, accel_mm_s2).duration
