"""What ``orthocal compensate`` costs: the time to rewrite a program of 10 000 lines
(station.gcode.sample: four in five a G1 of 5 mm, the fifth a quarter arc of radius
2 to 10 mm) for the held-out machine of the geometry-in-the-controller work (Δρ left
of a few µm, tilts (0.2, 0.1, −0.15) mrad, gaps (0.15, −0.10, 0.12) mm), at the
default tolerance of 1 µm, and the segments it writes.

    python bench/compensate_cost.py [--lines 10000] [--tolerance 0.001] [--repeat 3]

Prints the best of the repeats (seconds per 10 000 lines) and the segments per kind
of line.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from orthocal import Geometry
from station.gcode.rewrite import Job, compensate
from station.gcode.sample import sample_program
from station.gcode.subdivide import CompensatedMachine, JointLimits

MACHINE = np.array([0.002, -0.001, 0.0015, 0.0, 0.0, 0.0, 0.2, 0.1, -0.15,
                    0.15, -0.10, 0.12])
#: The paper's machine's soft limits with 10 mm spare (joint ρ, mm).
LIMITS = JointLimits(np.full(3, 200.25), np.full(3, 380.25), "bench")


def job(tolerance: float) -> Job:
    return Job(CompensatedMachine(Geometry(), MACHINE), LIMITS, tolerance, np.zeros(3),
               "bench: the held-out machine")


def run(lines: int, tolerance: float, repeat: int) -> tuple[float, int, int]:
    """Best time (s), motions and segments of compensating the sample program."""
    text = sample_program(lines)
    best, result = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = compensate(text, "sample.ngc", job(tolerance))
        best = min(best, time.perf_counter() - t0)
    assert result is not None
    return best, result.motions, result.segments


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=10_000)
    ap.add_argument("--tolerance", type=float, default=0.001)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    seconds, motions, segments = run(a.lines, a.tolerance, a.repeat)
    print(f"{a.lines} lines, {motions} motions -> {segments} segments at {a.tolerance:g} mm")
    print(f"{seconds:.2f} s, {seconds * 10_000 / a.lines:.2f} s per 10 000 lines")
    for label, body in (("G1 of 5 mm", "G1 X5 Y0 Z0\n"),
                        ("quarter arc r = 6 mm", "G3 X6 Y6 I0 J6\n")):
        r = compensate("G0 X0 Y0 Z0\n" + body, "one.ngc", job(a.tolerance))
        print(f"  {label}: {r.segments - 1} segments")


if __name__ == "__main__":
    main()
