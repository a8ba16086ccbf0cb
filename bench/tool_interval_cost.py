"""What the tool's figures cost: one figure with its 95 % intervals (orthocal.
tool_interval.after_interval, orthocal.compensation.compensated_interval: Monte Carlo,
orthocal.field_mc) with the default draws on the station's 7³ grid, as the station
computes them at the end of every run.

CPU seconds per figure (process time: what a small PC of one free core would take),
and wall seconds beside it (the machine's load adds to those), best and median of
``--repeat``, for a large field (the tilted and gapped machine, offsets alone), a field
near zero (a square machine left at ~1 µm), the geometry in the controller (told
everything), and it with the layout not told (its noise in the plug-in).

    python bench/tool_interval_cost.py
    python bench/tool_interval_cost.py --repeat 20 --draws 2000
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

# One BLAS thread, as the station's matrices want (tests/conftest.py says why): set
# before numpy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from orthocal import Geometry
from orthocal.accuracy import workspace_grid
from orthocal.compensation import compensated_interval
from orthocal.tool_interval import after_interval

G = Geometry()
SE = np.array([1e-3] * 3 + [0.0] * 3 + [0.01] * 3 + [0.002] * 3)
COV = np.diag(SE**2)
TILTED = np.array([0.001, -0.001, 0.0005, 0, 0, 0, 0.2, 0.1, -0.15, 0.15, -0.10, 0.12])
SQUARE = np.array([0.001, -0.001, 0.0005, 0, 0, 0, 0.005, -0.01, 0.003, 0.001, -0.002, 0.0])
ABSENT = [False] * 6 + [True] * 6


def cases(grid: np.ndarray, draws: int) -> dict:
    told = SQUARE.copy()
    told[6:] = 0.0
    return {
        "after, tilted and gapped (~34 µm)":
            lambda: after_interval(TILTED, COV, 10, None, grid, G, draws=draws),
        "after, square (~1 µm, near zero)":
            lambda: after_interval(SQUARE, COV, 10, None, grid, G, draws=draws),
        "in the controller, told everything":
            lambda: compensated_interval(TILTED, TILTED, COV, 10, grid, G, draws=draws),
        "in the controller, the layout not told":
            lambda: compensated_interval(told, SQUARE, COV, 10, grid, G, draws=draws,
                                         absent=ABSENT),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--draws", type=int, default=4000)
    args = ap.parse_args()
    grid = workspace_grid(None, 7, G).points
    print(f"{len(grid)} points (7³), {args.draws} draws per figure; seconds per figure, "
          f"best / median of {args.repeat}")
    for name, call in cases(grid, args.draws).items():
        call()  # imports and caches once
        cpu, wall = [], []
        for _ in range(args.repeat):
            c, w = time.process_time(), time.perf_counter()
            call()
            cpu.append(time.process_time() - c)
            wall.append(time.perf_counter() - w)
        print(f"  {name:40s} CPU {min(cpu):.3f} / {np.median(cpu):.3f}   "
              f"wall {min(wall):.3f} / {np.median(wall):.3f}")


if __name__ == "__main__":
    main()
