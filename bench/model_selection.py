"""How often ``auto`` picks the right model (issue 9): simulated station runs.

Each run is simulated at the station's data level, not through the devices: per
setup (leg i, two gauges along j and k) the stops Π0, Π_i^+, Π_i^−, Π0, ... of
``--cycles`` cycles, ``--readings`` gaussian readings of σ = ``--noise`` per stop
and gauge, stop means, per-cycle deviations P − (Z_before + Z_after)/2 around
the exact model's deviations of a machine with random offsets and the case's
tilts; the noise estimate is the one the station uses (cycle-to-cycle scatter
from two cycles on, else the scatter of readings at a stop). Then
:func:`orthocal.selection.select_model` decides, exactly as ``orthocal run``
with ``model = "auto"``.

    python bench/model_selection.py                    # 500 runs per case, ~3 min
    python bench/model_selection.py --runs 100 --cycles 2

Requirement (issue 9, noise 2 µm): untilted machines keep ``rho`` in ≥ 99 % of
runs; with 0.2 mrad of tilt or more a tilt model is picked in ≥ 99 %.
Sections are functions in ``SECTIONS``: add one to report another figure.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from orthocal import Geometry, deviations
from orthocal.selection import (
    LEVEL,
    noise_from_cycles,
    noise_from_readings,
    select_model,
)

G = Geometry()
LEGS = "xyz"
ALL_KEYS = [(s, i, j) for i in LEGS for j in LEGS if i != j for s in "+-"]


@dataclass(frozen=True)
class Case:
    name: str
    tilt: Callable[[np.random.Generator], np.ndarray]  # mrad
    wants_tilt: bool


def _one_pair(size: float) -> Callable[[np.random.Generator], np.ndarray]:
    def draw(rng: np.random.Generator) -> np.ndarray:
        t = np.zeros(3)
        t[rng.integers(3)] = size * rng.choice([-1.0, 1.0])
        return t

    return draw


CASES = [
    Case("no tilt", lambda rng: np.zeros(3), wants_tilt=False),
    Case("0.2 mrad on one pair of axes", _one_pair(0.2), wants_tilt=True),
    Case("0.2 mrad on all three pairs", lambda rng: 0.2 * rng.choice([-1.0, 1.0], 3), True),
    Case("issue's machine 0.5, -0.5, 0.3 mrad", lambda rng: np.array([0.5, -0.5, 0.3]), True),
]


def simulate_run(truth: np.ndarray, rng: np.random.Generator, noise: float, cycles: int,
                 readings: int) -> tuple[dict, np.ndarray]:
    """Per-cycle deviations (key → list) and the std of the readings at each stop."""
    exact = dict(zip(ALL_KEYS, deviations(ALL_KEYS, G, truth), strict=True))
    n_stops = 3 * cycles + 1  # Z0, P+1, P-1, Z1, P+2, ...
    # one (gauge, stop, reading) block per gauge: legs × two directions
    raw = rng.normal(0.0, noise, (6, n_stops, readings))
    means = raw.mean(axis=2)
    stop_std = raw.std(axis=2, ddof=1).ravel() if readings > 1 else np.empty(0)
    data: dict = {}
    gauges = [(i, j) for i in LEGS for j in LEGS if i != j]
    for g, (i, j) in enumerate(gauges):
        for s, offset in (("+", 1), ("-", 2)):
            vals = []
            for k in range(1, cycles + 1):
                zero = 0.5 * (means[g, 3 * (k - 1)] + means[g, 3 * k])
                vals.append(exact[(s, i, j)] + means[g, 3 * (k - 1) + offset] - zero)
            data[(s, i, j)] = vals
    return data, stop_std


def selection_rates(case: Case, args: argparse.Namespace, rng: np.random.Generator) -> dict:
    picks: Counter[str] = Counter()
    t0 = time.perf_counter()
    for _ in range(args.runs):
        truth = np.zeros(9)
        truth[:3] = rng.uniform(-args.offset, args.offset, 3)
        truth[6:] = case.tilt(rng)
        data, stop_std = simulate_run(truth, rng, args.noise, args.cycles, args.readings)
        if args.cycles >= 2:
            sigma, dof = noise_from_cycles(data)
            source = "cycle-to-cycle scatter"
        else:
            sigma, dof = noise_from_readings(stop_std, args.readings)
            source = "within-stop scatter"
        sel = select_model(data, G, sigma, dof, level=args.level, noise_source=source)
        picks[sel.model] += 1
    right = sum(v for m, v in picks.items() if ("tilt" in m) == case.wants_tilt)
    return {"picks": picks, "right": right / args.runs, "s_per_run":
            (time.perf_counter() - t0) / args.runs}


def section_rates(args: argparse.Namespace, rng: np.random.Generator) -> None:
    print(f"auto model selection: lack-of-fit F test at level {args.level:g}, "
          f"{args.runs} runs per case, noise {1000 * args.noise:g} µm per reading, "
          f"{args.readings} readings per stop, {args.cycles} cycle(s), "
          f"offsets uniform ±{args.offset:g} mm")
    for case in CASES:
        r = selection_rates(case, args, rng)
        want = "a tilt model" if case.wants_tilt else "rho"
        picks = ", ".join(f"{m} {100 * n / args.runs:.1f} %" for m, n in
                          sorted(r["picks"].items()))
        verdict = "OK" if r["right"] >= 0.99 else "BELOW 99 %"
        print(f"  {case.name:38s} picks {want:12s} in {100 * r['right']:5.1f} %  "
              f"[{verdict}]  ({picks}; {1000 * r['s_per_run']:.0f} ms/run)")


def section_calibration(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """The test's honesty: at level 0.05 an untilted machine should fail rho in 5 %."""
    loose = argparse.Namespace(**{**vars(args), "level": 0.05})
    r = selection_rates(CASES[0], loose, rng)
    print(f"  calibration: at level 0.05 rho is rejected on untilted machines in "
          f"{100 * (1 - r['right']):.1f} % of {args.runs} runs (5 % expected)")


def section_power(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """The smallest tilts auto sees (one pair of axes tilted, the weakest case)."""
    runs = max(args.runs // 5, 20)
    few = argparse.Namespace(**{**vars(args), "runs": runs})
    cells = []
    for size in (0.02, 0.05, 0.1):
        r = selection_rates(Case(f"{size}", _one_pair(size), True), few, rng)
        cells.append(f"{size:g} mrad {100 * r['right']:.0f} %")
    print(f"  power (tilt model picked, one pair tilted, {runs} runs each): " + ", ".join(cells))


SECTIONS: list[Callable[[argparse.Namespace, np.random.Generator], None]] = [
    section_rates, section_calibration, section_power,
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=500)
    ap.add_argument("--noise", type=float, default=0.002, help="σ of one reading, mm")
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--readings", type=int, default=5)
    ap.add_argument("--offset", type=float, default=2.0, help="Δρ drawn in ±this, mm")
    ap.add_argument("--level", type=float, default=LEVEL)
    ap.add_argument("--seed", type=int, default=20261124)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    for section in SECTIONS:
        section(args, rng)


if __name__ == "__main__":
    main()
