"""Where the axes can be during one COMMAND 1, and bounds over that set
(docs/design.md, "Register map": COMMAND 1 promises no interpolation).

The station never models a drive's timing: profile shape, acceleration, start
delays and the order of the axes are the drive's own and cannot be measured
from here. What it assumes instead, by motion model (the register-map
profile's ``motion``, overridden by ``[controller] motion``):

* ``independent`` (the built-in profiles' default): within one COMMAND 1 each
  axis moves monotonically from where it is to its target, at any pace and in
  any order (trapezoids, S-curves, axes a few ms apart, one axis after
  another). The joint positions it can pass through are then exactly the
  joint-space box spanned by the move's two ends, and a move is safe only if
  it is safe everywhere in that box: "safe for any axis timing".
* ``coordinated``: the controller interpolates: the joints stay on the straight
  line between the two ends in joint space, at any speed profile along it
  (its following error is taken to be far below the plunger margin).

A bound over the set (:func:`segment_bound`) is found by branch and bound on
grids over it (the box's corners, edges and interior, or the line's samples):
each cell's extreme is its corners' widened by the error bound of multilinear
interpolation, Σ_i h_i²/8 · max|∂²f/∂ρ_i²|, with the second derivatives taken
from the grid's own second differences (× CURVATURE_SAFETY), and no widening
along an axis where the cell's edges show the function monotone. Cells whose
bound may hide a more extreme value are split until the bound is within
``tolerance`` of the extreme found: where the function is monotone over the box
the corners hold the extremes; where it is not (a leg that swings through its
middle), the search finds the inside extreme.

Waypoints (:func:`route`) split a move into sub-moves, each its own COMMAND 1,
placed where the end point lies on its straight line from one stop to the next
(nominal kinematics: between two test postures of leg i that line is axis i,
along which leg i stays parallel to itself and its indicators read their
mounting value). They are placed greedily, each sub-move as long as its box
allows, which gives the fewest; then, for that count, spread so that the
smallest slack of any sub-move is as large as it can be (room for what the
plan cannot know: the travel the offsets themselves cause).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

import orthocal
from drivers.base import Vec3
from orthocal import Geometry

MotionModel = Literal["coordinated", "independent"]
MOTION_MODELS: tuple[str, ...] = ("coordinated", "independent")
#: What the plan guarantees under each model, in the words of the plan listing.
GUARANTEE = {
    "independent": "safe for any axis timing (each axis moves monotonically from its start "
                   "to its target, at any pace, in any order: the whole joint-space box of "
                   "each move's ends is checked)",
    "coordinated": "the controller interpolates: the joints stay on the straight line "
                   "between stops in joint space, at any speed profile along it",
}
# A bound is refined until it lies within this of the extreme found (mm of travel).
TOLERANCE_MM = 0.005
# Branch and bound: cells are halved at most this many times (a 160 mm move: cells
# of 0.6 mm), and a round samples at most this many points.
MAX_DEPTH = 8
MAX_SAMPLES = 20000
# The largest second derivative inside a cell is taken as at most this many times
# the largest second difference the grid shows (smooth functions on a grid fine
# enough that the widening is below the tolerance: their curvature varies slowly).
CURVATURE_SAFETY = 2.0
# Bisection steps of the greedy waypoint placement (fraction of the move: 1/512, a
# third of a mm on the paper's longest move; each step a decision at the plan check),
# and of the slack the waypoints are then spread for (1/64 of the room there is).
BISECTION_STEPS = 9
SPREAD_STEPS = 6


class OutsideWorkspace(ValueError):
    """Part of the set a move can pass through has no forward kinematics."""


class NotCrossing(ValueError):
    """The leg under test leaves the plane of a mounted indicator (raised by a
    values function; passed on as it is, not taken for leaving the workspace)."""


@dataclass(frozen=True)
class Bound:
    """Lower and upper bound of each column of a function over a move's set, and
    the extremes of the values sampled there (attained: a limit they pass is
    crossed for certain). ``sharp``: refined to the tolerance (not only as far as
    a decision against limits needed)."""

    lo: np.ndarray
    hi: np.ndarray
    seen_lo: np.ndarray | None = None
    seen_hi: np.ndarray | None = None
    sharp: bool = True

    def within(self, low: np.ndarray | None, high: np.ndarray | None) -> bool:
        """The bound proves every value within the limits."""
        return not _outside(self.lo, self.hi, low, high)

    def refutes(self, low: np.ndarray | None, high: np.ndarray | None) -> bool:
        """A value sampled lies beyond a limit."""
        if self.seen_lo is None or self.seen_hi is None:
            return False
        return _outside(self.seen_lo, self.seen_hi, low, high)

    def merge(self, other: Bound) -> Bound:
        """What two searches of the same set know: the tighter bound of the two (each
        holds), the extremes of all values sampled."""
        seen = [(b.seen_lo, b.seen_hi) for b in (self, other)
                if b.seen_lo is not None and b.seen_hi is not None]
        return Bound(np.maximum(self.lo, other.lo), np.minimum(self.hi, other.hi),
                     np.min([lo for lo, _ in seen], axis=0) if seen else None,
                     np.max([hi for _, hi in seen], axis=0) if seen else None,
                     self.sharp or other.sharp)


Values = Callable[[np.ndarray], np.ndarray]  # (n, 3) joints -> (n, m) values


def _space(a: np.ndarray, b: np.ndarray,
           motion: str) -> tuple[int, Callable[[np.ndarray], np.ndarray]]:
    """The set a move can pass through as the image of the unit cube [0, 1]^d:
    (d, u ↦ joints). The line: d = 1; the box: one dimension per axis that moves."""
    if motion == "coordinated":
        return (1 if np.any(a != b) else 0), lambda u: a + (b - a) * u[..., :1]
    active = [i for i in range(3) if abs(b[i] - a[i]) > 1e-12]

    def joints(u: np.ndarray) -> np.ndarray:
        out = np.broadcast_to(a, (*u.shape[:-1], 3)).copy()
        for k, i in enumerate(active):
            out[..., i] = a[i] + (b[i] - a[i]) * u[..., k]
        return out

    return len(active), joints


def reachable_points(a: Vec3, b: Vec3, motion: str,
                     n: int = 5) -> np.ndarray:
    """A grid of n points per dimension over the joint positions one COMMAND 1 from
    a to b can pass through: the box of its ends (independent) or the straight
    line (coordinated)."""
    a_v, b_v = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    d, joints = _space(a_v, b_v, motion)
    if d == 0:
        return a_v[None, :].copy()
    mesh = np.meshgrid(*[np.linspace(0.0, 1.0, n)] * d, indexing="ij")
    return joints(np.stack([m.ravel() for m in mesh], axis=-1))


def _cell_extremes(values: np.ndarray, dims: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Per grid cell, the min and max of the cell's corners along the grid axes
    ``dims`` (each of size ≥ 2) of ``values``."""
    lo, hi = values, values
    for axis in dims:
        a, b = _halves(values.ndim, axis, values.shape[axis])
        lo = np.minimum(lo[a], lo[b])
        hi = np.maximum(hi[a], hi[b])
    return lo, hi


def _cell_max(values: np.ndarray, dims: tuple[int, ...]) -> np.ndarray:
    """:func:`_cell_extremes`' max alone."""
    hi = values
    for axis in dims:
        a, b = _halves(values.ndim, axis, values.shape[axis])
        hi = np.maximum(hi[a], hi[b])
    return hi


def _halves(ndim: int, axis: int, n: int) -> tuple[tuple[slice, ...], tuple[slice, ...]]:
    """Index tuples of a cell's lower and upper corners along ``axis`` (size n)."""
    a = [slice(None)] * ndim
    b = [slice(None)] * ndim
    a[axis], b[axis] = slice(0, n - 1), slice(1, n)
    return tuple(a), tuple(b)


def cell_bounds(values: np.ndarray, dims: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bound of a smooth function over each cell of a regular grid
    (``values``: grid axes ``dims``, each of size ≥ 3, other axes batch/columns).

    Multilinear interpolation on a cell errs by at most Σ_i D_i s_i(1 − s_i)/2
    (s the position in the cell, D_i = h_i² max|∂²f/∂ρ_i²| over the cell, taken
    from the second differences at the cell's nodes × CURVATURE_SAFETY). Where,
    along axis i, every edge of a cell changes f by at least D_i/2 in one sense, f
    is monotone along i inside the cell and its extremes lie on a face: no
    widening for that axis. Elsewhere the axis adds D_i/8. So a bound is exact
    where the function is monotone on the grid's scale (a plunger at a stop, the
    leg parallel) and widened only where an extreme may hide inside a cell."""
    cell_lo, cell_hi = _cell_extremes(values, dims)
    widen = np.zeros(cell_lo.shape)
    for axis in dims:
        others = tuple(a for a in dims if a != axis)
        d2_cell = CURVATURE_SAFETY * _second_difference_max(values, axis, others)
        d_lo, d_hi = _cell_extremes(np.diff(values, axis=axis), others)  # the cells' edges
        monotone = (d_lo >= d2_cell / 2.0) | (d_hi <= -d2_cell / 2.0)
        widen = widen + np.where(monotone, 0.0, d2_cell / 8.0)
    return cell_lo - widen, cell_hi + widen


def _second_difference_max(values: np.ndarray, axis: int, others: tuple[int, ...]
                           ) -> np.ndarray:
    """Per cell, the largest |second difference| along ``axis`` over the cell's nodes
    (the grid's ends take their neighbour's). On the 3-point grid of every
    branch-and-bound step there is one second difference per line, every node's: its
    cells' max along ``axis`` is that value itself (broadcast over the axis' two
    cells), and only the ``others`` axes are reduced. The same numbers as the
    general case, a third of the numpy calls."""
    n = values.shape[axis]
    d2 = np.abs(np.diff(values, n=2, axis=axis))
    if n == 3:
        return _cell_max(d2, others)
    d2 = np.concatenate([np.take(d2, [0], axis=axis), d2, np.take(d2, [n - 3], axis=axis)],
                        axis=axis)
    return _cell_max(d2, (axis, *others))


@functools.cache
def _unit_grid(d: int, n: int) -> np.ndarray:
    """The n points 0, 1/2 (, 1) per dimension of the unit cube [0, 1]^d, as rows
    ((n^d, d); n = 3: a cell's sample grid, n = 2: its sub-cells' corners). Read
    only: cached, every branch-and-bound step of every sub-move uses them."""
    steps = np.array([0.0, 0.5, 1.0][:n])
    grid = np.stack([m.ravel() for m in np.meshgrid(*[steps] * d, indexing="ij")], axis=-1)
    grid.setflags(write=False)
    return grid


def segment_bound(f: Values, a: Vec3, b: Vec3, motion: str,
                  low: np.ndarray | None = None, high: np.ndarray | None = None,
                  tolerance: float = TOLERANCE_MM, max_depth: int = MAX_DEPTH
                  ) -> Bound:
    """Bound of each column of ``f`` over the set a move from a to b can pass
    through (module docstring), by branch and bound: every cell is sampled on a
    3-point grid per dimension and bounded (:func:`cell_bounds`); a cell whose
    bound lies more than ``tolerance`` beyond the best value found so far is split
    in two along every dimension, until none is (or the depth or cell budget is
    spent: the bound then stays as wide as the cells left). ``low``/``high``: the
    search only has to decide whether the values keep within them (Bound.within,
    Bound.refutes): a sample beyond them ends it at once (the bound then unknown,
    ±inf), and a cell whose bound lies within them is not refined further (its
    bound already proves it safe), so the Bound is as sharp as that decision
    needed, not within ``tolerance`` (``sharp`` False). ``max_depth``: rounds of splitting
    at most (1: the cell bounds of one 3-point grid, for a set so small that its
    curvature widens them by microns). Raises OutsideWorkspace when ``f`` does (the
    set leaves the machine's workspace)."""
    a_v, b_v = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    d, joints = _space(a_v, b_v, motion)
    if d == 0:
        v = _evaluate(f, a_v[None, :])[0]
        return Bound(v, v, v, v)
    deciding = low is not None or high is not None
    offsets, corners = _unit_grid(d, 3), _unit_grid(d, 2)  # (3^d, d), (2^d, d)
    c0, size = np.zeros((1, d)), np.ones((1, d))  # cells in the unit cube
    best_lo = best_hi = None
    final_lo: list[np.ndarray] = []
    final_hi: list[np.ndarray] = []
    dims = tuple(range(1, d + 1))
    for depth in range(max_depth):
        u = c0[:, None, :] + size[:, None, :] * offsets[None, :, :]  # (B, 3^d, d)
        values = _evaluate(f, joints(u.reshape(-1, d)))
        m = values.shape[-1]
        flat = values.reshape(-1, m)
        lo_now, hi_now = flat.min(axis=0), flat.max(axis=0)
        best_lo = lo_now if best_lo is None else np.minimum(best_lo, lo_now)
        best_hi = hi_now if best_hi is None else np.maximum(best_hi, hi_now)
        if _outside(lo_now, hi_now, low, high):  # refuted: no bound needed
            return Bound(np.full(m, -np.inf), np.full(m, np.inf), best_lo, best_hi, False)
        grid = values.reshape(len(c0), *([3] * d), m)
        sub_lo, sub_hi = cell_bounds(grid, dims)
        sub_lo, sub_hi = sub_lo.reshape(-1, m), sub_hi.reshape(-1, m)  # (B·2^d, m)
        sub_c0 = (c0[:, None, :] + size[:, None, :] * corners[None, :, :]).reshape(-1, d)
        sub_size = np.repeat(size / 2.0, len(corners), axis=0)
        split = (sub_lo < best_lo - tolerance).any(axis=1) | \
            (sub_hi > best_hi + tolerance).any(axis=1)
        if deciding:
            # A decision: only a cell that may cross a limit needs a sharper bound.
            split &= _crosses(sub_lo, sub_hi, low, high)
        if depth == max_depth - 1 or np.count_nonzero(split) * len(offsets) > MAX_SAMPLES:
            split[:] = False  # the budget is spent: these bounds stand as they are
        final_lo.append(sub_lo[~split].min(axis=0, initial=np.inf))
        final_hi.append(sub_hi[~split].max(axis=0, initial=-np.inf))
        if not split.any():
            break
        c0, size = sub_c0[split], sub_size[split]
    lo, hi = np.min(final_lo, axis=0), np.max(final_hi, axis=0)
    assert best_lo is not None and best_hi is not None
    return Bound(np.minimum(lo, best_lo), np.maximum(hi, best_hi), best_lo, best_hi,
                 not deciding)


def _evaluate(f: Values, points: np.ndarray) -> np.ndarray:
    try:
        values = np.asarray(f(points), dtype=float)
    except (NotCrossing, OutsideWorkspace):
        raise
    except ValueError as exc:
        raise OutsideWorkspace(str(exc)) from None
    return values.reshape(len(points), -1)


def _crosses(lo: np.ndarray, hi: np.ndarray, low: np.ndarray | None,
             high: np.ndarray | None) -> np.ndarray:
    """Per cell (rows of lo/hi), whether its bound reaches beyond a limit."""
    out = np.zeros(len(lo), dtype=bool)
    if low is not None:
        out |= (lo < low - 1e-9).any(axis=1)
    if high is not None:
        out |= (hi > high + 1e-9).any(axis=1)
    return out


def _outside(lo: np.ndarray, hi: np.ndarray, low: np.ndarray | None,
             high: np.ndarray | None) -> bool:
    # 1e-9: a bound that touches its limit (a stop, where the travel is exact) holds
    return bool((low is not None and (lo < low - 1e-9).any())
                or (high is not None and (hi > high + 1e-9).any()))


def line_point(a: Vec3, b: Vec3,
               geometry: Geometry) -> Callable[[float], np.ndarray]:
    """λ ↦ the joints that put the end point at fraction λ of its straight line
    from P(a) to P(b) (nominal kinematics); the joint-space line where an end has
    no forward kinematics (the plan check then says where)."""
    a_v = np.asarray(a, dtype=float)
    b_v = np.asarray(b, dtype=float)
    try:
        pa, pb = orthocal.forward(a_v, geometry), orthocal.forward(b_v, geometry)
    except ValueError:
        return lambda lam: a_v + (b_v - a_v) * lam

    def at(lam: float) -> np.ndarray:
        if lam <= 0.0:
            return a_v.copy()
        if lam >= 1.0:
            return b_v.copy()
        try:
            return np.asarray(orthocal.inverse(pa + (pb - pa) * lam, geometry), dtype=float)
        except ValueError:
            return a_v + (b_v - a_v) * lam

    return at


Feasible = Callable[[np.ndarray, np.ndarray, float], bool]  # (start, end, slack) -> safe


def _greedy(feasible: Feasible, at: Callable[[float], np.ndarray], slack: float,
            max_waypoints: int) -> list[float] | None:
    """Fractions of the waypoints, each sub-move as long as ``feasible`` allows."""
    cuts: list[float] = []
    t0 = 0.0
    while True:
        start = at(t0)
        if feasible(start, at(1.0), slack):
            return cuts
        if len(cuts) >= max_waypoints:
            return None
        lo, hi = t0, 1.0
        for _ in range(BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            if feasible(start, at(mid), slack):
                lo = mid
            else:
                hi = mid
        if lo <= t0:
            return None  # not even a short step from here holds
        cuts.append(lo)
        t0 = lo


def route(feasible: Feasible, a: Vec3, b: Vec3, geometry: Geometry,
          max_waypoints: int, max_slack: float = 0.0) -> list[np.ndarray] | None:
    """The targets of the sub-moves from a to b (waypoints, then b), fewest first
    (module docstring), or None when no route of up to ``max_waypoints`` holds.
    ``feasible(start, end, slack)`` says whether one COMMAND 1 from start to end is
    safe with ``slack`` mm to spare; with the count found, the waypoints are
    spread for the largest common slack up to ``max_slack``."""
    at = line_point(a, b, geometry)
    cuts = _greedy(feasible, at, 0.0, max_waypoints)
    if cuts is None:
        return None
    if cuts and max_slack > 0:
        # The largest slack that the same number of waypoints still achieves.
        count = len(cuts)
        lo, hi = 0.0, max_slack
        for _ in range(SPREAD_STEPS):
            mid = 0.5 * (lo + hi)
            spread = _greedy(feasible, at, mid, count)
            if spread is None:
                hi = mid
            else:
                lo, cuts = mid, spread
    return [at(t) for t in cuts] + [np.asarray(b, dtype=float)]
