"""The closed loop on bowed legs: whole simulated calibrations (``orthocal run
--simulate`` in-process) of a machine whose legs are bowed (``--leg-bow``, the same
sagitta on every gauge plane), the legs stated straight to ``--stated`` in the
config's [uncertainty], 1 µm gauges, stands by eye, three cycles of three readings,
model ``auto``. For every seed: how the loop stopped, its write-backs, the mountings
against 3 + 2 × write-backs, the offsets' error against the hidden truth (µm), the
last verification's model and its Δρ standard errors (docs/model.md, "Leg form in
the loop").

    python bench/bowed_loop.py                  # seeds 1-3, 8 µm bows, stated 10 µm
    python bench/bowed_loop.py --bow 0 --runs 2 # straight legs, same statement
    python bench/bowed_loop.py --alternate      # leg y bowed the other way: no tilt
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.runs import run_json
from orthocal import AXES
from station.commands.options import RunOptions, SimOptions

TRUE_DRHO = (0.6, -0.4, 0.9)


def one_run(seed: int, bow_mm: float, stated_mm: float, out: Path,
            alternate: bool = False) -> dict[str, Any]:
    def hook(station: Any) -> None:  # what a user writes in the config's [uncertainty]
        config = station.config
        station.config = lambda: {**config(),
                                  "uncertainty": {"leg_straightness_mm": stated_mm}}

    bows = f"{bow_mm},{-bow_mm},{bow_mm}" if alternate else f"{bow_mm}"
    sim = SimOptions(seed=seed, noise=0.001, true_drho=TRUE_DRHO, leg_bow=bows,
                     procedure={"cycles": 3, "readings": 3}, station_hook=hook)
    code, result = run_json(RunOptions(sim=sim, out=out, yes=True, json=True))
    result["exit_code"] = code
    return result


def figures(result: dict[str, Any]) -> str:
    o = np.array([result["offsets_final"][a] - result["offsets_before"][a] for a in AXES])
    left = 1000 * np.abs(np.array(TRUE_DRHO) + o)
    writes = result["loop"]["write_backs"]
    last = result["iterations"][-1]
    ses = ", ".join(f"{1000 * last['std_errors'][f'drho_{a}']:.2f}" for a in AXES)
    return (f"{result['loop']['stopped']} (exit {result['exit_code']}), {writes} write-back(s), "
            f"{result['timing']['mountings']} mountings (bound {3 + 2 * writes}), offsets "
            f"off ≤ {left.max():.1f} µm (said: ≤ {_said_um(last)}), last model "
            f"{last['model']} ({last['verdict']}), se(Δρ) {ses} µm")


def _said_um(last: dict[str, Any]) -> str:
    """What the last verification says the worst joint may still be off by."""
    shown = [v for v in (last.get("shown_within_95_mm") or {}).values() if v is not None]
    return f"{1000 * max(shown):.1f} µm" if shown else "—"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--bow", type=float, default=0.008, help="each leg's sagitta, mm")
    parser.add_argument("--stated", type=float, default=0.010,
                        help="[uncertainty] leg_straightness_mm")
    parser.add_argument("--alternate", action="store_true",
                        help="leg y bowed the other way (bows of both signs are no tilt)")
    args = parser.parse_args()
    signs = " (+, −, +)" if args.alternate else ""
    print(f"bows {1000 * args.bow:g} µm{signs}, stated {1000 * args.stated:g} µm, 1 µm gauges, "
          "3 cycles × 3 readings, stands by eye, Δρ (0.6, −0.4, 0.9) mm")
    with tempfile.TemporaryDirectory(prefix="orthocal-bowed-") as tmp:
        for k in range(args.runs):
            result = one_run(args.seed + k, args.bow, args.stated, Path(tmp), args.alternate)
            print(f"  seed {args.seed + k}: {figures(result)}")


if __name__ == "__main__":
    main()
