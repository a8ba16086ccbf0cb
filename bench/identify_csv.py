"""``orthocal identify`` on a CSV without a ``cycle`` column: do its 95 % intervals hold
the truth?

Machines with offsets within ±2 mm (and ``--gap`` mm of gaps), read as a run reads them
(1 µm gauges, 3 cycles of 5 readings, consecutive cycles sharing their Π0 stops, each
gauge's stand set by eye up to ``--mount-error`` mm off the leg's middle), written as one
value per deviation (each the mean of its cycles), identified with ``--model``. For
every parameter, over the machines: how often the truth lies outside the 95 % interval
and how far (error over the interval's half-width), with

* the fit's standard errors alone, k from Student's t on its residual's dof (what
  ``identify`` printed as "std err" before);
* the intervals ``identify`` states (station.commands.identify.uncertainty: the stands
  carried as a Type B term within ±--mount-error).

    python bench/identify_csv.py                      # 200 machines, model rho
    python bench/identify_csv.py --model rho+gap --gap 0.1 --runs 100
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import orthocal
from orthocal.noise import coverage_factor
from station.commands.identify import uncertainty

GAUGES = [(i, j) for i in "xyz" for j in "xyz" if i != j]
KEYS = [(s, i, j) for i, j in GAUGES for s in "+-"]


def means(truth: np.ndarray, rng: np.random.Generator, mount_error: float,
          noise: float = 0.001, cycles: int = 3, readings: int = 5) -> dict:
    """One value per deviation: the mean of its cycles, each cycle's stop mean less the
    mean of the two Π0 stops around it, every gauge in its stand's plane."""
    stands = rng.uniform(-mount_error, mount_error, len(GAUGES))
    planes = stands[[GAUGES.index((k[1], k[2])) for k in KEYS]]
    exact = orthocal.deviations(KEYS, orthocal.Geometry(), truth, planes)
    stops = rng.normal(0.0, noise, (len(GAUGES), 3 * cycles + 1, readings)).mean(axis=2)
    out = {}
    for n, (s, i, j) in enumerate(KEYS):
        g, off = GAUGES.index((i, j)), 1 if s == "+" else 2
        per = [stops[g, 3 * c + off] - 0.5 * (stops[g, 3 * c] + stops[g, 3 * c + 3])
               for c in range(cycles)]
        out[(s, i, j)] = [float(exact[n] + np.mean(per))]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--model", default="rho")
    parser.add_argument("--gap", type=float, default=0.0)
    parser.add_argument("--mount-error", type=float, default=5.0)
    args = parser.parse_args()
    geometry = orthocal.Geometry()
    before, after = [], []
    for seed in range(args.runs):
        rng = np.random.default_rng(seed)
        truth = np.r_[rng.uniform(-2, 2, 3), 0, 0, 0, 0, 0, 0,
                      args.gap, -args.gap, args.gap]
        data = means(truth, rng, args.mount_error)
        fit = orthocal.identify(data, geometry, model=args.model)
        stated = uncertainty(fit, geometry, data, args.mount_error)
        assert stated is not None
        true = dict(zip(orthocal.PARAM_NAMES, truth, strict=True))
        k = coverage_factor(fit.dof)
        before.append([(fit.parameters[n] - true[n]) / (k * fit.std_errors[n])
                       for n in fit.names])
        after.append([(fit.parameters[n] - true[n]) / stated["expanded"][n] for n in fit.names])
    names = list(fit.names)
    print(f"model {args.model}, {args.runs} machines, offsets within ±2 mm, gaps "
          f"{args.gap:g} mm, stands by eye within ±{args.mount_error:g} mm, one value per "
          "deviation (no cycle column); error over the 95 % half-width:")
    for label, z in (("fit's standard errors alone", before), ("identify's intervals", after)):
        a = np.abs(np.array(z))
        outside = ", ".join(f"{n} {100 * v:.1f} %"
                            for n, v in zip(names, (a > 1).mean(axis=0), strict=True))
        print(f"  {label}: outside {outside}; worst {a.max():.2f}, "
              f"RMS {np.sqrt(np.mean(a**2)):.2f}")


if __name__ == "__main__":
    main()
