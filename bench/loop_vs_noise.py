"""What the closed loop is for, and that it never chases noise.

Whole simulated calibrations through the real station (``orthocal run
--simulate ... --yes --json``, a subprocess each: virtual station, measurement,
identification, write-back rounds, verifications), with the procedure's default
cycles and readings (settle 0 and a fast virtual axis, to keep the wall time
down; neither changes a reading).

Part "misplaced": hidden Δρ uniform in ±2.9 mm, every indicator stand off the
leg's middle by a random amount uniform in ±8 mm (``--mount-error 8``, drawn anew
at every mounting), 1 µm indicator noise. Printed per run: the error of the
first round alone (max over the axes of |Δρ̂ − Δρ|: what a single write-back
leaves in the machine), the number of write-backs, and the final error of the
total written correction in units of the last identification's standard error
(the loop ends "within 3σ of the truth" when that is ≤ 3 on every axis), and
the run's own final statement: remaining.total (the correction the controller
holds plus what the last verification found left, not written) against the
truth, in the remaining's standard errors, and whether it lies inside the
run's 95 % interval.

Part "small": hidden Δρ uniform in ±0.5 mm, stands within ±1 mm, 1 µm noise:
one round fixes these machines, so every run must take exactly one write-back.

Part "promise": what "converged" promises. A held-out controller (a drive of
its own: cosine profiles, the station told nothing), 12.5 mm gauges at half
preload, stands set by eye (±5 mm), 1 µm noise, model auto, Δρ uniform in ±1.5
mm; with a short procedure (2 cycles × 3 readings) and the default one (3 × 5).
Per run: how it ended, the verification passes and write-backs, and what the
machine is left with: the true Δρ minus the correction the drive holds (read
back), worst axis. A run that says converged must leave every axis within
converge_mm (2 µm) + the drive's count (1 µm).

    python bench/loop_vs_noise.py [--runs 20] [--seed 1] [--part misplaced|small|both|promise]
                                [--model rho|auto|...]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from station_accuracy import coverage_range, simulated_run, statement_z  # bench/: sys.path[0]

AXES = ("x", "y", "z")
# Parts misplaced and small fit Δρ alone by default: the bias the loop removes is the
# stands'. --model auto measures the station's default, whose first round may take
# rho+tilt for the stands' misfit and later rounds choose again.
MODEL = "rho"


def calibrate(seed: int, drho: np.ndarray, mount_mm: float, noise: float, out: Path) -> dict:
    # "=": a value starting with "-" would read as an option
    return simulated_run(
        seed, out, "--true-drho=" + ",".join(f"{v:.4f}" for v in drho),
        "--mount-error", str(mount_mm), "--noise", str(noise), "--sim-speed", "20000",
        "--sim-procedure", json.dumps({"settle_s": 0.0, "model": MODEL}))


def promise(runs: int, seed0: int, tmp: Path) -> None:
    """Part "promise" (module docstring)."""
    for label, procedure in (("2 cycles × 3 readings", {"cycles": 2, "readings": 3}),
                             ("default, 3 cycles × 5 readings", {})):
        print(f"\n== promise: {label}, cosine drive, stands by eye (±5 mm), 1 µm noise, "
              f"model auto, {runs} runs")
        print(f"{'seed':>5} {'stopped':>14} {'passes':>10} {'writes':>6} "
              f"{'left on the machine (µm, x y z)':>32} {'wall s':>7}")
        ends: dict[str, int] = {}
        worst_converged: list[float] = []
        for k in range(runs):
            seed = seed0 + k
            rng = np.random.default_rng([seed, 20])
            drho = np.round(rng.uniform(-1.5, 1.5, 3), 4)
            t0 = time.monotonic()
            r = simulated_run(
                seed, tmp, "--true-drho=" + ",".join(f"{v:.4f}" for v in drho),
                "--mount-error", "5", "--noise", "0.001", "--drive-profile", "cosine",
                "--sim-speed", "20000",
                "--sim-procedure", json.dumps({"settle_s": 0.0, **procedure}))
            before, held = r["offsets_before"], r["offsets_written"]
            left = [1000 * (t - (before[a] - held[a])) for a, t in zip(AXES, drho,
                                                                      strict=True)]
            stopped = r["loop"]["stopped"]
            ends[stopped] = ends.get(stopped, 0) + 1
            if stopped == "converged":
                worst_converged.append(max(abs(v) for v in left))
            passes = "+".join(str(len(it.get("passes") or [it["phase"]]))
                              for it in r["iterations"][1:]) or "—"
            print(f"{seed:>5} {stopped:>14} {passes:>10} {writes(r):>6} "
                  f"{' '.join(f'{v:+.2f}' for v in left):>32} "
                  f"{time.monotonic() - t0:>7.1f}", flush=True)
        print("ended: " + ", ".join(f"{k} {v}" for k, v in sorted(ends.items())))
        if worst_converged:
            print(f"converged runs: worst axis left {max(worst_converged):.2f} µm (median "
                  f"{np.median(worst_converged):.2f}), within 2 µm + the 1 µm count in "
                  f"{sum(1 for w in worst_converged if w <= 3.0)}/{len(worst_converged)}")


def writes(r: dict) -> int:
    return sum(1 for it in r["iterations"] if it["offsets_written"] is not None)


def part(name: str, runs: int, seed0: int, drho_max: float, mount_mm: float, noise: float,
         tmp: Path) -> dict[str, list]:
    print(f"\n== {name}: Δρ uniform in ±{drho_max} mm, stands within ±{mount_mm} mm, "
          f"noise {noise * 1000:g} µm, {runs} runs")
    print(f"{'seed':>5} {'true Δρ (mm)':>26} {'1st round err':>14} {'write-backs':>11} "
          f"{'final |err|/σ (x y z)':>24} {'statement z (x y z)':>22} {'converged':>9} "
          f"{'wall s':>7}")
    rows: dict[str, list] = {"first": [], "rounds": [], "z": [], "converged": [],
                             "statement": [], "inside": []}
    for k in range(runs):
        seed = seed0 + k
        rng = np.random.default_rng([seed, 10])
        drho = np.round(rng.uniform(-drho_max, drho_max, 3), 4)
        t0 = time.monotonic()
        r = calibrate(seed, drho, mount_mm, noise, tmp)
        first = max(abs(r["iterations"][0]["identified"][f"drho_{a}"] - t)
                    for a, t in zip(AXES, drho, strict=True))
        # The last identification's standard errors: after the loop its fit is the
        # noise's (a first identification's σ̂ also holds the stands' misfit).
        last = r["iterations"][-1]
        z = [abs(r["identified"][f"drho_{a}"] - t) / last["std_errors"][f"drho_{a}"]
             for a, t in zip(AXES, drho, strict=True)]
        scored = statement_z(r, dict(zip(AXES, drho, strict=True)))
        stated = [z for z, _ in scored]
        rows["inside"] += [ok for _, ok in scored]
        rows["statement"].append(stated)
        rows["first"].append(first)
        rows["rounds"].append(writes(r))
        rows["z"].append(max(z))
        rows["converged"].append(bool(r["converged"]))
        print(f"{seed:>5} {' '.join(f'{v:+.3f}' for v in drho):>26} "
              f"{first * 1000:>11.1f} µm {writes(r):>11} "
              f"{' '.join(f'{v:.2f}' for v in z):>24} "
              f"{' '.join(f'{v:+.2f}' for v in stated) or '—':>22} {r['converged']!s:>9} "
              f"{time.monotonic() - t0:>7.1f}", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--part", choices=["misplaced", "small", "both", "promise"],
                        default="both")
    parser.add_argument("--model", default="rho", help="the procedure's model (default rho)")
    args = parser.parse_args()
    global MODEL
    MODEL = args.model
    with tempfile.TemporaryDirectory(prefix="orthocal-loop-") as tmp:
        if args.part == "promise":
            promise(args.runs, args.seed, Path(tmp))
            return
        if args.part in ("misplaced", "both"):
            m = part("misplaced stands", args.runs, args.seed, 2.9, 8.0, 0.001, Path(tmp))
            first = np.array(m["first"]) * 1000
            rounds = np.array(m["rounds"])
            print(f"first round alone: error ≥ 10 µm in {int(np.sum(first >= 10))}/{args.runs} "
                  f"runs (median {np.median(first):.1f} µm, max {first.max():.1f} µm)")
            print("write-backs per run: " + ", ".join(
                f"{n}: {int(np.sum(rounds == n))}" for n in sorted(set(rounds.tolist()))))
            within = int(np.sum(np.array(m["z"]) <= 3))
            print(f"closed loop: final total within 3σ of the truth on every axis in "
                  f"{within}/{args.runs} runs (worst {max(m['z']):.2f}σ); converged in "
                  f"{sum(m['converged'])}/{args.runs}")
            statement(m)
        if args.part in ("small", "both"):
            s = part("small offsets, well-placed stands", args.runs, args.seed, 0.5, 1.0,
                     0.001, Path(tmp))
            one = sum(1 for n in s["rounds"] if n == 1)
            print(f"exactly one write-back in {one}/{args.runs} runs; final total within 3σ "
                  f"in {sum(1 for z in s['z'] if z <= 3)}/{args.runs}")
            statement(s)


def statement(rows: dict[str, list]) -> None:
    runs = [r for r in rows["statement"] if r]
    z = np.asarray([v for r in runs for v in r])
    if z.size:
        every = sum(1 for r in runs if max(abs(v) for v in r) <= 3)
        lo, hi = coverage_range(z.size)
        print(f"the run's statement (remaining.total): within 3σ of the truth on every "
              f"axis in {every}/{len(rows['statement'])} runs; RMS(error/SE) "
              f"{float(np.sqrt(np.mean(z**2))):.2f}, max {float(np.max(np.abs(z))):.2f}; "
              f"inside its 95 % interval {sum(rows['inside'])}/{z.size} (an honest one: "
              f"{lo}-{hi}, 99 % of the time)")


if __name__ == "__main__":
    main()
