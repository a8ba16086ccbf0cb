"""Misplaced indicator stands against ``auto`` ("Stands are not tilt").

The operator sets each stand "at the middle of the leg" by eye: each of the six
gauges reads in its own plane x_i = L/2 + m, m uniform in ±``--stand`` mm, drawn
afresh for each run. The deviations depend on m through (m × leg slope) and the
legs slope with the offsets Δρ, so on a square machine misplaced stands leave a
lack of fit that a model without them reads as tilt. Each run is simulated at
the station's data level as bench/model_selection.py does (per setup the stops
Π0, Π_i^+, Π_i^−, Π0, ... of ``--cycles`` cycles, ``--readings`` gaussian
readings of σ = ``--noise`` per stop and gauge, per-cycle deviations
P − (Z_before + Z_after)/2 around the exact model's, here read in the misplaced
planes; the noise from the cycle-to-cycle scatter), then
:func:`orthocal.select_model` decides, once as today and once with the stands
modelled (``stands=Stands(tolerance=--tolerance)``), on the same data.

    python bench/stands_vs_auto.py                      # 500 runs per case, ~4 min on one core
    python bench/stands_vs_auto.py --runs 100
    python bench/stands_vs_auto.py --only section_designs

Requirement (noise 2 µm, offsets ±1.5 mm, stands ±5 mm): square
machines keep a model without tilt in ≥ 99 % of runs, and 0.2 mrad of tilt (one
pair of axes, random pair and sign) is still found in ≥ 99 %.
Sections are functions in ``SECTIONS``.
"""

from __future__ import annotations

import argparse
import itertools
import time
from collections.abc import Callable

import numpy as np

# bench/ is sys.path[0]: the cases and the station's deviations of the model-selection
# bench, read here with each gauge in its own plane
from model_selection import ALL_KEYS as KEYS
from model_selection import GAUGE_OF_KEY, Case, G, one_pair
from model_selection import simulate_run as selection_run

from orthocal import deviations, identify
from orthocal.covariance import with_measured_noise
from orthocal.noise import noise_from_cycles
from orthocal.selection import LEVEL, lack_of_fit, select_model
from orthocal.stands import GAUGES, Stands

CASES = [
    Case("square", lambda rng: np.zeros(3), wants_tilt=False),
    Case("0.2 mrad on one pair of axes", one_pair(0.2), wants_tilt=True),
    Case("±0.2 mrad on all three pairs", lambda rng: 0.2 * rng.choice([-1.0, 1.0], 3), True),
]


def draw_machine(case: Case, args: argparse.Namespace, rng: np.random.Generator
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(9-vector of the truth, the six stands' offsets from L/2 in GAUGES order)."""
    truth = np.zeros(9)
    truth[:3] = rng.uniform(-args.offset, args.offset, 3)
    truth[6:] = case.tilt(rng)
    return truth, rng.uniform(-args.stand, args.stand, 6)


def simulate_run(truth: np.ndarray, stand: np.ndarray, rng: np.random.Generator,
                 args: argparse.Namespace) -> dict:
    """Per-cycle deviations (key → list), each gauge reading in its own plane."""
    return selection_run(truth, rng, args.noise, args.cycles, args.readings, stand)[0]


def _errors(ident, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Δρ error µm, tilt error µrad; a model without tilt states zero tilt)."""
    v = ident.vector
    return 1000 * (v[:3] - truth[:3]), 1000 * (v[6:] - truth[6:])


def _stat(errors: list[np.ndarray]) -> str:
    e = np.asarray(errors)
    return f"RMS {np.sqrt(np.mean(e**2)):5.2f}, worst {np.abs(e).max():6.1f}"


def section_rates(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """The requirement: today's ``auto`` and ``auto`` with the stands modelled, on
    the same runs; the chosen model's errors in Δρ and tilts (noise and stands)."""
    stands = Stands(tolerance=args.tolerance)
    print(f"misplaced stands: each gauge uniform ±{args.stand:g} mm off L/2, offsets "
          f"uniform ±{args.offset:g} mm, noise {1000 * args.noise:g} µm per reading, "
          f"{args.readings} readings per stop, {args.cycles} cycles, level {args.level:g}, "
          f"{args.runs} runs per case; stands modelled with tolerance ±{args.tolerance:g} mm")
    for case in CASES:
        right = {"today": 0, "stands": 0}
        err: dict[str, dict[str, list]] = {k: {"drho": [], "tilt": []} for k in right}
        t_used = {"today": 0.0, "stands": 0.0}
        for _ in range(args.runs):
            truth, stand = draw_machine(case, args, rng)
            data = simulate_run(truth, stand, rng, args)
            sigma, dof = noise_from_cycles(data)
            for label, option in (("today", None), ("stands", stands)):
                t0 = time.perf_counter()
                sel = select_model(data, G, sigma, dof, level=args.level,
                                   noise_source="cycle-to-cycle scatter", stands=option)
                t_used[label] += time.perf_counter() - t0
                right[label] += ("tilt" in sel.model) == case.wants_tilt
                d, t = _errors(sel.identification, truth)
                err[label]["drho"].append(d)
                err[label]["tilt"].append(t)
        want = "a tilt model" if case.wants_tilt else "no tilt"
        print(f"  {case.name}: {want} chosen")
        for label in right:
            rate = right[label] / args.runs
            verdict = "" if label == "today" else ("  [OK]" if rate >= 0.99 else "  [BELOW 99 %]")
            print(f"    {label:7s} {100 * rate:5.1f} %{verdict}  Δρ error µm "
                  f"{_stat(err[label]['drho'])}; tilt error µrad {_stat(err[label]['tilt'])}"
                  f"  ({1000 * t_used[label] / args.runs:.0f} ms/run)")


def section_bias(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """The stands' bias alone: the same machines' exact deviations (no noise, three
    identical cycles) fitted by the right model (rho when square, rho+tilt when
    tilted), without and with the stands modelled (their prior weighed at the
    procedure's nominal noise of one deviation)."""
    runs = max(args.runs // 5, 20)
    stands = Stands(tolerance=args.tolerance)
    sigma_dev = args.noise * np.sqrt(1.5 / args.readings)
    print(f"  bias (noiseless deviations, the right model, {runs} runs per case; Δρ µm, "
          "tilt µrad):")
    for case in CASES:
        model = "rho+tilt" if case.wants_tilt else "rho"
        err: dict[str, dict[str, list]] = {k: {"drho": [], "tilt": []}
                                           for k in ("today", "stands")}
        for _ in range(runs):
            truth, stand = draw_machine(case, args, rng)
            exact = deviations(KEYS, G, truth, stand[GAUGE_OF_KEY])
            clean = {k: [v] * args.cycles for k, v in zip(KEYS, exact, strict=True)}
            for label, option in (("today", None), ("stands", stands)):
                fit = identify(clean, G, model, sigma=sigma_dev if option else None,
                               stands=option)
                d, t = _errors(fit, truth)
                err[label]["drho"].append(d)
                err[label]["tilt"].append(t)
        tilt = {lab: f", tilt {_stat(e['tilt'])}" if case.wants_tilt else ""
                for lab, e in err.items()}
        print(f"    {case.name:30s} ({model}) today Δρ {_stat(err['today']['drho'])}"
              f"{tilt['today']} | stands Δρ {_stat(err['stands']['drho'])}{tilt['stands']}")


def section_robustness(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """When the station's knowledge is off: stands placed twice as badly as the
    tolerance says, and larger offsets (no tilt chosen on square machines / a tilt
    model chosen with 0.2 mrad on one pair)."""
    runs = max(args.runs // 5, 20)
    stands = Stands(tolerance=args.tolerance)
    print(f"  robustness ({runs} runs per cell, stands modelled with tolerance "
          f"±{args.tolerance:g} mm):")
    for label, over in ((f"stands ±{2 * args.stand:g} mm", {"stand": 2 * args.stand}),
                        (f"offsets ±{2 * args.offset:g} mm", {"offset": 2 * args.offset}),
                        (f"offsets ±{args.offset / 3:g} mm", {"offset": args.offset / 3})):
        sub = argparse.Namespace(**{**vars(args), **over})
        cells = []
        for case in CASES[:2]:
            right = 0
            for _ in range(runs):
                truth, stand = draw_machine(case, sub, rng)
                data = simulate_run(truth, stand, rng, sub)
                sigma, dof = noise_from_cycles(data)
                sel = select_model(data, G, sigma, dof, level=args.level, stands=stands)
                right += ("tilt" in sel.model) == case.wants_tilt
            cells.append(f"{case.name} {100 * right / runs:.1f} %")
        print(f"    {label:18s} right model: " + ", ".join(cells))


def section_calibration(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """The test's honesty: perfectly placed stands keep rho at the level's rate
    (the stands' prior only makes the test more lenient), and misplaced stands at
    level 0.05 reject rho in about 5 % (the two tests, lack of fit and against
    rho+tilt, at most 2 × 5 %)."""
    stands = Stands(tolerance=args.tolerance)
    square = CASES[0]
    kept_today = kept = 0
    for _ in range(args.runs):
        truth, _ = draw_machine(square, args, rng)
        data = simulate_run(truth, np.zeros(6), rng, args)
        sigma, dof = noise_from_cycles(data)
        kept_today += select_model(data, G, sigma, dof, level=args.level).model == "rho"
        kept += select_model(data, G, sigma, dof, level=args.level,
                             stands=stands).model == "rho"
    print(f"  calibration: stands at L/2 exactly, square machines: rho kept in "
          f"{100 * kept / args.runs:.1f} % with the stands modelled, "
          f"{100 * kept_today / args.runs:.1f} % today ({args.runs} runs, level "
          f"{args.level:g})")
    runs = max(args.runs // 2, 50)
    rejected = 0
    for _ in range(runs):
        truth, stand = draw_machine(square, args, rng)
        data = simulate_run(truth, stand, rng, args)
        sigma, dof = noise_from_cycles(data)
        rejected += select_model(data, G, sigma, dof, level=0.05,
                                 stands=stands).model != "rho"
    print(f"  calibration: misplaced stands at level 0.05: rho rejected in "
          f"{100 * rejected / runs:.1f} % of {runs} runs (≤ 5-10 % expected)")


def section_recovery(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """How well the stands come back, against the size of the leg's offset: the
    error RMS of the observable stands' estimates (square machines, the model
    chosen), how many are observable, and RMS(error / SE) with the SEs the station
    reports (with_measured_noise; ≈ 1 when they are honest)."""
    runs = max(args.runs // 2, 50)
    stands = Stands(tolerance=args.tolerance)
    edges = np.linspace(0.0, args.offset, 4)
    rows: list[tuple[float, float, bool, float]] = []  # (|Δρ_i|, error, observable, z)
    for _ in range(runs):
        truth, stand = draw_machine(CASES[0], args, rng)
        data = simulate_run(truth, stand, rng, args)
        sigma, dof = noise_from_cycles(data)
        fit = select_model(data, G, sigma, dof, level=args.level, stands=stands).identification
        fit = with_measured_noise(fit, G, sigma, noise_dof=dof)
        for g, (leg, direction) in enumerate(GAUGES):
            e = fit.stands[f"stand_{leg}{direction}"]
            err = e.offset - stand[g]
            rows.append((abs(truth["xyz".index(leg)]), err, e.observable, err / e.std_error))
    a = np.array(rows)
    print(f"  stand recovery ({runs} square machines, stands uniform ±{args.stand:g} mm: "
          f"RMS {args.stand / np.sqrt(3):.2f} mm before):")
    for lo, hi in itertools.pairwise(edges):
        sel = (a[:, 0] >= lo) & (a[:, 0] < hi + 1e-12)
        obs = sel & (a[:, 2] > 0)
        rms_obs = np.sqrt(np.mean(a[obs, 1] ** 2)) if obs.any() else float("nan")
        print(f"    |Δρ_leg| {lo:.1f}–{hi:.1f} mm: observable {100 * obs.sum() / sel.sum():5.1f} %,"
              f" error RMS {rms_obs:.2f} mm (observable), {np.sqrt(np.mean(a[sel, 1] ** 2)):.2f}"
              f" mm (all); RMS(error/SE) {np.sqrt(np.mean(a[sel, 3] ** 2)):.2f}")


def section_standard_errors(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """Are the stated standard errors honest with the stands modelled? RMS(error /
    SE) of Δρ and tilts over runs, SEs as the station states them (measured noise,
    shared Π0: with_measured_noise), the right model fitted."""
    runs = max(args.runs // 5, 20)
    stands = Stands(tolerance=args.tolerance)
    for case in CASES[:2]:
        model = "rho+tilt" if case.wants_tilt else "rho"
        z = []
        for _ in range(runs):
            truth, stand = draw_machine(case, args, rng)
            data = simulate_run(truth, stand, rng, args)
            sigma, dof = noise_from_cycles(data)
            fit = with_measured_noise(identify(data, G, model, sigma=sigma, stands=stands), G,
                                      sigma, noise_dof=dof)
            cols = [0, 1, 2] + ([6, 7, 8] if case.wants_tilt else [])
            z.append((fit.vector[cols] - truth[cols]) / [fit.std_errors[n] for n in fit.names])
        rms = " / ".join(f"{v:.2f}" for v in np.sqrt(np.mean(np.square(z), axis=0)))
        print(f"  RMS(error / SE), {model} with stands, {case.name}, {runs} runs: {rms}")


def section_designs(args: argparse.Namespace, rng: np.random.Generator) -> None:
    """The alternatives weighed for the option (same runs): (a) fixed-effect stands,
    rho's lack of fit on 12 − 3 − 6 = 3 dof (the fit with a tolerance of 10 m, the
    prior negligible); (b) random-effect stands, the lack of fit alone (9 dof);
    (b + LR) the option as built: (b) and the test against rho+tilt."""
    runs = max(args.runs // 4, 50)
    from scipy.stats import f as f_dist

    stands = Stands(tolerance=args.tolerance)
    fixed = Stands(tolerance=1e4)
    print(f"  designs, rho rejected ({runs} runs per case; square should be ≈ 0, tilt ≈ 100 %):")
    for case in CASES[:2]:
        rej = {"fixed (a)": 0, "random, lack of fit (b)": 0, "random + LR (chosen)": 0}
        for _ in range(runs):
            truth, stand = draw_machine(case, args, rng)
            data = simulate_run(truth, stand, rng, args)
            sigma, dof = noise_from_cycles(data)
            fit = identify(data, G, "rho", sigma=sigma, stands=fixed)
            t = lack_of_fit(fit, G, sigma, dof)
            F3 = t.F * t.dof_model / (t.dof_model - 6)
            rej["fixed (a)"] += f_dist.sf(F3, t.dof_model - 6, dof) < args.level
            sel = select_model(data, G, sigma, dof, level=args.level, stands=stands)
            first = sel.tests[0]
            rej["random, lack of fit (b)"] += first.p_value < args.level
            rej["random + LR (chosen)"] += sel.model != "rho"
        print(f"    {case.name:30s} " + ", ".join(f"{k} {100 * v / runs:.1f} %"
                                                   for k, v in rej.items()))


SECTIONS: list[Callable[[argparse.Namespace, np.random.Generator], None]] = [
    section_rates, section_bias, section_calibration, section_recovery,
    section_standard_errors, section_designs, section_robustness,
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=500)
    ap.add_argument("--noise", type=float, default=0.002, help="σ of one reading, mm")
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--readings", type=int, default=5)
    ap.add_argument("--offset", type=float, default=1.5, help="Δρ drawn in ±this, mm")
    ap.add_argument("--stand", type=float, default=5.0, help="stands drawn in ±this, mm")
    ap.add_argument("--tolerance", type=float, default=5.0,
                    help="the stands' placement tolerance the option is given, mm")
    ap.add_argument("--level", type=float, default=LEVEL)
    ap.add_argument("--seed", type=int, default=20261717)
    ap.add_argument("--only", choices=[f.__name__ for f in SECTIONS], default=None,
                    help="run one section")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    for section in SECTIONS:
        if args.only in (None, section.__name__):
            section(args, rng)


if __name__ == "__main__":
    main()
