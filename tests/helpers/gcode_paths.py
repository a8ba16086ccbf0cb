"""Programmed paths and the points a compensated program sends, stated independently
of station.gcode (imported by the compensate tests): a program's motions as lines and
arcs (the start turned about the plane's normal, Rodrigues' formula, rising along it
for a helix), the points an output file sends a controller read back by a parser of
their own, and the distance of a tool's points from a programmed path."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

Z_AXIS, Y_AXIS, X_AXIS = np.eye(3)[2], np.eye(3)[1], np.eye(3)[0]
INCH = 25.4  # mm


@dataclass(frozen=True)
class Line:
    a: tuple[float, float, float]
    b: tuple[float, float, float]

    def dense(self, step_mm: float | None = None) -> np.ndarray:
        """Its two ends (the polyline that is the line), or a point every ``step_mm``."""
        a, b = np.array(self.a, dtype=float), np.array(self.b, dtype=float)
        if step_mm is None:
            return np.array([a, b])
        n = max(2, int(np.linalg.norm(b - a) / step_mm) + 1)
        return a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)


@dataclass(frozen=True)
class Arc:
    """The start turned by ``angle`` (rad, right-handed) about ``axis`` through
    ``centre``, rising ``rise`` along the axis (a helix)."""

    centre: tuple[float, float, float]
    axis: np.ndarray
    start: tuple[float, float, float]
    angle: float
    rise: float = 0.0

    def dense(self, step_mm: float | None = None) -> np.ndarray:
        """A point every ``step_mm`` along the turn, by default chords 0.1 nm off the
        arc, so that the polyline is the curve."""
        c, k = np.array(self.centre, dtype=float), self.axis
        v = np.array(self.start, dtype=float) - c
        r = float(np.linalg.norm(v - (v @ k) * k))
        step = step_mm / r if step_mm else 2.0 * math.sqrt(2.0 * 1e-7 / r)
        s = np.linspace(0.0, 1.0, int(abs(self.angle) / step) + 2)[:, None]
        phi = self.angle * s
        turned = (v * np.cos(phi) + np.cross(k, v) * np.sin(phi)
                  + k * (k @ v) * (1 - np.cos(phi)))
        return c + turned + self.rise * s * k


def distance_to(path: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Each point's distance to the polyline ``path`` (dense enough to be the curve):
    the segments beside its nearest vertex."""
    _, i = cKDTree(path).query(points)
    best = np.full(len(points), np.inf)
    for lo in (i - 1, i):
        ok = (lo >= 0) & (lo + 1 < len(path))
        a, b = path[np.clip(lo, 0, len(path) - 2)], path[np.clip(lo + 1, 1, len(path) - 1)]
        d = b - a
        t = np.clip(((points - a) * d).sum(1) / np.maximum((d * d).sum(1), 1e-300), 0, 1)
        dist = np.linalg.norm(points - (a + t[:, None] * d), axis=1)
        best = np.where(ok, np.minimum(best, dist), best)
    return best


def sent(text: str, offset=(0.0, 0.0, 0.0)) -> list[tuple[int | None, np.ndarray]]:
    """Every point a controller is sent, in machine mm (``offset``: the work origin),
    with the N of its block."""
    inches, absolute, block = False, True, None
    pos = np.zeros(3)
    out = []
    for line in text.splitlines():
        code = re.sub(r"\(.*?\)|;.*", "", line).upper()
        if m := re.match(r"\s*N(\d+)", code):
            block = int(m.group(1))
        for g in re.findall(r"G(\d+(?:\.\d+)?)", code):
            inches = {"20": True, "21": False}.get(g, inches)
            absolute = {"90": True, "91": False}.get(g, absolute)
        xyz = dict(re.findall(r"([XYZ])([-+]?\d*\.?\d+)", code))
        if not re.search(r"\bG0?[01]\b", re.sub(r"G", " G", code)) or not xyz:
            continue
        assert set(xyz) == set("XYZ"), line  # every point written whole
        v = np.array([float(xyz[a]) for a in "XYZ"]) * (INCH if inches else 1.0)
        pos = v if absolute else pos + v
        out.append((block, pos + offset))
    return out
