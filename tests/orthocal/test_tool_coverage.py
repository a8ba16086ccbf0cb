"""The tool's 95 % intervals mean what they say (docs/model.md, "Intervals at the
tool"): over N seeded simulated runs whose truth is known, the truth's RMS and max of
|E| lie inside their intervals at a rate between 0.90 and 0.99, in both regimes: a
large field (the tilted and gapped machine, offsets alone: 25-45 µm RMS; with its
geometry in the controller: ~1 µm) and a field near zero (a square machine left at
~1 µm). From both sides: a true machine θ is drawn, an estimate θ̂ simulated from it
(normal with the stated Σ, each bounded input uniform in ±its bound), the interval
computed from θ̂ alone, the truth's figure judged by the exact model.

Σ: Δρ 1 µm, tilts 0.01 mrad, gaps 2 µm (the held-out machine's identification errors).
A small grid (4³) and 500 draws per interval keep it fast; bench/tool_interval_coverage.py
runs the same regimes at 1000 runs, 5³ and the default 4000 draws.

N per regime, and what a rate in [0.90, 0.99] means for it (binomial): at N = 200 a
method that covers 95 % passes with probability 0.998, one that covers 88 % or 99.5 %
with 0.23 and 0.26. Near zero the truth can only be missed from below (a norm's
interval that reaches 0 holds a small truth whenever its upper end does), so the rate
is nearer 97.5 %: N = 300 there, where one that covers 97.5 % passes with probability
0.98 and one that covers 99.5 % with 0.19."""

from __future__ import annotations

import numpy as np
import pytest

from orthocal import Geometry, workspace_grid
from orthocal.accuracy import error_field, field_stats, fit_frame
from orthocal.compensation import compensated_field, compensated_interval
from orthocal.field_mc import Bounded
from orthocal.kinematics import forward, inverse
from orthocal.tool_interval import after_interval

G = Geometry()
SE = np.array([1e-3] * 3 + [0.0] * 3 + [0.01] * 3 + [0.002] * 3)
LAYOUT = np.array([0.2, 0.1, -0.15, 0.15, -0.10, 0.12])  # tilts mrad, gaps mm
# a bounded error of the tilts the shape of the legs' form's (each column a plane's
# bow read as tilts), each within ±0.01 mrad, drawn rectangular
FORM = np.zeros((12, 3))
FORM[6:9] = [[1.0, 0.5, 0.0], [0.0, 1.0, 0.5], [0.5, 0.0, 1.0]]
FORM_BOUND = np.full(3, 0.01)
LEAD = 2e-5  # the joints' lead error: within ±20 µm/m


@pytest.fixture(scope="module")
def grid() -> np.ndarray:
    return workspace_grid(None, 4, G).points


def lead_columns(points: np.ndarray) -> np.ndarray:
    """Joint errors (3n × 3) per unit lead error: e_i = ε_i·(ρ_i − L)."""
    rho = inverse(points, G)
    cols = np.zeros((len(points), 3, 3))
    for i in range(3):
        cols[:, i, i] = rho[:, i] - G.leg_length
    return cols.reshape(-1, 3)


def simulate(regime: str, runs: int, grid: np.ndarray, seed: int
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the truth's (RMS, max) per run, the RMS intervals, the max intervals), mm."""
    rng = np.random.default_rng(seed)
    truths, rms_iv, max_iv = [], [], []
    for k in range(runs):
        large = regime in ("offsets, tilted", "offsets, tilted, lead", "controller, tilted")
        truth = np.r_[rng.normal(0, 1e-3, 3), 0, 0, 0, LAYOUT if large else np.zeros(6)]
        est = truth + rng.standard_normal(12) * SE
        cov, dof, kw = np.diag(SE**2), None, {}
        if regime in ("offsets, tilted", "controller, tilted"):
            # Σ estimated on 10 dof (Student t in the draws), and the bounded input
            dof = 10
            cov = cov * rng.chisquare(dof) / dof
            est += FORM @ (rng.uniform(-1, 1, 3) * FORM_BOUND)
            kw["bounded"] = Bounded(FORM, FORM_BOUND)
        if regime.startswith("controller"):
            told, absent = est.copy(), None
            if regime == "controller, square":  # the model kept rho: Δρ told alone
                told[6:] = 0.0
                absent = [False] * 6 + [True] * 6
            iv = compensated_interval(told, est, cov, dof, grid, G, draws=500, seed=k,
                                      absent=absent, **kw)
            f = compensated_field(grid, G, truth, told)
            true = (f.rms_mm, f.max_mm)
        elif regime == "offsets, tilted, lead":
            # the truth's joints off by ε·(ρ − L), ε uniform in ±LEAD: not in the estimate
            eps = rng.uniform(-LEAD, LEAD, 3)
            e = (lead_columns(grid) @ eps).reshape(-1, 3)
            landed = forward(inverse(grid, G) + e, G, truth[:3], None, truth[6:9], truth[9:])
            true = field_stats(fit_frame(grid, landed - grid))
            iv = after_interval(est, cov, dof, None, grid, G, draws=500, seed=k,
                                joint_draws=Bounded(lead_columns(grid), [LEAD] * 3))
        else:
            f = error_field(grid, G, truth, None)
            true = (f.rms_mm, f.max_mm)
            iv = after_interval(est, cov, dof, None, grid, G, draws=500, seed=k, **kw)
        truths.append(true)
        rms_iv.append(iv.rms_interval_mm)
        max_iv.append(iv.max_interval_mm)
    return np.array(truths), np.array(rms_iv), np.array(max_iv)


def rates(truths: np.ndarray, rms_iv: np.ndarray, max_iv: np.ndarray) -> tuple[float, float]:
    inside = [(iv[:, 0] <= truths[:, i]) & (truths[:, i] <= iv[:, 1])
              for i, iv in enumerate((rms_iv, max_iv))]
    return float(np.mean(inside[0])), float(np.mean(inside[1]))


@pytest.mark.parametrize(("regime", "runs", "size"), [
    ("offsets, tilted", 200, (25e-3, 45e-3)),       # large: offsets alone
    ("offsets, tilted, lead", 200, (25e-3, 45e-3)),  # and errors of the joints
    ("controller, tilted", 200, (0.3e-3, 3e-3)),     # the geometry in the controller
    ("offsets, square", 300, (0.05e-3, 1.5e-3)),     # near zero
    ("controller, square", 300, (0.05e-3, 1.5e-3)),  # near zero, the layout not told
])
def test_the_truth_lies_inside_each_95_interval_at_95_percent(grid, regime, runs, size) -> None:
    truths, rms_iv, max_iv = simulate(regime, runs, grid, seed=2024)
    # the regime is the one named: the truth's median RMS
    assert size[0] < float(np.median(truths[:, 0])) < size[1]
    rms, mx = rates(truths, rms_iv, max_iv)
    assert 0.90 <= rms <= 0.99, f"{regime}: RMS inside {rms:.3f} of {runs}"
    assert 0.90 <= mx <= 0.99, f"{regime}: max inside {mx:.3f} of {runs}"
    # max ≥ RMS at both ends, in every run
    assert np.all(max_iv >= rms_iv)
    if regime.startswith("offsets, tilted"):
        # tilts and gaps identified, the tool more than 10 µm off with offsets alone:
        # the interval within half and twice the truth in every run
        assert np.all(truths[:, 0] > 0.010)
        assert np.all(rms_iv[:, 0] >= truths[:, 0] / 2) and np.all(rms_iv[:, 1] <= 2 * truths[:, 0])


def test_plain_s1_misses_a_truth_near_zero(grid) -> None:
    """Why the correction: plain S1 (the truth F(θ̂ − δ), δ drawn about the estimate,
    its 2.5-97.5 % range) on the square machine puts its lower end above the truth in
    most runs, the plug-in's norm being biased upward by the noise power; the
    intervals stated hold it (the test above)."""
    rng = np.random.default_rng(7)
    cols = [0, 1, 2, 6, 7, 8, 9, 10, 11]
    from orthocal.tool_interval import field_jacobian

    misses = 0
    for _ in range(40):
        truth = np.r_[rng.normal(0, 1e-3, 3), np.zeros(9)]
        est = truth + rng.standard_normal(12) * SE
        J = field_jacobian(grid, G, est, None, "translation", cols)
        F0 = error_field(grid, G, est, None).field.ravel()
        d = rng.standard_normal((500, 9)) * SE[cols]
        f = (F0 - d @ J.T).reshape(500, -1, 3)
        lo = np.quantile(np.sqrt(np.mean(np.sum(f**2, axis=2), axis=1)), 0.025)
        misses += error_field(grid, G, truth, None).rms_mm < lo
    assert misses >= 30  # of 40: plain S1 covers a truth near zero in a few runs at most
