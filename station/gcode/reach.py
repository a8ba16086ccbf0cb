"""Where a program first goes out of reach: the first point along its motions, in
program order, that the identified machine's legs cannot reach (the workspace) or
whose joints lie beyond the controller's soft limits, named with its line.

The subdivision (station.gcode.subdivide) finds that some segment is out of reach;
the segment's ends need not be the place (a motion's start is where the previous
one ended, inside). So when it refuses, the motions up to the one it found are
sampled along their curves, and between the last sample within reach and the first
beyond it the crossing is found by bisection in t: the point the operator must look
at, not the reachable start of the motion.

The joints at a programmed point p are those the controller commands for it,
IK_nominal(FK_nominal(IK_c(p))) = IK_c(p) (orthocal.compensation, (K1), (K2)).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from orthocal import Geometry
from orthocal.compensation import compensated_points, controller_joints
from station.gcode.paths import Curves
from station.gcode.words import GcodeError

#: Samples per motion when looking for its first point out of reach.
SAMPLES = 257
#: Bisection steps between the last sample within reach and the first beyond: t to
#: 2**-40 of the motion, far below a micrometre on any machine.
_BISECTIONS = 40
_CHUNK = 64  # motions sampled at once: 16 000 points


@dataclass(frozen=True)
class Bounds:
    """What a point must satisfy: the identified machine (its geometry, θ_c) reaches
    it, and its joints lie within ``lower``..``upper`` (mm; ±inf where none), the
    limits' ``source`` said in the message."""

    geometry: Geometry
    theta_c: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    source: str


def guarded(fn: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    """``fn`` of the rows of ``x`` (m, k, 3), NaN rows where it has no answer (the
    kinematics raise ValueError for a whole array when one point is beyond reach:
    the array is halved until the rows that fail are found)."""
    out = np.full_like(x, np.nan)
    finite = np.isfinite(x).all(axis=(1, 2))
    if finite.any():
        out[finite] = _halving(fn, x[finite])
    return out


def _halving(fn: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    try:
        return fn(x)
    except ValueError:
        if len(x) == 1:
            return np.full_like(x, np.nan)
        h = len(x) // 2
        return np.concatenate([_halving(fn, x[:h]), _halving(fn, x[h:])])


def guarded_with(fn: Callable[[np.ndarray, np.ndarray], np.ndarray], x: np.ndarray,
                 aligned: np.ndarray) -> np.ndarray:
    """:func:`guarded` of ``fn(rows, their aligned rows)``: each row of ``aligned`` (one
    per row of x: a segment's directions) handed over with its own row of x."""
    out = np.full_like(x, np.nan)
    finite = np.isfinite(x).all(axis=(1, 2))
    if finite.any():
        out[finite] = _halving_with(fn, x[finite], aligned[finite])
    return out


def _halving_with(fn: Callable[[np.ndarray, np.ndarray], np.ndarray], x: np.ndarray,
                  aligned: np.ndarray) -> np.ndarray:
    try:
        return fn(x, aligned)
    except ValueError:
        if len(x) == 1:
            return np.full_like(x, np.nan)
        h = len(x) // 2
        return np.concatenate([_halving_with(fn, x[:h], aligned[:h]),
                               _halving_with(fn, x[h:], aligned[h:])])


def joints_at(points: np.ndarray, bounds: Bounds) -> np.ndarray:
    """The controller's joints for machine points (..., 3), NaN where out of reach."""
    shape = points.shape
    flat = points.reshape(-1, 1, 3)
    sent = guarded(lambda p: compensated_points(p, bounds.geometry, bounds.theta_c), flat)
    rho = guarded(lambda s: controller_joints(s, bounds.geometry, None), sent)
    return rho.reshape(shape)


def _out(rho: np.ndarray, bounds: Bounds) -> np.ndarray:
    """Which points (joints ``rho`` (..., 3)) are out of reach or beyond the limits."""
    with np.errstate(invalid="ignore"):
        return (np.isnan(rho).any(axis=-1) | (rho < bounds.lower).any(axis=-1)
                | (rho > bounds.upper).any(axis=-1))


def why_out(rho: np.ndarray, bounds: Bounds) -> str:
    """Why the point with joints ``rho`` (3,) is out of reach, in words."""
    if np.isnan(rho).any():
        return "the path leaves the workspace, beyond a leg's reach,"
    for axis in range(3):
        if rho[axis] < bounds.lower[axis]:
            side, bound = "lower", bounds.lower[axis]
        elif rho[axis] > bounds.upper[axis]:
            side, bound = "upper", bounds.upper[axis]
        else:
            continue
        return (f"the path takes joint {'xyz'[axis]} beyond the controller's {side} soft "
                f"limit {bound:.3f} mm ({bounds.source})")
    return "the path leaves what the nominal kinematics can follow"


def first_out(curves: Curves, offset: np.ndarray, bounds: Bounds,
              last: int) -> tuple[int, np.ndarray] | None:
    """The first motion of 0..``last`` that leaves reach along its curve, and its
    first point out of reach (machine coordinates, mm), found by sampling and
    bisection; None where the samples find none (an excursion thinner than them)."""
    t = np.linspace(0.0, 1.0, SAMPLES)
    for lo in range(0, last + 1, _CHUNK):
        ci = np.arange(lo, min(lo + _CHUNK, last + 1))
        points = curves.at(ci, np.broadcast_to(t, (len(ci), SAMPLES)).copy()) + offset
        out = _out(joints_at(points, bounds), bounds)
        hit = out.any(axis=1)
        if not hit.any():
            continue
        row = int(np.argmax(hit))
        j = int(np.argmax(out[row]))
        c = int(ci[row])
        if j == 0:
            return c, points[row, 0]
        return c, _crossing(curves, c, offset, bounds, float(t[j - 1]), float(t[j]))
    return None


def _crossing(curves: Curves, c: int, offset: np.ndarray, bounds: Bounds,
              inside: float, outside: float) -> np.ndarray:
    """The first point out of reach between t = ``inside`` (within) and ``outside``."""
    for _ in range(_BISECTIONS):
        mid = (inside + outside) / 2.0
        p = curves.at(np.array([c]), np.array([[mid]])) + offset
        if _out(joints_at(p, bounds), bounds)[0, 0]:
            outside = mid
        else:
            inside = mid
    return curves.at(np.array([c]), np.array([[outside]]))[0, 0] + offset


def refusal(curves: Curves, offset: np.ndarray, bounds: Bounds,
            labels: Sequence[tuple[int, str]], found: int, point: np.ndarray,
            why: str) -> GcodeError:
    """The error naming the program's first point out of reach: the first found by
    sampling the motions up to ``found``, else what the subdivision found on motion
    ``found``: ``point``, out of reach as ``why`` says (a chord between the points
    sent that leaves the soft limits where the programmed curve stays within)."""
    first = first_out(curves, offset, bounds, found)
    if first is not None:
        found, point = first
        why = why_out(joints_at(point[None, None, :], bounds)[0, 0], bounds)
    lineno, word = labels[found]
    p = point
    return GcodeError(lineno, word, "{} at machine point X{:.3f} Y{:.3f} Z{:.3f} mm, the "
                      "first point out of reach (work offset {:.3f},{:.3f},{:.3f})"
                      .format(why, *p, *offset))
