"""The station's own joint test against the truth: whole simulated runs (``orthocal run
--simulate --joint-test`` in-process) of a machine whose screws have the leads
``--lead`` (µm/m, homed at Π0), lost motion ``--backlash`` and optionally a pitch
error, 1 µm gauges; the virtual station's gauge blocks read with gauge A on each
carriage, ISO 230-2's five approaches from each side of eight targets (docs/model.md,
"The station's own joint test"). For every seed and joint: the lead found, its 95 %
interval, its error, whether the interval holds the truth, the reversal the test's
own table shows against −B, the datum's drift; then per joint the RMS and largest
error and how often the interval held the truth. ``--plot FILE`` draws the leads
found against the true ones, each with its interval.

The virtual station runs on a clock 20 times faster than real time unless
ORTHOCAL_SIM_TIME_SCALE says otherwise: these are figures of accuracy, not of time.

    python bench/joint_test_runs.py                          # seeds 1-5, +100/-80/+60 µm/m
    python bench/joint_test_runs.py --pitch 2,20 --runs 3    # a 2 µm, 20 mm pitch error too
    python bench/joint_test_runs.py --plot leads.png
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.runs import run_json
from station.commands.options import RunOptions, SimOptions

AXES = ("x", "y", "z")


def one_run(seed: int, args: argparse.Namespace, out: Path) -> dict[str, Any]:
    def hook(station: Any) -> None:  # what a user writes in the config's [joints]
        describe = station.config
        station.config = lambda: {**describe(), "joints": {"station_repeats": args.repeats}}

    sim = SimOptions(seed=seed, noise=0.001, true_drho=(0.6, -0.4, 0.9), joint_lead=args.lead,
                     joint_pitch=args.pitch, backlash=args.backlash, joint_test=True,
                     procedure={"cycles": 2, "readings": args.readings, "verify": False,
                                "max_iterations": 1},
                     report={"figures": False}, station_hook=hook)
    code, result = run_json(RunOptions(sim=sim, out=out, yes=True, json=True))
    result["exit_code"] = code
    return result


def own_reversal_um(result: dict[str, Any], axis: str) -> float:
    """The mean forward − reverse of the test's own table (the journal's record: the
    result's table carries the run's measured B instead)."""
    journal = Path(result["run_dir"]) / "journal.jsonl"
    for line in journal.read_text(encoding="utf-8").splitlines():
        rec = json.loads(line)
        if rec.get("type") == "joint-test" and rec["joint"] == axis:
            return float(np.mean(np.subtract(rec["forward_um"], rec["reverse_um"])[1:]))
    raise ValueError(f"no joint-test record of joint {axis}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--seed", type=int, default=1, help="the first seed")
    p.add_argument("--lead", default="100,-80,60", help="µm/m, x,y,z")
    p.add_argument("--pitch", default=None, help="AMPLITUDE_UM,PERIOD_MM")
    p.add_argument("--backlash", default="0.006,0,0.004", help="mm, x,y,z")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--readings", type=int, default=5)
    p.add_argument("--plot", type=Path, default=None, help="draw the leads found (PNG)")
    args = p.parse_args()
    os.environ.setdefault("ORTHOCAL_SIM_TIME_SCALE", "20")  # read as each station starts
    truth = [float(v) for v in args.lead.split(",")]
    backlash = [1e3 * float(v) for v in args.backlash.split(",")]
    print(f"leads {truth} µm/m, backlash {backlash} µm, pitch {args.pitch or 'none'}, "
          f"{args.repeats} approaches a side × {args.readings} readings, 8 targets of "
          "gauge blocks")
    print(f"{'seed':>4} {'joint':>5} {'found':>8} {'95 % interval':>18} {'error':>7} "
          f"{'holds':>5} {'reversal':>9} {'drift':>6}  (µm/m, µm)")
    found: dict[str, list[tuple[float, float, float]]] = {a: [] for a in AXES}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seed, args.seed + args.runs):
            result = one_run(seed, args, Path(tmp))
            for axis, k, b in zip(AXES, truth, backlash, strict=True):
                j = result["joints"][axis]
                lo, hi = j["lead_interval_95_um_per_m"]
                value = j["lead_um_per_m"]
                found[axis].append((value, lo, hi))
                print(f"{seed:4d} {axis:>5} {value:8.2f} [{lo:7.2f}, {hi:7.2f}] "
                      f"{value - k:+7.2f} {'yes' if lo <= k <= hi else 'NO':>5} "
                      f"{own_reversal_um(result, axis):+9.2f} "
                      f"{j['station_test']['drift_um']:+6.2f}   (B {b:.1f})")
    print("per joint: RMS and largest error of the lead found, intervals holding the truth")
    for axis, k in zip(AXES, truth, strict=True):
        e = np.array([v for v, _, _ in found[axis]]) - k
        held = sum(lo <= k <= hi for _, lo, hi in found[axis])
        print(f"  {axis}: {np.sqrt(np.mean(e**2)):.2f} µm/m RMS, {np.max(np.abs(e)):.2f} "
              f"largest; {held}/{len(e)} intervals hold {k:g}")
    if args.plot is not None:
        draw(found, truth, args.plot)
        print(f"figure: {args.plot}")
    return 0


def draw(found: dict[str, list[tuple[float, float, float]]], truth: list[float],
         path: Path) -> None:
    """The leads found against the true ones (left) and each run's error with its 95 %
    interval (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.5))
    span = [min(truth) - 30, max(truth) + 30]
    left.plot(span, span, color="#999999", lw=1, label="found = true")
    for n, (axis, k) in enumerate(zip(AXES, truth, strict=True)):
        runs = found[axis]
        values = np.array([v for v, _, _ in runs])
        err = np.array([[v - lo, hi - v] for v, lo, hi in runs]).T
        left.plot([k] * len(runs), values, "o", ms=4, color=f"C{n}", label=f"joint {axis}")
        seeds = np.arange(len(runs)) + 0.2 * (n - 1)
        right.errorbar(seeds, values - k, yerr=err, fmt="o", ms=4, capsize=2, color=f"C{n}",
                       label=f"joint {axis}")
    left.set_xlabel("true lead (µm/m)")
    left.set_ylabel("lead found (µm/m)")
    left.legend(loc="upper left")
    right.axhline(0.0, color="#999999", lw=1)
    for bound in (-10.0, 10.0):
        right.axhline(bound, color="#c0392b", lw=1, ls="--")
    right.set_xlabel("run (seed from the first)")
    right.set_ylabel("found − true (µm/m), with the 95 % interval")
    fig.suptitle("The station's own joint test: leads found against the truth")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
