"""Is the uncertainty the station reports honest?

Runs ``orthocal run --simulate --noise 0.005 --seed k --yes --json`` for k =
seed .. seed+runs−1 (each a whole calibration: virtual station, measurement,
identification, write-back, verification; random hidden Δρ within ±2 mm),
then compares the identified Δρ with the hidden truth:

    honesty = RMS(identified − true) / RMS(reported standard error)

over every run and axis (1 = the reported uncertainty is what the errors
show; target 0.8–1.2). Also printed: the RMS of the per-value ratio
error / standard error, and the RMS error itself. With 20 runs × 3 axes the
figure is itself uncertain by about 1/sqrt(2·60) ≈ 9 %.

The same for the run's final statement, which is what the station claims about
the machine once the closed loop stopped: the truth is ``remaining.total``
(the correction the controller holds plus what the last verification found
left, not written) ± its standard errors; printed with how many values lie
inside the 95 % interval (k95 from Student's t on the dof the run reports;
target 95 %: the binomial range an honest statement falls in 99 % of the time,
printed with it).

    python bench/station_accuracy.py [--runs 20] [--noise 0.005] [--seed 1]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

AXES = ("x", "y", "z")


def station_command() -> list[str]:
    script = Path(sys.executable).with_name("orthocal")
    return [str(script)] if script.exists() else [sys.executable, "-m", "station"]


def simulated_run(seed: int, out: Path, *options: str) -> dict:
    """``orthocal run --simulate --seed SEED OPTIONS --yes --json`` as a subprocess:
    its JSON result; a failed run ends the benchmark with the station's stderr."""
    cmd = [*station_command(), "run", "--simulate", "--seed", str(seed), *options,
           "--yes", "--json", "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr[-4000:])
        raise SystemExit(f"seed {seed}: station run failed (exit {proc.returncode})")
    return json.loads(proc.stdout)


def statement_z(r: dict, truth: dict[str, float]) -> list[tuple[float, bool]]:
    """Per axis, the run's statement against the truth (axis → mm): (remaining.total
    − truth) / its SE, and whether that lies inside the run's 95 % interval. Empty
    when the run states nothing (no measurement after the last write-back)."""
    rem = r.get("remaining") or {}
    out = []
    for a in AXES:
        n = f"drho_{a}"
        if n in (rem.get("total") or {}):
            z = (rem["total"][n] - truth[a]) / rem["std_errors"][n]
            out.append((z, abs(z) <= rem["coverage_factor_95"]))
    return out


def coverage_range(n: int, level: float = 0.95, keep: float = 0.99) -> tuple[int, int]:
    """The counts of n values an honest ``level`` interval holds with probability at
    least ``keep``, half the rest in each tail of the binomial: (lo, hi). Two-sided,
    so that intervals too wide fail too; with few values hi is n, and only the RMS
    of error/SE can show them too wide."""
    from scipy.stats import binom  # a second to import; only when printing

    tail = (1.0 - keep) / 2
    return int(binom.ppf(tail, n, level)), int(binom.ppf(1.0 - tail, n, level))


def calibrate(seed: int, noise: float, out: Path) -> dict:
    # A fast virtual axis and no settle: neither changes a reading, both the wall time.
    return simulated_run(seed, out, "--noise", str(noise), "--sim-speed", "20000",
                         "--sim-procedure", json.dumps({"settle_s": 0.0}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--noise", type=float, default=0.005, metavar="MM")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    errors, ses, zs, inside = [], [], [], 0
    with tempfile.TemporaryDirectory(prefix="orthocal-honesty-") as tmp:
        for k in range(args.runs):
            seed = args.seed + k
            r = calibrate(seed, args.noise, Path(tmp))
            truth = r["simulation"]["true_drho"]
            e = [r["identified"][f"drho_{a}"] - truth[a] for a in AXES]
            se = [r["std_errors"][f"drho_{a}"] for a in AXES]
            errors.append(e)
            ses.append(se)
            for z, ok in statement_z(r, truth):
                zs.append(z)
                inside += ok
            cycles = [s["cycles_used"] for s in r["setups"]]
            print(f"seed {seed}: error " + ", ".join(f"{1000 * v:+6.2f}" for v in e)
                  + " µm; SE " + ", ".join(f"{1000 * v:.2f}" for v in se)
                  + f" µm; cycles {cycles}", flush=True)
    err = np.asarray(errors)
    se = np.asarray(ses)
    rms_err = float(np.sqrt(np.mean(err**2)))
    rms_se = float(np.sqrt(np.mean(se**2)))
    per_value = float(np.sqrt(np.mean((err / se) ** 2)))
    n = err.size
    print(f"{args.runs} calibrations, noise {1000 * args.noise:g} µm: RMS error "
          f"{1000 * rms_err:.2f} µm, RMS reported SE {1000 * rms_se:.2f} µm")
    print(f"honesty RMS(error)/RMS(SE) = {rms_err / rms_se:.3f}; RMS(error/SE) = "
          f"{per_value:.3f} (± ~{100 / np.sqrt(2 * n):.0f} % from {n} values; target 0.8–1.2)")
    if zs:
        z = np.asarray(zs)
        lo, hi = coverage_range(z.size)
        print(f"final statement (remaining.total): RMS(error/SE) = "
              f"{float(np.sqrt(np.mean(z**2))):.3f}, max {float(np.max(np.abs(z))):.2f}; "
              f"inside its 95 % interval {inside}/{z.size} ({100 * inside / z.size:.0f} %; "
              f"an honest one: {lo}-{hi}, 99 % of the time)")


if __name__ == "__main__":
    main()
