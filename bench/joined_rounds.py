"""Rounds joined: is the joined standard error the scatter of the joined Δρ?

A verification's Δρ̂ is joined with the rounds before it (docs/model.md, "Joining the
rounds"); a round that carries an earlier round's layout or bows shares that round's
error through the carried prior's gain. Whole simulated calibrations (``orthocal run
--simulate`` in-process) over seeds, read from their result.json alone: for every
verification round k (k ≥ 1, from the second pass that carried a prior on), against
the hidden machine as the offsets written by then left it,

* the error of the round's own Δρ̂_k and of what the rounds before said of the same
  joints (their joined Δρ̃_{k−1} moved by the offsets written since), and the
  correlation of the two over the seeds (the two are not independent where the round
  carried what an earlier round measured);
* the joined Δρ̃_k's stated standard error against the RMS of its error over the
  seeds (µm), and how often |error| ≤ k·se (the 95 % interval) holds.

    python bench/joined_rounds.py                       # the second-plane machine, 8 seeds
    python bench/joined_rounds.py --machine held-out --runs 12 --jobs 3

``second-plane``: tilted (0.2, 0.1, −0.15) mrad, legs bowed 8 µm, every setup read at
0.75 of its leg too (bench/second_plane.py --setups second), objective tool.
``held-out``: gaps (0.15, −0.10, 0.12) mm and the same tilts, straight legs stated
straight to 2 µm (bench/gaps_vs_truth.py), objective joints.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from orthocal import AXES, coverage_factor

DRHO = [f"drho_{a}" for a in AXES]


def one_run(machine: str, seed: int) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="orthocal-joined-") as tmp:
        if machine == "second-plane":
            from bench import second_plane
            return second_plane.one_run(seed, 0.008, "second", Path(tmp))
        from bench import gaps_vs_truth
        return gaps_vs_truth.one_run(seed, gaps_vs_truth.CASES["held-out"], "joints", Path(tmp))


def round_errors(result: dict[str, Any]) -> list[dict[str, Any]]:
    """Per verification round: the errors (mm, per axis) of its own Δρ̂, of the rounds
    before joined and moved, and of the joined Δρ̃, with the joined stated se and dof."""
    sim = result["simulation"]
    true0 = np.array([sim["true_drho"][a] for a in AXES])
    o0 = np.array([result["offsets_before"][a] for a in AXES])
    offsets = o0.copy()
    out: list[dict[str, Any]] = []
    previous: np.ndarray | None = None
    previous_se = np.full(3, np.nan)
    for n, it in enumerate(result.get("iterations") or []):
        truth = true0 + offsets - o0  # the machine this round measured
        own = np.array([it["identified"][d] for d in DRHO])
        joined = it.get("joined") or {}
        value = np.array([joined.get("drho_mm", it["identified"])[d] for d in DRHO])
        ses = joined.get("std_errors_mm", it["std_errors"])
        se = np.array([ses[d] if ses[d] is not None else np.nan for d in DRHO])
        own_se = np.array([it["std_errors"][d] or np.nan for d in DRHO])
        if n and previous is not None:
            out.append({"round": n, "own": own - truth, "before": previous,
                        "joined": value - truth, "se": se, "dof": it.get("std_errors_dof"),
                        # the two joined as independent, by inverse variance (before (14))
                        "independent_se": 1.0 / np.sqrt(1.0 / own_se**2 + 1.0 / previous_se**2)})
        previous, previous_se = value - truth, se
        if it.get("offsets_written"):
            offsets = np.array([it["offsets_written"][a] for a in AXES])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--machine", choices=["second-plane", "held-out"],
                        default="second-plane")
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--jobs", type=int, default=2, help="runs at once (they mostly wait)")
    args = parser.parse_args()
    seeds = list(range(args.seed, args.seed + args.runs))
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        results = list(pool.map(one_run, [args.machine] * len(seeds), seeds))
    rounds: dict[int, list[dict[str, Any]]] = {}
    for seed, result in zip(seeds, results, strict=True):
        for r in round_errors(result):
            rounds.setdefault(r["round"], []).append(r)
        print(f"  seed {seed}: loop {result['loop']['stopped']}, "
              f"{len(result.get('iterations') or [])} rounds")
    print(f"machine {args.machine}, seeds {seeds[0]}–{seeds[-1]}; per verification round, "
          "over the seeds, µm:")
    for n, rs in sorted(rounds.items()):
        if len(rs) < 3:
            continue
        own = np.array([r["own"] for r in rs])
        before = np.array([r["before"] for r in rs])
        err = np.array([r["joined"] for r in rs])
        se = np.array([r["se"] for r in rs])
        corr = [float(np.corrcoef(own[:, i], before[:, i])[0, 1]) for i in range(3)]
        k = np.array([coverage_factor(r["dof"]) for r in rs])[:, None]
        held = float(np.mean(np.abs(err) <= k * se))
        print(f"  round {n} ({len(rs)} runs): correlation of its own Δρ̂'s error with the "
              f"rounds' before: {', '.join(f'{c:+.2f}' for c in corr)} (x, y, z); joined "
              f"standard error stated {1000 * np.nanmean(se):.2f} (as if independent "
              f"{1000 * np.nanmean([r['independent_se'] for r in rs]):.2f}), scatter (RMS error) "
              f"{1000 * np.sqrt(np.mean(err**2)):.2f} "
              f"({', '.join(f'{1000 * v:.2f}' for v in np.sqrt(np.mean(err**2, axis=0)))}); "
              f"95 % intervals hold the truth {100 * held:.0f} %")


if __name__ == "__main__":
    main()
