"""The statement's joint distribution (orthocal.uncertainty; docs/model.md, "The
statement's uncertainty", (14)): its check values, and that its Monte Carlo draws have
the moments its GUM combination states."""

from __future__ import annotations

import math

import numpy as np
import pytest

from orthocal.noise import coverage_factor
from orthocal.uncertainty import combined, type_a, type_b


def test_one_bounded_input_alone_gives_its_column_over_root_three() -> None:
    u = type_b(("a", "b"), np.array([[0.006], [-0.003]]), ["bow"], ["leg straightness"])
    m = u.marginal("a")
    assert m.u_b == pytest.approx(0.006 / math.sqrt(3.0), rel=1e-12)
    assert m.u_a == 0.0 and m.dof is None
    assert m.expanded == pytest.approx(coverage_factor(None) * 0.006 / math.sqrt(3.0))
    assert m.contributions == {"leg straightness": pytest.approx(0.006 / math.sqrt(3.0))}


def test_columns_of_one_label_are_one_input() -> None:
    # a bow seen by two fits: the same input, so a difference cancels it
    a = type_b(("drho_x",), np.array([[0.002]]), ["straightness:xy"], ["leg straightness"])
    b = type_b(("tilt_yx",), np.array([[0.002]]), ["straightness:xy"], ["leg straightness"])
    joint = combined([a, b], ("drho_x", "tilt_yx"))
    assert joint.linear_marginal([1.0, -1.0]).u_c == pytest.approx(0.0, abs=1e-15)
    assert joint.linear_marginal([1.0, 1.0]).u_c == pytest.approx(0.004 / math.sqrt(3.0))
    draws = joint.draws(2000, np.random.default_rng(1))
    assert np.allclose(draws[:, 0], draws[:, 1])  # one input drawn once
    other = type_b(("tilt_yx",), np.array([[0.002]]), ["straightness:xz"], ["leg straightness"])
    apart = combined([a, other], ("drho_x", "tilt_yx"))
    assert apart.linear_marginal([1.0, -1.0]).u_c == pytest.approx(
        math.sqrt(2.0) * 0.002 / math.sqrt(3.0))


def test_a_block_keeps_its_dof_and_combines_by_welch_satterthwaite() -> None:
    cov = np.array([[4e-6, 1e-6], [1e-6, 9e-6]])
    a = type_a(("x", "y"), cov, 12.0)
    m = a.linear_marginal([1.0, 1.0])
    assert m.u_a ** 2 == pytest.approx(cov.sum())
    assert m.dof == pytest.approx(12.0)
    assert m.k == pytest.approx(coverage_factor(12.0))
    ub = 0.002
    b = type_b(("x", "y"), np.array([[ub * math.sqrt(3.0)], [0.0]]), ["t"], ["temperature"])
    m2 = combined([a, b], ("x", "y")).marginal("x")
    assert m2.u_c == pytest.approx(math.sqrt(4e-6 + ub**2))
    assert m2.dof == pytest.approx((4e-6 + ub**2) ** 2 / ((4e-6) ** 2 / 12.0))
    assert 12.0 < m2.dof < math.inf


def test_draws_have_the_stated_covariance() -> None:
    # Type A on 20 dof (variance ν/(ν − 2) times Σ) and two Type B inputs
    cov = np.array([[1.0, 0.3], [0.3, 2.0]])
    a = type_a(("p", "q"), cov, 20.0)
    b = type_b(("p", "q"), np.array([[1.0, 0.0], [0.5, 2.0]]), ["u", "v"], ["s", "t"])
    joint = combined([a, b], ("p", "q"))
    draws = joint.draws(200_000, np.random.default_rng(7))
    expected = cov * 20.0 / 18.0 + joint.type_b_covariance()
    assert np.allclose(np.cov(draws.T), expected, rtol=0.03, atol=0.02)
    # the Type B part alone is bounded by its columns: |δ| ≤ Σ|c|
    only_b = type_b(("p", "q"), np.array([[1.0, 0.0], [0.5, 2.0]]), ["u", "v"], ["s", "t"])
    d = only_b.draws(50_000, np.random.default_rng(3))
    assert np.abs(d[:, 0]).max() <= 1.0 + 1e-12
    assert np.abs(d[:, 1]).max() <= 2.5 + 1e-12
    assert np.abs(d[:, 1]).max() > 2.3  # and reaches near it


def test_pick_and_embed_keep_the_errors() -> None:
    a = type_a(("x", "y", "z"), np.diag([1.0, 4.0, 9.0]), None)
    assert a.pick(("z", "x")).marginal("z").u_c == pytest.approx(3.0)
    e = a.embedded(("w", "x", "y", "z"))
    assert e.marginal("w").u_c == 0.0 and e.marginal("y").u_c == pytest.approx(2.0)
