"""How often ``auto`` picks the right model: simulated station runs.

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
    python bench/model_selection.py --only section_standard_errors
    python bench/model_selection.py --only section_strokes   # what intermediate stops cost and buy

Requirement (noise 2 µm): untilted machines keep ``rho`` in ≥ 99 % of
runs; with 0.2 mrad of tilt or more a tilt model is picked in ≥ 99 %.
Sections are functions in ``SECTIONS``: add one to report another figure.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from orthocal import MODELS, Geometry, IdentificationError, design, deviations, identify
from orthocal.noise import noise_from_cycles, noise_from_readings
from orthocal.postures import posture_name
from orthocal.selection import LEVEL, select_model
from station.commands.design_command import plan_keys

G = Geometry()
LEGS = "xyz"
ALL_KEYS = [(s, i, j) for i in LEGS for j in LEGS if i != j for s in "+-"]


@dataclass(frozen=True)
class Case:
    name: str
    tilt: Callable[[np.random.Generator], np.ndarray]  # mrad
    wants_tilt: bool


def one_pair(size: float) -> Callable[[np.random.Generator], np.ndarray]:
    def draw(rng: np.random.Generator) -> np.ndarray:
        t = np.zeros(3)
        t[rng.integers(3)] = size * rng.choice([-1.0, 1.0])
        return t

    return draw


CASES = [
    Case("no tilt", lambda rng: np.zeros(3), wants_tilt=False),
    Case("0.2 mrad on one pair of axes", one_pair(0.2), wants_tilt=True),
    Case("0.2 mrad on all three pairs", lambda rng: 0.2 * rng.choice([-1.0, 1.0], 3), True),
    Case("0.5, -0.5, 0.3 mrad on the three pairs", lambda rng: np.array([0.5, -0.5, 0.3]),
         True),
]


GAUGES = [(i, j) for i in LEGS for j in LEGS if i != j]  # ALL_KEYS' gauges, in order
GAUGE_OF_KEY = np.array([GAUGES.index((k[1], k[2])) for k in ALL_KEYS])


def simulate_run(truth: np.ndarray, rng: np.random.Generator, noise: float, cycles: int,
                 readings: int, stands: np.ndarray | None = None
                 ) -> tuple[dict, np.ndarray]:
    """Per-cycle deviations (key → list) and the std of the readings at each stop;
    ``stands``: each gauge's stand off L/2 (mm, GAUGES order), each gauge then
    reading in its own plane (bench/stands_vs_auto.py)."""
    planes = None if stands is None else stands[GAUGE_OF_KEY]
    exact = dict(zip(ALL_KEYS, deviations(ALL_KEYS, G, truth, planes), strict=True))
    n_stops = 3 * cycles + 1  # Z0, P+1, P-1, Z1, P+2, ...
    # one (gauge, stop, reading) block per gauge: legs × two directions
    raw = rng.normal(0.0, noise, (6, n_stops, readings))
    means = raw.mean(axis=2)
    stop_std = raw.std(axis=2, ddof=1).ravel() if readings > 1 else np.empty(0)
    data: dict = {}
    for g, (i, j) in enumerate(GAUGES):
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
        r = selection_rates(Case(f"{size}", one_pair(size), True), few, rng)
        cells.append(f"{size:g} mrad {100 * r['right']:.0f} %")
    print(f"  power (tilt model picked, one pair tilted, {runs} runs each): " + ", ".join(cells))


def simulate_strokes(truth: np.ndarray, strokes: list[float], rng: np.random.Generator,
                     noise: float, cycles: int, readings: int) -> dict:
    """Per-cycle deviations of a run through ``strokes`` (the station's visiting
    order does not matter here: every stop of a cycle is read against the same
    two Π0 stops)."""
    names = [posture_name(float(st), G) for st in strokes]
    keys = [(p, i, j) for p in names for i in LEGS for j in LEGS if i != j]
    exact = dict(zip(keys, deviations(keys, G, truth), strict=True))
    n = len(names)
    data: dict = {k: [] for k in keys}
    for i in LEGS:
        for j in (d for d in LEGS if d != i):
            zero = rng.normal(0.0, noise, (cycles + 1, readings)).mean(axis=1)
            stops = rng.normal(0.0, noise, (cycles, n, readings)).mean(axis=2)
            for c in range(cycles):
                for k, p in enumerate(names):
                    dev = stops[c, k] - 0.5 * (zero[c] + zero[c + 1])
                    data[(p, i, j)].append(exact[(p, i, j)] + dev)
    return data


def section_strokes(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """What intermediate stops cost (run time, from the station's time model) and
    buy (standard errors: orthocal design's prediction and the scatter of
    simulated identifications), two against four stops per leg."""
    from station.commands.design_command import run_time
    from station.config import parse_config
    from station.plan.steps import build_plan

    runs = max(args.runs // 2, 50)
    models = ("rho", "rho+tilt", "full+tilt")
    print(f"intermediate stops ({runs} simulated runs per stroke set, noise "
          f"{1000 * args.noise:g} µm, {args.cycles} cycles × {args.readings} readings; run time "
          "at bench/cycle.py's timing: 100 mm/s, 1000 mm/s², settle 0.05 s, mitutoyo 9600 "
          "baud, measurement + verification, operator mounting excluded):")
    for strokes in ([60.0, -100.0], [60.0, 30.0, -50.0, -100.0]):
        cfg = parse_config({
            "controller": {"speed_mm_s": 100.0, "accel_mm_s2": 1000.0},
            "indicators": [{"name": "A", "port": "none"}, {"name": "B", "port": "none"}],
            "setups": [{"leg": i, "indicators": dict(zip("AB", [d for d in LEGS if d != i],
                                                         strict=True))} for i in LEGS],
            "procedure": {"cycles": args.cycles, "readings": args.readings,
                          "settle_s": 0.05, "strokes": strokes}})
        plan = build_plan(cfg)
        t = run_time(plan, cfg)
        keys, indicators = plan_keys(plan)
        estimates: dict[str, list[np.ndarray]] = {m: [] for m in models}
        for _ in range(runs):
            truth = np.zeros(9)
            truth[:3] = rng.uniform(-args.offset, args.offset, 3)
            data = simulate_strokes(truth, strokes, rng, args.noise, args.cycles,
                                    args.readings)
            for m in models:
                try:
                    fit = identify(data, G, model=m, method="nonlinear")
                    estimates[m].append(fit.vector - truth)
                except IdentificationError:
                    break
        cells = []
        for m in models:
            q = design.quality(keys, G, m)
            if not q.identifiable:
                cells.append(f"{m}: not identifiable (rank {q.rank} of {len(q.names)})")
                continue
            J = design.design_matrix(keys, G, m)
            pred = 1000 * args.noise * design.run_std_errors(J, indicators, args.cycles,
                                                              args.readings)
            # RMS error about the truth of the station's (nonlinear) fit: the linear
            # one carries several µm of linearisation bias at ±2 mm offsets (docs/model.md).
            emp = 1000 * np.sqrt(np.mean(np.square(estimates[m]), axis=0))[list(MODELS[m])]
            groups = {"Δρ": "drho", "ΔL": "dL", "tilt": "tilt"}
            parts = []
            for label, prefix in groups.items():
                idx = [k for k, nm in enumerate(q.names) if nm.startswith(prefix)]
                if idx:
                    unit = " µrad" if prefix == "tilt" else " µm"
                    parts.append(f"{label} {pred[idx].max():.2f}/{emp[idx].max():.2f}{unit}")
            cells.append(f"{m}: " + ", ".join(parts))
        label = ", ".join(f"{v:+g}" for v in strokes)
        print(f"  stops {label} mm: run {t['total_s']:.1f} s ({t['stops']} stops, "
              f"{t['moves']} moves per phase)")
        print("    SE predicted/simulated (largest of each group): " + "; ".join(cells))


def section_standard_errors(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """Are the reported standard errors honest? RMS(error / SE) of ordinary least
    squares against the station's (measured noise with the shared-Π0 correlation)."""
    from orthocal import identify
    from orthocal.covariance import with_measured_noise

    runs = max(args.runs // 2, 20)
    for model, tilt in (("rho", np.zeros(3)), ("rho+tilt", np.array([0.5, -0.5, 0.3]))):
        z_ols, z_station = [], []
        for _ in range(runs):
            truth = np.r_[rng.uniform(-args.offset, args.offset, 3), 0, 0, 0, tilt]
            data, _ = simulate_run(truth, rng, args.noise, args.cycles, args.readings)
            r = identify(data, G, model)
            sigma, _ = noise_from_cycles(data)
            station = with_measured_noise(r, G, sigma)
            cols = [0, 1, 2] + ([6, 7, 8] if "tilt" in model else [])
            err = r.vector[cols] - truth[cols]
            z_ols.append(err / [r.std_errors[n] for n in r.names])
            z_station.append(err / [station.std_errors[n] for n in r.names])

        def rms(z: list) -> str:
            return " / ".join(f"{v:.2f}" for v in np.sqrt(np.mean(np.square(z), axis=0)))

        print(f"  RMS(error / SE), {model}, {runs} runs: ordinary least squares {rms(z_ols)}; "
              f"station (measured noise, shared Π0) {rms(z_station)}")


#: The gap section's machines (docs/model.md, "Axes that do not meet"): what each has,
#: the straightness the config states (mm), and what auto should keep.
GAP_CASES: dict[str, dict[str, Any]] = {
    "gaps 0.05 mm": {"gap": 0.05, "bow": 0.0, "stated": 0.002, "want": "gap"},
    "gaps 0.1 mm": {"gap": 0.10, "bow": 0.0, "stated": 0.002, "want": "gap"},
    "square, axes meet": {"gap": 0.0, "bow": 0.0, "stated": 0.010, "want": "rho"},
    "legs bowed 8 µm": {"gap": 0.0, "bow": 0.008, "stated": 0.010, "want": "rho"},
}


def simulate_stands(truth: np.ndarray, rng: np.random.Generator, noise: float, cycles: int,
                    readings: int, stands: np.ndarray, bow: float) -> dict:
    """Per-cycle deviations as :func:`simulate_run` gives them, every gauge in its own
    plane (``stands``, mm off L/2, GAUGES order) and every gauge plane's leg bowed
    by the sagitta ``bow`` (mm)."""
    planes = stands[GAUGE_OF_KEY]
    bows = {g: bow for g in GAUGES} if bow else None
    exact = dict(zip(ALL_KEYS, deviations(ALL_KEYS, G, truth, planes, bow=bows), strict=True))
    means = rng.normal(0.0, noise, (6, 3 * cycles + 1, readings)).mean(axis=2)
    data: dict = {}
    for g, (i, j) in enumerate(GAUGES):
        for s, offset in (("+", 1), ("-", 2)):
            data[(s, i, j)] = [exact[(s, i, j)] + means[g, 3 * (k - 1) + offset]
                               - 0.5 * (means[g, 3 * (k - 1)] + means[g, 3 * k])
                               for k in range(1, cycles + 1)]
    return data


def section_gaps(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """Axes that do not meet (docs/model.md): how often auto finds gaps, keeps rho on
    a square machine whose axes meet, and claims gaps or tilts for bowed legs, at
    1 µm of noise, stands by eye (±5 mm, modelled as the station does), the
    station's allowance for the stated form and gauge errors (orthocal.misfit:
    the case's straightness, MPE 3 µm, plunger 2°, 0.5 K)."""
    from orthocal import Stands
    from orthocal.misfit import Allowance

    noise, offset = 0.001, 1.0
    print(f"axes that do not meet: {args.runs} runs per case, noise {1000 * noise:g} µm per "
          f"reading, {args.readings} readings × {args.cycles} cycles, offsets uniform "
          f"±{offset:g} mm, stands uniform ±5 mm (modelled, tolerance 5 mm), gaps of random "
          "sign on all three pairs")
    for name, case in GAP_CASES.items():
        if args.gap_case not in (None, name):
            continue
        allowance = Allowance(straightness={g: case["stated"] for g in GAUGES},
                              mpe={g: 0.003 for g in GAUGES}, plunger_angle_deg=2.0,
                              temperature_change=0.5)
        picks: Counter[str] = Counter()
        t0 = time.perf_counter()
        for _ in range(args.runs):
            truth = np.zeros(12)
            truth[:3] = rng.uniform(-offset, offset, 3)
            truth[9:] = case["gap"] * rng.choice([-1.0, 1.0], 3)
            data = simulate_stands(truth, rng, noise, args.cycles, args.readings,
                                   rng.uniform(-5.0, 5.0, 6), case["bow"])
            sigma, dof = noise_from_cycles(data)
            sel = select_model(data, G, sigma, dof, stands=Stands(tolerance=5.0),
                               allowance=allowance, level=args.level)
            picks[sel.model] += 1
        if case["want"] == "gap":
            right = sum(n for m, n in picks.items() if "gap" in m)
            what = "finds gaps"
        else:
            right = picks["rho"]
            what = "keeps rho"
        claims = ", ".join(f"{m} {100 * n / args.runs:.1f} %" for m, n in sorted(picks.items()))
        print(f"  {name:20s} (legs stated straight to {1000 * case['stated']:g} µm): {what} in "
              f"{100 * right / args.runs:5.1f} % ({claims}; "
              f"{(time.perf_counter() - t0) / args.runs:.2f} s/run)")


SECTIONS: list[Callable[[argparse.Namespace, np.random.Generator], None]] = [
    section_rates, section_calibration, section_power, section_standard_errors, section_strokes,
    section_gaps,
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
    ap.add_argument("--only", choices=[f.__name__ for f in SECTIONS], default=None,
                    help="run one section")
    ap.add_argument("--gap-case", choices=list(GAP_CASES), default=None,
                    help="section_gaps: one case only")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    for section in SECTIONS:
        if args.only in (None, section.__name__):
            section(args, rng)


if __name__ == "__main__":
    main()
