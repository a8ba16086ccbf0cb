"""The rehearsal, round by round: does each round's Δρ̂ lie within its noise of the
hidden machine, and does the loop end where the machine is?

Whole simulated calibrations of examples/rehearsal.toml (``orthocal run --simulate
FILE --seed S`` in-process: tilts 0.05/0/−0.03 mrad, gaps 0.2/−0.1/0.15 mm, 4 µm of
lost motion, a drive moving each axis on its own, stands set by eye, 1 µm gauges), over
seeds. For every run: how the loop ended, its write-backs, the joints' error the
offsets leave against the hidden truth (µm; the drive counts whole µm), and a "converged"
that is false (the truth beyond ``converged_within_mm``). For every round after the
first, against the machine as the offsets written by then left it: the error of its own
Δρ̂ and of the rounds' joined Δρ̃ in units of their stated standard errors (RMS and
mean over runs and axes: 1 and 0 for honest standard errors), and which rounds kept a
model without the tilts the machine has, or were stated between tilts and bows.

    python bench/rehearsal_rounds.py                  # seeds 1-8, 2 at a time
    python bench/rehearsal_rounds.py --runs 4 --seed 7
    python bench/rehearsal_rounds.py --before         # the figures of the code before

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

DRHO = [f"drho_{a}" for a in AXES]
REHEARSAL = ROOT / "examples" / "rehearsal.toml"

#: The code before (2026-12-07, main at 7b5751e), the same command: per run (seed,
#: ending, write-backs, the joints' largest error left µm); per round after the first,
#: RMS of own error / stated se and of joined error / stated se; rounds whose model
#: lacked the tilts; rounds stated between tilts and bows.
BEFORE = {
    "runs": [(1, "converged", 2, 1.0), (2, "converged", 2, 4.0), (3, "not-converged", 3, 1.0),
             (4, "not-converged", 2, 2.0), (5, "converged", 2, 3.0), (6, "max_iterations", 3, 1.0),
             (7, "max_iterations", 3, 1.0), (8, "converged", 2, 2.0)],
    "own_rms": 1.60, "joined_rms": 1.83, "without_tilts": 5, "between": 6,
}


def one_run(seed: int, scale: str) -> dict[str, Any]:
    """``orthocal run --simulate examples/rehearsal.toml --seed SEED`` in this process,
    its output kept off the terminal: the result document."""
    return cli_json(["run", "--simulate", str(REHEARSAL), "--seed", str(seed)], scale)


def rounds_of(result: dict[str, Any]) -> tuple[list[dict[str, Any]], np.ndarray]:
    """Per round after the first: its model, whether it was stated between tilts and
    bows, and the errors of its own and joined Δρ̂ over their standard errors; and the
    truth the run leaves (mm)."""
    sim = result["simulation"]
    truth0 = np.array([sim["true_drho"][a] for a in AXES])
    o0 = np.array([result["offsets_before"][a] for a in AXES])
    offsets = o0.copy()
    out = []
    for n, it in enumerate(result.get("iterations") or []):
        truth = truth0 + offsets  # Δρ as the offsets written by then leave it
        own = np.array([it["identified"][d] for d in DRHO])
        se = np.array([it["std_errors"][d] for d in DRHO], dtype=float)
        joined = it.get("joined") or {"drho_mm": it["identified"], "std_errors_mm":
                                      it["std_errors"]}
        value = np.array([joined["drho_mm"][d] for d in DRHO])
        jse = np.array([joined["std_errors_mm"][d] for d in DRHO], dtype=float)
        if n:
            out.append({"model": it["model"], "between": it.get("ambiguity") is not None,
                        "own": (own - truth) / se, "joined": (value - truth) / jse})
        if it.get("offsets_written"):
            offsets = np.array([it["offsets_written"][a] for a in AXES])
    return out, truth0 + offsets


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=8)
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
    rounds: list[dict[str, Any]] = []
    false_converged = 0
    for seed, result in zip(seeds, results, strict=True):
        rs, left = rounds_of(result)
        rounds += rs
        loop = result["loop"]
        worst = 1000 * float(np.max(np.abs(left)))
        wrong = bool(result.get("converged")) and worst > 1000 * loop["converged_within_mm"] + 1e-6
        false_converged += wrong
        print(f"  seed {seed}: {loop['stopped']}, {loop['write_backs']} write-back(s), "
              f"joints left within {worst:.0f} µm of zero"
              f"{' (said converged: FALSE)' if wrong else ''}; rounds "
              + ", ".join(f"{r['model']}{' (tilts or bows)' if r['between'] else ''}"
                          for r in rs))
    own = np.array([r["own"] for r in rounds])
    joined = np.array([r["joined"] for r in rounds])
    print(f"rounds after the first: {len(rounds)}; error / stated standard error, RMS "
          f"(mean) over rounds and axes: own {np.sqrt(np.mean(own**2)):.2f} "
          f"({np.mean(own):+.2f}), joined {np.sqrt(np.mean(joined**2)):.2f} "
          f"({np.mean(joined):+.2f}); without the tilts "
          f"{sum('tilt' not in r['model'] for r in rounds)}, between tilts and bows "
          f"{sum(r['between'] for r in rounds)}; a false \"converged\": {false_converged}")


if __name__ == "__main__":
    main()
