"""Identification accuracy against the statistical floor (issue: the maths).

For hidden offsets of 0.5, 2 and 5 mm and indicator noise σ = 5 µm on each of
the 12 deviations, a Monte Carlo of identifications prints, for each method,
the RMS error of the identified parameters divided by the statistical floor
σ·sqrt(diag((JᵀJ)⁻¹)) — the standard error of an ideal unbiased estimator,
with J the exact model's Jacobian at the true parameters. A ratio of 1 is the
best possible; the linear method (the paper's) adds its linearisation bias.

    python bench/accuracy.py [--trials 4000] [--model rho|L|full] [--seed 1]

Target: nonlinear ≤ 1.05 at every size. The Monte Carlo itself is uncertain by
about 1/sqrt(2·trials) (1.1 % at 4000 trials).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from orthocal import MODELS, PARAM_NAMES, Geometry, deviations, exact_jacobian, identify

KEYS = [(s, i, j) for s in "+-" for i in "xyz" for j in "xyz" if i != j]


def exact_floor(geometry: Geometry, truth: np.ndarray, model: str, sigma: float) -> np.ndarray:
    J = exact_jacobian(KEYS, geometry, truth, model)
    return sigma * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))


def run(size: float, model: str, trials: int, sigma: float, rng: np.random.Generator):
    geometry = Geometry()
    cols = list(MODELS[model])
    sq_err = {"linear": np.zeros(len(cols)), "nonlinear": np.zeros(len(cols))}
    floor_sq = np.zeros(len(cols))
    for _ in range(trials):
        truth = np.zeros(6)
        truth[cols] = size * rng.choice([-1.0, 1.0], len(cols))
        clean = deviations(KEYS, geometry, truth)
        data = dict(zip(KEYS, clean + rng.normal(0, sigma, len(KEYS)), strict=True))
        for method in sq_err:
            r = identify(data, geometry, model=model, method=method)
            sq_err[method] += (r.vector[cols] - truth[cols]) ** 2
        floor_sq += exact_floor(geometry, truth, model, sigma) ** 2
    floor = np.sqrt(floor_sq / trials)
    ratios = {m: np.sqrt(e / trials) / floor for m, e in sq_err.items()}
    return floor, ratios


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=4000)
    parser.add_argument("--model", choices=sorted(MODELS), default="rho")
    parser.add_argument("--noise", type=float, default=0.005, help="σ per deviation, mm")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    names = [PARAM_NAMES[c] for c in MODELS[args.model]]
    print(f"model {args.model}, σ = {args.noise * 1000:g} µm, {args.trials} trials per size, "
          f"12 deviations; ratio = RMS error / statistical floor (1 = ideal)")  # fmt: skip
    print(f"{'offset mm':>9}  {'floor µm':>9}  {'nonlinear':>20}  {'linear':>20}")
    worst = 0.0
    start = time.perf_counter()
    for size in (0.5, 2.0, 5.0):
        floor, ratios = run(size, args.model, args.trials, args.noise, rng)
        nl, li = ratios["nonlinear"], ratios["linear"]
        worst = max(worst, float(nl.max()))
        print(f"{size:9.1f}  {floor.mean() * 1000:9.2f}  "
              f"{np.sqrt(np.mean(nl**2)):6.3f} (max {nl.max():5.3f})  "
              f"{np.sqrt(np.mean(li**2)):6.3f} (max {li.max():6.3f})")  # fmt: skip
    print(
        f"per-parameter ratios are over {', '.join(names)}; "
        f"worst nonlinear ratio {worst:.3f} (target ≤ 1.05): "
        f"{'PASS' if worst <= 1.05 else 'FAIL'}; {time.perf_counter() - start:.0f} s"
    )


if __name__ == "__main__":
    main()
