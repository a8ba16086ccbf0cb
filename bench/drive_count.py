"""The drive's count: a square machine on a drive that takes its targets in 0.01 mm.

Whole simulated calibrations with the IAI PCON map (``orthocal run --simulate
--profile iai-pcon-direct --seed S`` in-process: a square machine, Δρ of the seed,
stands set by eye, 1 µm gauges), over seeds. For every run: how the loop ended and
its write-backs, the tilts as stated (value ± U, mrad) and how many lie beyond their
U, the advice to shim a rail, each joint's error left against the hidden truth (µm;
half a count is 5 µm), the tool after calibration as stated, and what the count does
at the tool (accuracy.drive_count, model.md (J17)).

    python bench/drive_count.py                  # seeds 1-4, 2 at a time
    python bench/drive_count.py --runs 2 --seed 3
    python bench/drive_count.py --before         # the figures of the code before

The virtual station runs ``--time-scale`` times faster than real time (as the tests'
do: the readings at the stops, the counts and the journal do not depend on it).
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

# Runnable from a plain checkout, without the editable install.
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.runs import cli_json  # noqa: E402
from orthocal import AXES  # noqa: E402

TILTS = ("tilt_yx", "tilt_zx", "tilt_zy")

#: The code before (2026-12-07, main at ec0fae2, blind to the count), the same command
#: and seeds: per run (seed, ending, write-backs, tilts beyond their U, shim advice,
#: the joints' largest error left µm, the tool after stated µm RMS).
BEFORE: dict[str, Any] = {"runs": [
    [1, "converged", 2, 3, 3, 8.1, 7.6], [2, "converged", 2, 3, 3, 6.0, 7.2],
    [3, "converged", 2, 3, 3, 7.4, 8.2], [4, "converged", 2, 3, 3, 7.8, 8.5]]}


def one_run(seed: int, scale: str) -> dict[str, Any]:
    """``orthocal run --simulate --profile iai-pcon-direct --seed SEED`` in this
    process, its output kept off the terminal: the result document."""
    return cli_json(["run", "--simulate", "--profile", "iai-pcon-direct", "--seed", str(seed)],
                    scale)


def joints_left_um(result: dict[str, Any]) -> np.ndarray:
    """Each joint's Δρ as the final offsets leave it, against the hidden truth, µm."""
    sim = result["simulation"]
    truth = np.array([sim["true_drho"][a] for a in AXES])
    before = np.array([result["offsets_before"][a] for a in AXES])
    final = np.array([result["offsets_final"][a] for a in AXES])
    return 1000.0 * (truth + final - before)


def summary(seed: int, result: dict[str, Any]) -> dict[str, Any]:
    stated = {q["name"]: q for q in result["statement"]}
    beyond = [n for n in TILTS if abs(stated[n]["value"]) > stated[n]["expanded"]]
    shims = sum(a["id"].startswith("shim.") for a in result["advice"])
    left = joints_left_um(result)
    count = result["accuracy"].get("drive_count")
    return {"seed": seed, "stopped": result["loop"]["stopped"],
            "write_backs": result["loop"]["write_backs"],
            "tilts_mrad": {n: [round(stated[n]["value"], 3), round(stated[n]["expanded"], 3)]
                           for n in TILTS},
            "tilts_beyond_u": len(beyond), "shim_advice": shims,
            "joints_left_um": float(np.max(np.abs(left))),
            "tool_after_rms_um": 1000.0 * stated["tool.after.rms"]["value"],
            "count_at_tool_um": None if count is None else
            [1000.0 * count["rms_mm"], 1000.0 * count["max_mm"]]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=4)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--jobs", type=int, default=2, help="runs at once (they mostly wait)")
    parser.add_argument("--time-scale", default="20")
    parser.add_argument("--before", action="store_true", help="print the code before's figures")
    args = parser.parse_args()
    if args.before:
        print(json.dumps(BEFORE, indent=1))
        return
    seeds = list(range(args.seed, args.seed + args.runs))
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        results = list(pool.map(one_run, seeds, [args.time_scale] * len(seeds)))
    rows = [summary(s, r) for s, r in zip(seeds, results, strict=True)]
    for row in rows:
        tilts = ", ".join(f"{n} {v:+.3f} ± {u:.3f}" for n, (v, u) in row["tilts_mrad"].items())
        count = row["count_at_tool_um"]
        print(f"  seed {row['seed']}: {row['stopped']}, {row['write_backs']} write-back(s); "
              f"tilts (mrad) {tilts}: {row['tilts_beyond_u']} beyond U, "
              f"{row['shim_advice']} shim advice; joints left within "
              f"{row['joints_left_um']:.1f} µm; tool after {row['tool_after_rms_um']:.1f} µm "
              "RMS" + ("" if count is None else
                       f"; the count at the tool {count[0]:.1f} µm RMS, {count[1]:.1f} max"))
    print(json.dumps({"runs": [[r["seed"], r["stopped"], r["write_backs"], r["tilts_beyond_u"],
                                r["shim_advice"], round(r["joints_left_um"], 1),
                                round(r["tool_after_rms_um"], 1)] for r in rows]}))


if __name__ == "__main__":
    main()
