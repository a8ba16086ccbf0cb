"""The programmed path of each motion as a curve C(t), t from 0 to 1: a line, or an
arc, full circle, helix (G2/G3) linearised later, all in one form so that the
points of every motion of a program are evaluated at once:

    C(t) = centre + r(t)·(cos(θt)·e1 + sin(θt)·e2) + t·lin,   r(t) = r0 + (r1 − r0)·t

A line has r0 = r1 = 0 (centre its start, lin its length); an arc has e1 toward its
start from the centre (in the plane), e2 = normal × e1, θ signed (positive
counterclockwise about the plane's normal, G3) and lin its helix's rise along the
normal. t is proportional to the angle, and to the rise and the length, so a
helix's t goes at constant speed. Where the radius to the end differs from the
radius to the start within LinuxCNC's tolerance, the radius changes linearly with
the angle (LinuxCNC's spiral); beyond it the arc is refused, as LinuxCNC does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from station.gcode.codes import named
from station.gcode.modal import CCW, PLANES, ProgramMove
from station.gcode.words import GcodeError

# LinuxCNC's arc tolerances (interp_internal.hh), in mm here, by the program's units
# (G20: True): the radius too small to reach, and how far the radius to the end may
# differ from the radius to the start (absolute, and relative).
_RADIUS_TOL = 0.00005 * 25.4
_SPIRAL_TOL = {False: 2 * 0.01 * math.sqrt(2), True: 2 * 0.001 * math.sqrt(2) * 25.4}
_SPIRAL_REL = 0.001
# Start and end closer than this (mm) in the plane: one point, a full circle per turn.
_SAME_POINT = 1e-9


@dataclass(frozen=True)
class Curves:
    """Every motion's curve, one row each (see the module's formula)."""

    centre: np.ndarray  # (n, 3)
    e1: np.ndarray  # (n, 3)
    e2: np.ndarray  # (n, 3)
    r0: np.ndarray  # (n,)
    r1: np.ndarray  # (n,)
    theta: np.ndarray  # (n,) rad
    lin: np.ndarray  # (n, 3)
    start: np.ndarray  # (n, 3)
    end: np.ndarray  # (n, 3)

    def __len__(self) -> int:
        return len(self.theta)

    def at(self, ci: np.ndarray, t: np.ndarray) -> np.ndarray:
        """C(t) of curves ``ci`` (m,) at ``t`` (m, k): (m, k, 3). t = 0 and 1 give the
        start and end exactly, as the neighbouring motions' ends."""
        th = self.theta[ci][:, None] * t
        r = self.r0[ci][:, None] + (self.r1 - self.r0)[ci][:, None] * t
        p = (self.centre[ci][:, None, :]
             + r[..., None] * (np.cos(th)[..., None] * self.e1[ci][:, None, :]
                               + np.sin(th)[..., None] * self.e2[ci][:, None, :])
             + t[..., None] * self.lin[ci][:, None, :])
        p = np.where((t == 0.0)[..., None], self.start[ci][:, None, :], p)
        return np.where((t == 1.0)[..., None], self.end[ci][:, None, :], p)


def curves_of(moves: list[ProgramMove]) -> Curves:
    """The curves of ``moves``; the first motion (no start) is the point it goes to.
    GcodeError for an arc LinuxCNC would refuse."""
    rows = [_line(m) if not m.arc else _arc(m) for m in moves]
    if not rows:
        z = np.zeros((0, 3))
        return Curves(z, z, z, np.zeros(0), np.zeros(0), np.zeros(0), z, z, z)
    cols = list(zip(*rows, strict=True))
    return Curves(*(np.array(c, dtype=float) for c in cols))


def _line(m: ProgramMove) -> tuple:
    start = m.end if m.start is None else m.start
    zero = np.zeros(3)
    return start, zero, zero, 0.0, 0.0, 0.0, m.end - start, start, m.end


def _arc(m: ProgramMove) -> tuple:
    assert m.start is not None
    first, second, normal = PLANES[m.plane]
    centre = _centre(m) if m.radius is not None else m.centre
    assert centre is not None
    u0 = (m.start - centre)[[first, second]]
    u1 = (m.end - centre)[[first, second]]
    r0, r1 = float(np.hypot(*u0)), float(np.hypot(*u1))
    _check_radii(m, r0, r1)
    e1 = np.zeros(3)
    e1[[first, second]] = u0 / r0
    e2 = np.zeros(3)
    e2[[first, second]] = (-e1[second], e1[first])  # normal × e1
    ccw = m.code == CCW
    cross = u0[0] * u1[1] - u0[1] * u1[0]
    dot = float(u0 @ u1)
    angle = math.atan2(cross if ccw else -cross, dot)  # the way the arc turns
    if angle <= 0.0 or (np.hypot(*(u1 - u0)) < _SAME_POINT and m.radius is None):
        angle += 2.0 * math.pi  # a full turn where start and end are one point
    angle += 2.0 * math.pi * (m.turns - 1)
    theta = angle if ccw else -angle
    c3 = m.start.copy()
    c3[[first, second]] = centre[[first, second]]
    lin = np.zeros(3)
    lin[normal] = m.end[normal] - m.start[normal]
    return c3, e1, e2, r0, r1, theta, lin, m.start, m.end


def _centre(m: ProgramMove) -> np.ndarray:
    """The centre of an R-format arc (LinuxCNC's arc_data_r): on the chord's
    perpendicular, left of the chord for G3 with R > 0 or G2 with R < 0."""
    assert m.start is not None and m.radius is not None
    first, second, _ = PLANES[m.plane]
    a, b = m.start[[first, second]], m.end[[first, second]]
    if np.array_equal(a, b):
        raise GcodeError(m.lineno, m.label, "an R arc whose end is its start has no "
                         "centre: give a full circle by I, J, K")
    radius = abs(m.radius)
    half = float(np.hypot(*(b - a))) / 2.0
    if half - radius > _RADIUS_TOL:
        raise GcodeError(m.lineno, m.label, f"radius {radius / _unit(m):g} is too small "
                         "to reach the arc's end")
    half = min(half, radius)
    chord = (b - a) / (2.0 * half) if half > 0 else np.array([1.0, 0.0])
    left = np.array([-chord[1], chord[0]])
    side = 1.0 if (m.code == CCW) == (m.radius > 0) else -1.0
    mid = (a + b) / 2.0
    centre = m.start.copy()
    centre[[first, second]] = mid + side * math.sqrt(max(radius**2 - half**2, 0.0)) * left
    return centre


def _check_radii(m: ProgramMove, r0: float, r1: float) -> None:
    if r0 < _RADIUS_TOL or r1 < _RADIUS_TOL:
        raise GcodeError(m.lineno, m.label, "an arc of zero radius")
    err = abs(r0 - r1)
    if err > _SPIRAL_TOL[m.inches] or err / max(r0, r1) > _SPIRAL_REL:
        u = _unit(m)
        raise GcodeError(m.lineno, m.label, f"the radius to the arc's end ({r1 / u:.4f}) "
                         f"differs from the radius to its start ({r0 / u:.4f}) by more than "
                         f"LinuxCNC accepts in the {named('G', m.plane)} plane")


def _unit(m: ProgramMove) -> float:
    return 25.4 if m.inches else 1.0
