"""The cell bounds under every path check (station/plan/motion.py ``cell_bounds``):
the 3-point grid's shortcut gives the numbers the general formula gives, bit for
bit, and a bound holds the function it bounds inside every cell."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from station.plan.motion import CURVATURE_SAFETY, cell_bounds


def general_cell_bounds(values: np.ndarray, dims: tuple[int, ...]
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The bound as first written, for any grid size: every node's |second
    difference| (the ends take their neighbour's), its max over each cell's corners
    along every grid axis."""

    def extremes(v: np.ndarray, axes: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = v, v
        for axis in axes:
            n = v.shape[axis]
            a = [slice(None)] * v.ndim
            b = [slice(None)] * v.ndim
            a[axis], b[axis] = slice(0, n - 1), slice(1, n)
            lo = np.minimum(lo[tuple(a)], lo[tuple(b)])
            hi = np.maximum(hi[tuple(a)], hi[tuple(b)])
        return lo, hi

    cell_lo, cell_hi = extremes(values, dims)
    widen = np.zeros(cell_lo.shape)
    for axis in dims:
        n = values.shape[axis]
        d2 = np.abs(np.diff(values, n=2, axis=axis))
        d2 = np.concatenate([np.take(d2, [0], axis=axis), d2, np.take(d2, [n - 3], axis=axis)],
                            axis=axis)
        d2_cell = CURVATURE_SAFETY * extremes(d2, dims)[1]
        others = tuple(a for a in dims if a != axis)
        d_lo, d_hi = extremes(np.diff(values, axis=axis), others)
        monotone = (d_lo >= d2_cell / 2.0) | (d_hi <= -d2_cell / 2.0)
        widen = widen + np.where(monotone, 0.0, d2_cell / 8.0)
    return cell_lo - widen, cell_hi + widen


@pytest.mark.parametrize(("batch", "d", "n", "columns"), [
    (7, 1, 3, 2), (5, 2, 3, 3), (4, 3, 3, 2), (3, 2, 5, 2), (2, 3, 4, 1)])
def test_the_shortcut_is_the_general_formula_bit_for_bit(batch: int, d: int, n: int,
                                                         columns: int) -> None:
    rng = np.random.default_rng(20261203 + 10 * d + n)
    dims = tuple(range(1, d + 1))
    for scale in (1e-6, 1.0, 300.0):
        # smooth (monotone cells, where no widening is due) and rough (where it is)
        grid = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0, n)] * d, indexing="ij"), axis=-1)
        smooth = scale * (grid.sum(axis=-1)[None, ..., None]
                          + 0.1 * (grid**2).sum(axis=-1)[None, ..., None])
        rough = scale * rng.standard_normal((batch, *[n] * d, columns))
        for values in (np.broadcast_to(smooth, (batch, *[n] * d, columns)).copy(), rough,
                       smooth + 1e-3 * rough):
            lo, hi = cell_bounds(values, dims)
            ref_lo, ref_hi = general_cell_bounds(values, dims)
            assert lo.shape == ref_lo.shape == (batch, *[n - 1] * d, columns)
            assert np.array_equal(lo, ref_lo) and np.array_equal(hi, ref_hi)


def test_a_bound_holds_the_function_inside_every_cell() -> None:
    # A smooth function with an extreme inside a cell (where sampling the corners and
    # the middle misses it) and monotone stretches, bounded on one 3-point grid per
    # square of a chequerboard, then evaluated densely inside each cell.
    def f(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.sin(3.0 * x + 0.4) * np.cos(2.0 * y) + 0.3 * x * y

    for x0, y0, h in itertools.product((0.0, 0.45, 1.1), (0.0, 0.7), (0.3, 0.6)):
        u = np.linspace(0.0, 1.0, 3)
        X, Y = np.meshgrid(x0 + h * u, y0 + h * u, indexing="ij")
        lo, hi = cell_bounds(f(X, Y)[None, :, :, None], (1, 2))
        for i, j in itertools.product(range(2), range(2)):
            s = np.linspace(0.0, 0.5, 21)
            xs, ys = np.meshgrid(x0 + h * (i * 0.5 + s), y0 + h * (j * 0.5 + s), indexing="ij")
            inside = f(xs, ys)
            assert lo[0, i, j, 0] <= inside.min() + 1e-12, (x0, y0, h, i, j)
            assert inside.max() <= hi[0, i, j, 0] + 1e-12, (x0, y0, h, i, j)
