"""Do the tool's 95 % intervals mean what they say? Coverage against simulated truths.

For each regime, ``--runs`` seeded trials: a true machine θ is drawn, an estimate θ̂ is
simulated from it (θ̂ = θ + δ, δ normal with the stated covariance Σ, plus each bounded
input drawn uniform in ±its bound), the interval is computed from θ̂ alone
(orthocal.tool_interval.after_interval, orthocal.compensation.compensated_interval:
Monte Carlo over the inputs' joint distribution, orthocal.field_mc), and the truth's
RMS and max of |E| over the grid are counted inside or not. Σ: Δρ 1 µm, tilts 0.01 mrad,
gaps 2 µm (standard errors; the held-out machine's identification errors,
docs/model.md "The geometry in the controller").

Regimes (the tilted and gapped machine: tilts (0.2, 0.1, −0.15) mrad, gaps (0.15,
−0.10, 0.12) mm; the square one: tilts and gaps 0; Δρ left ~N(0, 1 µm) in both):

* ``after-large``: offsets alone on the tilted and gapped machine (25–45 µm RMS);
  every run also checks the interval lies within half and twice the truth;
* ``after-large-t-form``: the same, Σ estimated on 10 dof (the estimate's Σ̂ = Σ·χ²₁₀/10,
  Student t in the draws) and the tilts off by a bounded form-like input (rectangular,
  ±0.01 mrad per column);
* ``after-large-lead``: the same, and the joints' lead errors within ±20 µm/m, in the
  truth only (the joint_draws hook);
* ``after-square``: offsets alone on the square machine (~0.4 µm RMS: near zero);
* ``after-written-square``: the square machine, its offsets written from this very
  estimate (Δρ's error in the truth: ``in_truth``);
* ``comp-large``: the geometry in the controller (told θ̂) on the tilted and gapped
  machine (~1 µm), with Student t and the bounded input as above;
* ``comp-square``: the square machine, the controller told Δρ only (the layout absent,
  its noise in the plug-in).

    python bench/tool_interval_coverage.py                      # 1000 runs per regime
    python bench/tool_interval_coverage.py --runs 200 --only after-square,comp-square
    python bench/tool_interval_coverage.py --form               # the legs' form's cost
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from orthocal import PARAM_NAMES, Geometry, covariance_matrix, deviations, identify
from orthocal.accuracy import error_field, field_stats, fit_frame, workspace_grid
from orthocal.budget import form_columns, form_covariance, propagation
from orthocal.compensation import compensated_field, compensated_interval
from orthocal.field_mc import Bounded
from orthocal.kinematics import forward, inverse
from orthocal.tool_interval import after_interval

G = Geometry()
SE = np.array([1e-3] * 3 + [0.0] * 3 + [0.01] * 3 + [0.002] * 3)
LAYOUT = np.array([0.2, 0.1, -0.15, 0.15, -0.10, 0.12])
FORM = np.zeros((12, 3))
FORM[6:9] = [[1.0, 0.5, 0.0], [0.0, 1.0, 0.5], [0.5, 0.0, 1.0]]
FORM_BOUND = np.full(3, 0.01)
LEAD = 2e-5
DRHO = ("drho_x", "drho_y", "drho_z")
REGIMES = ("after-large", "after-large-t-form", "after-large-lead", "after-square",
           "after-written-square", "comp-large", "comp-square")


def lead_columns(points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Joint errors (3n × 3) per unit lead error: e_i = ε_i·(ρ_i − L)."""
    rho = inverse(points, G) + offsets
    cols = np.zeros((len(points), 3, 3))
    for i in range(3):
        cols[:, i, i] = rho[:, i] - G.leg_length
    return cols.reshape(-1, 3)


def trial(regime: str, k: int, rng: np.random.Generator, grid: np.ndarray, draws: int
          ) -> tuple[tuple[float, float], object]:
    """(the truth's RMS and max, the interval stated) of one simulated run."""
    large = "large" in regime
    truth = np.r_[rng.normal(0, 1e-3, 3), 0, 0, 0, LAYOUT if large else np.zeros(6)]
    est = truth + rng.standard_normal(12) * SE
    cov, dof, kw = np.diag(SE**2), None, {}
    if "t-form" in regime or regime == "comp-large":
        dof = 10
        cov = cov * rng.chisquare(dof) / dof
        est += FORM @ (rng.uniform(-1, 1, 3) * FORM_BOUND)
        kw["bounded"] = Bounded(FORM, FORM_BOUND)
    o = -est[:3] if regime == "after-written-square" else np.zeros(3)
    if regime.startswith("comp"):
        told, absent = est.copy(), None
        if regime == "comp-square":
            told[6:] = 0.0
            absent = [False] * 6 + [True] * 6
        iv = compensated_interval(told, est, cov, dof, grid, draws=draws, seed=k,
                                  absent=absent, **kw)
        f = compensated_field(grid, G, truth, told)
        return (f.rms_mm, f.max_mm), iv
    if regime == "after-written-square":
        kw["in_truth"] = DRHO
    if regime == "after-large-lead":
        cols = lead_columns(grid, o)
        kw["joint_draws"] = Bounded(cols, [LEAD] * 3)
        e = (cols @ rng.uniform(-LEAD, LEAD, 3)).reshape(-1, 3)
        landed = forward(inverse(grid, G) + o + e, G, truth[:3], None, truth[6:9], truth[9:])
        true = field_stats(fit_frame(grid, landed - grid))
    else:
        f = error_field(grid, G, truth, o)
        true = (f.rms_mm, f.max_mm)
    iv = after_interval(est, cov, dof, o, grid, G, draws=draws, seed=k, **kw)
    return true, iv


def coverage(regime: str, runs: int, grid: np.ndarray, draws: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    inside, below, band, start = np.zeros(2), np.zeros(2), 0, time.process_time()
    for k in range(runs):
        true, iv = trial(regime, k, rng, grid, draws)
        for i, (t, (lo, hi)) in enumerate(zip(true, (iv.rms_interval_mm, iv.max_interval_mm),
                                              strict=True)):
            inside[i] += lo <= t <= hi
            below[i] += t < lo
        lo, hi = iv.rms_interval_mm
        band += true[0] / 2 <= lo and hi <= 2 * true[0]
    half = 1.96 * math.sqrt(0.95 * 0.05 / runs)
    print(f"{regime:22s} N={runs}: RMS {inside[0] / runs:.3f} (below {int(below[0])}), "
          f"max {inside[1] / runs:.3f} (below {int(below[1])}); within ½–2× the truth "
          f"{band}/{runs}; ±{half:.3f} at 95 %; {(time.process_time() - start) / runs:.3f} s "
          "CPU per run", flush=True)


def form_cost(straightness: float) -> None:
    """What the legs' form does to the held-out machine's figures, by how it is drawn:
    today's covariance (one bow shared by every plane with the worst sign, plus each
    plane's, as a normal), each plane's bow rectangular and independent, every plane
    bowed alike (rectangular)."""
    keys = [(s, i, j) for i in "xyz" for j in "xyz" if i != j for s in "+-"]
    truth = np.r_[0.002, -0.001, 0.0015, 0, 0, 0, LAYOUT]
    rng = np.random.default_rng(3)
    data = {key: list(v + rng.normal(0, 0.001, 3))
            for key, v in zip(keys, deviations(keys, G, truth), strict=True)}
    fit = identify(data, G, "rho+tilt+gap")
    prop = propagation(fit, G)
    est = np.array([fit.parameters.get(n, 0.0) for n in PARAM_NAMES])
    cov = covariance_matrix(np.asarray(fit.covariance), fit.names)
    grid = workspace_grid(None, 7, G).points
    layout = [i for i, n in enumerate(fit.names) if n.startswith(("tilt", "gap"))]

    def on_layout(b: Bounded) -> Bounded:  # as the station: the form's part in the layout
        c = np.zeros_like(b.columns)
        c[layout] = b.columns[layout]
        return Bounded(c, b.bounds, b.names)
    shared = np.zeros((12, 12))
    shared[6:, 6:] = covariance_matrix(form_covariance(prop, straightness), fit.names)[6:, 6:]
    print(f"legs straight to {1000 * straightness:g} µm (held-out machine, rho+tilt+gap fit "
          "of 12 deviations, 1 µm noise, 3 cycles; µm RMS [95 %]):")
    for label, kw in (("statistical only", {}),
                      ("covariance, shared bow + planes, normal", {"systematic": shared}),
                      ("each plane rectangular, independent", {
                          "bounded": on_layout(form_columns(prop, straightness))}),
                      ("every plane bowed alike, rectangular", {
                          "bounded": on_layout(form_columns(prop, straightness, alike=1.0))})):
        c = compensated_interval(est, est, cov, fit.std_error_dof, grid, **kw)
        a = after_interval(est, cov, fit.std_error_dof, None, grid, G, **kw)
        print(f"  {label:42s} in the controller {1000 * c.rms_mm:5.2f} "
              f"[{1000 * c.rms_interval_mm[0]:5.2f}, {1000 * c.rms_interval_mm[1]:5.2f}]; "
              f"offsets alone {1000 * a.rms_mm:5.2f} [{1000 * a.rms_interval_mm[0]:5.2f}, "
              f"{1000 * a.rms_interval_mm[1]:5.2f}]")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--points", type=int, default=5, help="grid nodes per axis")
    ap.add_argument("--draws", type=int, default=4000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--only", default=",".join(REGIMES))
    ap.add_argument("--form", action="store_true", help="the legs' form's cost instead")
    args = ap.parse_args()
    if args.form:
        for s in (0.010, 0.002):
            form_cost(s)
        return
    grid = workspace_grid(None, args.points, G).points
    print(f"grid {args.points}³ over the default box, {args.draws} draws per interval")
    for regime in args.only.split(","):
        if regime not in REGIMES:
            raise SystemExit(f"--only: unknown regime {regime!r} (one of {', '.join(REGIMES)})")
        coverage(regime, args.runs, grid, args.draws, args.seed)


if __name__ == "__main__":
    main()
