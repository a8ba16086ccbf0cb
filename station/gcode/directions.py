"""Which way each joint moves along a program (docs/design.md, "Compensate", directions):
the joints' errors depend on the side a joint comes from, so a program compensated for
them takes each joint's direction from the program's own motion.

Along a motion's curve C(t) the identified machine needs the joints q(t) = IK_c(C(t)).
A joint's q is sampled every :data:`STEP_MM` of path (at least :data:`MIN_SAMPLES` per
motion); where its steps change sign it turns back, and the turning point is found to
1e-12 of t by golden-section search on q. The motions are cut there
(:func:`turning_points`), so that on every piece each joint moves one way or stands:
its direction is +1 (forward, q rising), −1 (reverse) or, standing, the side of its
last move (:func:`piece_directions`). Before a joint's first move in the program its
side is that of its first move (the carriage, once it moves, moves that way); a joint
the program never moves has none (0: the middle of its band).

Two turns within one sampling step (a joint backing off by at most ~STEP²/L, a few µm)
are not seen: over such a stretch its error is taken for the side it had.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from station.gcode.paths import Curves

#: Samples of a motion's joints at most this far apart along its path (mm).
STEP_MM = 1.0
MIN_SAMPLES = 16
#: A joint moving less than this over a piece stands (mm).
STANDS_MM = 1e-9
#: Turning points closer than this in t are one.
_T_TOL = 1e-12
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0

JointsOf = Callable[[np.ndarray], np.ndarray]  # machine points (..., 3) → joints (..., 3)


def _lengths(curves: Curves) -> np.ndarray:
    """Each curve's path length (mm): arc length (the larger radius) and rise."""
    radius = np.maximum(curves.r0, curves.r1)
    flat = np.abs(curves.theta) * radius
    return np.hypot(flat, np.linalg.norm(curves.lin, axis=1))


def turning_points(curves: Curves, offset: np.ndarray, joints: JointsOf) -> list[np.ndarray]:
    """Per motion, the parameters t in (0, 1) where a joint turns back, sorted. ``joints``
    gives the joints the machine needs at machine points (NaN where it has none: such a
    stretch shows no turn; the rewriting refuses it anyway). Every motion's samples are
    taken at once, and every turn's search runs at once."""
    if not len(curves):
        return []
    n = np.clip(np.ceil(_lengths(curves) / STEP_MM), MIN_SAMPLES, None).astype(int)
    ci = np.repeat(np.arange(len(curves)), n + 1)
    first = np.cumsum(n + 1) - (n + 1)
    t = (np.arange(len(ci)) - np.repeat(first, n + 1)) / np.repeat(n, n + 1)
    q = joints(curves.at(ci, t[:, None])[:, 0] + offset)  # (samples, 3)
    step = np.diff(q, axis=0)
    inside = ci[1:] == ci[:-1]  # a step within one curve
    found_ci, found_lo, found_hi, found_i, found_sign = [], [], [], [], []
    for i in range(3):
        moving = np.flatnonzero(inside & np.isfinite(step[:, i])
                                & (np.abs(step[:, i]) > STANDS_MM))
        a, b = moving[:-1], moving[1:]
        turn = (ci[a] == ci[b]) & (np.sign(step[a, i]) != np.sign(step[b, i]))
        a, b = a[turn], b[turn]
        found_ci.append(ci[a])
        found_lo.append(t[a])
        found_hi.append(t[b + 1])
        found_i.append(np.full(len(a), i))
        found_sign.append(np.sign(step[a, i]))
    where = np.concatenate(found_ci)
    turns = _golden(curves, offset, joints, where, np.concatenate(found_lo),
                    np.concatenate(found_hi), np.concatenate(found_i),
                    np.concatenate(found_sign))
    return [_merged(sorted(turns[where == k].tolist())) for k in range(len(curves))]


def _golden(curves: Curves, offset: np.ndarray, joints: JointsOf, ci: np.ndarray,
            lo: np.ndarray, hi: np.ndarray, joint: np.ndarray,
            sign: np.ndarray) -> np.ndarray:
    """Each turn's t: the extremum of q_joint (a maximum where ``sign`` > 0, it rose
    before) between ``lo`` and ``hi``, all searched at once by golden section."""
    if not len(ci):
        return np.zeros(0)
    rows = np.arange(len(ci))

    def f(x: np.ndarray) -> np.ndarray:
        q = joints(curves.at(ci, x[:, None])[:, 0] + offset)
        return -sign * q[rows, joint]

    x1, x2 = hi - _GOLDEN * (hi - lo), lo + _GOLDEN * (hi - lo)
    f1, f2 = f(x1), f(x2)
    while np.max(hi - lo) > _T_TOL:
        left = f1 <= f2  # the minimum lies in [lo, x2]
        hi, lo = np.where(left, x2, hi), np.where(left, lo, x1)
        x1n = np.where(left, hi - _GOLDEN * (hi - lo), x2)
        x2n = np.where(left, x1, lo + _GOLDEN * (hi - lo))
        f1n = np.where(left, np.nan, f2)
        f2n = np.where(left, f1, np.nan)
        fresh = np.where(left, x1n, x2n)
        value = f(fresh)
        x1, x2 = x1n, x2n
        f1, f2 = np.where(left, value, f1n), np.where(left, f2n, value)
    return 0.5 * (lo + hi)


def _merged(ts: list[float]) -> np.ndarray:
    """Turning points inside (0, 1), one of each cluster closer than 1e-9."""
    kept: list[float] = []
    for x in ts:
        if 1e-9 < x < 1.0 - 1e-9 and (not kept or x - kept[-1] > 1e-9):
            kept.append(x)
    return np.array(kept)


def piece_directions(q_start: np.ndarray, q_end: np.ndarray) -> np.ndarray:
    """Each piece's direction per joint (m, 3) from its joints at its start and end
    ((m, 3) each, the pieces in program order): +1 or −1 where the joint moves; where
    it stands, the side of its last move before; before its first move, that move's
    side; 0 for a joint the program never moves."""
    move = q_end - q_start
    sides = np.where(np.abs(move) > STANDS_MM, np.sign(move), 0.0)
    sides = np.where(np.isfinite(sides), sides, 0.0)
    out = sides.copy()
    for i in range(out.shape[1]):
        col = out[:, i]
        last = 0.0
        for k in range(len(col)):  # standing: the last side
            if col[k] == 0.0:
                col[k] = last
            last = col[k]
        moved = np.flatnonzero(col != 0.0)
        if len(moved):
            col[:moved[0]] = col[moved[0]]  # before the first move: its side
    return out
