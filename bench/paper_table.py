"""The paper's Table 1 (experiment 1, before calibration) under each model.

Pashkevich & Gomolitsky's twelve deviations, as printed (two digits, mm), are
identified with ``method="nonlinear"`` on the paper's geometry (L = 310.25 mm,
strokes −100 / +60 mm) under every model of :data:`orthocal.MODELS`. For each
model that these twelve deviations determine it prints the parameters (mm; tilts
in mrad), their standard errors from the fit's own residual (σ̂ = √(RSS/dof), so
on 12 − p degrees of freedom), the residual RMS, the degrees of freedom, the
condition number, and what the table's rounding to 0.01 mm cannot settle: the
standard deviation of each parameter over ``--draws`` fits of the table plus
uniform ±0.005 mm noise (seed fixed). Beside the residual, the residual that
rounding alone would leave if the model were exact: 0.005/√3 mm · √(dof/12).
For the models they do not determine, the reason :func:`orthocal.identify`
gives (:class:`orthocal.IdentificationError`).

    python bench/paper_table.py                   # 2000 draws, ~7 min
    python bench/paper_table.py --draws 200 --seed 2
    python bench/paper_table.py --json            # the same figures as JSON

There is no target: this states what the twelve numbers carry, under each model.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from orthocal import MODELS, TILT_NAMES, Geometry, IdentificationError, identify

GEOMETRY = Geometry(310.25, -100.0, 60.0)
# Table 1 of the paper, in the order of its columns: (posture sign, leg i, direction j).
COLUMNS = [
    ("+", "y", "x"), ("+", "x", "y"), ("-", "y", "x"), ("-", "x", "y"),
    ("+", "z", "x"), ("+", "x", "z"), ("-", "z", "x"), ("-", "x", "z"),
    ("+", "z", "y"), ("+", "y", "z"), ("-", "z", "y"), ("-", "y", "z"),
]  # fmt: skip
TABLE_1 = np.array([-0.19, 0.08, 0.22, -0.34, -0.29, -0.52, 0.08, 0.62, 0.02, -0.24, 0.20,
                    0.45])  # mm
ROUNDING = 0.005  # mm: the table's half-step
METHOD = "nonlinear"


def unit(name: str) -> str:
    return "mrad" if name in TILT_NAMES else "mm"


def fit(values: np.ndarray, model: str):
    return identify(dict(zip(COLUMNS, values, strict=True)), GEOMETRY, model=model,
                    method=METHOD)


def rounding_spread(model: str, names: tuple[str, ...], draws: int,
                    rng: np.random.Generator) -> tuple[dict[str, float], int]:
    """SD of each parameter over fits of the table plus uniform ±ROUNDING noise,
    and how many of the draws failed or did not converge (left out)."""
    found = []
    failed = 0
    for _ in range(draws):
        noisy = TABLE_1 + rng.uniform(-ROUNDING, ROUNDING, len(TABLE_1))
        try:
            r = fit(noisy, model)
        except IdentificationError:
            failed += 1
            continue
        if not r.converged:
            failed += 1
            continue
        found.append([r.parameters[n] for n in names])
    sd = np.std(np.array(found), axis=0, ddof=1)
    return {n: float(s) for n, s in zip(names, sd, strict=True)}, failed


def measure(draws: int, seed: int) -> list[dict]:
    rows = []
    for k, model in enumerate(MODELS):
        try:
            r = fit(TABLE_1, model)
        except IdentificationError as exc:
            rows.append({"model": model, "identifiable": False, "why": str(exc)})
            continue
        rng = np.random.default_rng([seed, k])  # each model its own stream
        spread, failed = rounding_spread(model, r.names, draws, rng)
        n = len(TABLE_1)
        rows.append({
            "model": model,
            "identifiable": True,
            "p": len(r.names),
            "dof": r.dof,
            "parameters": dict(r.parameters),
            "units": {nm: unit(nm) for nm in r.names},
            "std_errors": dict(r.std_errors),
            "rounding_sd": spread,
            "rounding_draws": draws - failed,
            "rounding_failed": failed,
            "residual_rms_um": 1e3 * r.residual_rms,
            "rounding_residual_um": 1e3 * ROUNDING / np.sqrt(3) * np.sqrt(r.dof / n),
            "condition_number": r.condition_number,
            "converged": r.converged,
        })
    return rows


def print_table(rows: list[dict], draws: int, seed: int) -> None:
    rms = 1e3 * float(np.sqrt(np.mean(TABLE_1**2)))
    print(f"Table 1 (experiment 1, before calibration): 12 deviations, RMS {rms:.0f} µm; "
          f"method {METHOD}")
    print(f"rounding: uniform ±{ROUNDING} mm ({1e3 * ROUNDING / np.sqrt(3):.2f} µm SD per "
          f"deviation), {draws} draws, seed {seed}")
    print()
    print(f"{'model':<14}{'p':>3}{'dof':>5}{'residual RMS':>14}{'rounding alone':>16}"
          f"{'condition':>11}")
    for row in rows:
        if not row["identifiable"]:
            print(f"{row['model']:<14}   not identifiable (see below)")
            continue
        print(f"{row['model']:<14}{row['p']:>3}{row['dof']:>5}"
              f"{row['residual_rms_um']:>11.1f} µm{row['rounding_residual_um']:>13.1f} µm"
              f"{row['condition_number']:>11.1f}"
              + ("" if row["converged"] else "  NOT CONVERGED"))
    print()
    print(f"{'model':<14}{'parameter':<10}{'value':>9}{'SE (fit)':>10}{'SD (rounding)':>15}"
          f"  unit")
    for row in rows:
        if not row["identifiable"]:
            continue
        for nm, value in row["parameters"].items():
            print(f"{row['model']:<14}{nm:<10}{value:>9.3f}{row['std_errors'][nm]:>10.3f}"
                  f"{row['rounding_sd'][nm]:>15.4f}  {row['units'][nm]}")
        if row["rounding_failed"]:
            print(f"{'':<14}({row['rounding_failed']} of {draws} rounding draws failed or "
                  "did not converge; left out)")
        print()
    for row in rows:
        if not row["identifiable"]:
            print(f"{row['model']}: {row['why']}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=2000,
                        help="rounding draws per model (default 2000)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args(argv)
    if args.draws < 2:
        parser.error("--draws must be at least 2")
    start = time.perf_counter()
    rows = measure(args.draws, args.seed)
    if args.json:
        print(json.dumps({"method": METHOD, "table_mm": TABLE_1.tolist(),
                          "columns": ["".join(c) for c in COLUMNS], "rounding_mm": ROUNDING,
                          "draws": args.draws, "seed": args.seed, "models": rows}, indent=2))
        return
    print_table(rows, args.draws, args.seed)
    print(f"\n{time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
