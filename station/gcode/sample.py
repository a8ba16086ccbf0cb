"""A program to measure compensate's cost by (bench/compensate_cost.py): a seeded walk in
the middle of the workspace, four in five lines a G1 of 5 mm in a random direction,
the fifth a G2 or G3 quarter arc of radius 2 to 10 mm in the XY plane (I, J), now
and then a comment or a feed."""

from __future__ import annotations

import numpy as np

#: The walk stays in this box (mm, work coordinates = machine with a zero offset).
BOX = np.array([[-50.0, -50.0, -50.0], [50.0, 50.0, 10.0]])


def sample_program(lines: int = 10_000, seed: int = 0) -> str:
    """``lines`` lines of motion (plus a short preamble), reproducible by ``seed``."""
    rng = np.random.default_rng(seed)
    p = np.zeros(3)
    out = ["(sample program for orthocal compensate's bench)", "G21 G90 G17 G94",
           "G0 X0.000 Y0.000 Z0.000", "G1 F600"]
    for k in range(lines):
        if k % 5 == 4:
            p, line = _arc(rng, p)
        else:
            p, line = _line(rng, p)
        if k % 50 == 0:
            line += f" F{rng.integers(300, 1200)} (pass {k // 50})"
        out.append(line)
    out.append("M2")
    return "\n".join(out) + "\n"


def _line(rng: np.random.Generator, p: np.ndarray) -> tuple[np.ndarray, str]:
    d = rng.normal(size=3)
    q = p + 5.0 * d / np.linalg.norm(d)
    q = np.where(q < BOX[0], 2 * BOX[0] - q, np.where(q > BOX[1], 2 * BOX[1] - q, q))
    return q, "G1 X{:.3f} Y{:.3f} Z{:.3f}".format(*q)


def _arc(rng: np.random.Generator, p: np.ndarray) -> tuple[np.ndarray, str]:
    r = rng.uniform(2.0, 10.0)
    a = rng.uniform(0.0, 2 * np.pi)
    centre = p + r * np.array([np.cos(a), np.sin(a), 0.0])
    ccw = bool(rng.integers(2))
    turn = np.pi / 2 if ccw else -np.pi / 2
    b = a + np.pi + turn  # the start seen from the centre, turned a quarter
    q = centre + r * np.array([np.cos(b), np.sin(b), 0.0])
    if (q[:2] < BOX[0, :2]).any() or (q[:2] > BOX[1, :2]).any():
        return _line(rng, p)  # an arc that would leave the box: a line instead
    ij = centre - p
    return q, "{} X{:.3f} Y{:.3f} I{:.3f} J{:.3f}".format("G3" if ccw else "G2", q[0], q[1],
                                                          ij[0], ij[1])
