"""Test postures of the nominal machine (docs/model.md, "Test postures").

A posture is named by a string: ``"0"`` is Π0; ``"+"`` / ``"-"`` are Π_i^± at
the geometry's ρmax / ρmin (the paper's postures); a signed stroke such as
``"+30"`` or ``"-50.5"`` (mm) is an intermediate stop Π_i(s) with P = s·e_i.
Every test posture is the same construction at its stroke s: leg i's joint at
L + s, the two other joints at L·cos α with α = asin(s/L), so that leg i stays
parallel to its axis and P = s·e_i.

A second gauge plane (docs/model.md, "Leg form against tilts and gaps"): a
posture name may end in ``"@f"`` (``"+@0.25"``, ``"-50@0.75"``): the same
posture, its deviations read by gauges whose plane cuts the leg at the fraction
f of its length from the carriage's joint at Π0 (the plane x_i = L·(1 − f),
L/2 + L·(1/2 − f)), not at the middle. Without the suffix: f = 1/2.
"""

from __future__ import annotations

import re

import numpy as np

from orthocal.geometry import AXIS_INDEX, Geometry

SIGNS = ("+", "-")
_STROKE = re.compile(r"^[+-](\d+(\.\d*)?|\.\d+)$")
_PLANE = re.compile(r"^0?\.\d+$")
#: The gauges' plane without a suffix: the middle of the leg.
MIDDLE = 0.5


def split_plane(name: str) -> tuple[str, float]:
    """(the posture, the fraction f of the leg its gauges' plane cuts at Π0) of a
    posture name: ``"+@0.25"`` → ``("+", 0.25)``, ``"+"`` → ``("+", 0.5)``; raises
    ValueError for a suffix that is not a fraction strictly between 0 and 1."""
    if not isinstance(name, str) or "@" not in name:
        return name, MIDDLE
    base, _, frac = name.partition("@")
    if not _PLANE.match(frac) or not 0.0 < float(frac) < 1.0 or float(frac) == MIDDLE:
        raise ValueError(f"a gauge plane is '@' and a fraction of the leg strictly between "
                         f"0 and 1 other than 0.5 (such as '+@0.25'), got {name!r}")
    return base, float(frac)


def with_plane(name: str, fraction: float) -> str:
    """The posture name ``name`` read in the gauge plane at ``fraction`` of the leg
    (no suffix at the middle)."""
    return name if fraction == MIDDLE else check_posture(f"{name}@{fraction:g}")


def plane_at(fraction: float, geometry: Geometry) -> float:
    """How far (mm) a gauges' plane at ``fraction`` of the leg (from the carriage's
    joint at Π0) lies off L/2, the middle: L·(1/2 − f); 0 at the middle."""
    return geometry.leg_length * (MIDDLE - fraction)


def plane_offset(name: str, geometry: Geometry) -> float:
    """How far (mm) the gauges' plane of posture ``name`` lies off L/2:
    :func:`plane_at` its fraction (:func:`split_plane`); 0 without a suffix."""
    return plane_at(split_plane(name)[1], geometry)


def check_posture(name: str) -> str:
    """Validate a test-posture name ('+', '-' or a signed nonzero stroke such as
    '+30', each optionally read in a second gauge plane, '+@0.25'); raises
    ValueError."""
    base, _ = split_plane(name)
    if base in SIGNS:
        return name
    if isinstance(base, str) and _STROKE.match(base) and float(base) != 0.0:
        return name
    raise ValueError(
        f"posture must be '+', '-' or a signed nonzero stroke in mm such as '+30', got {name!r}")


def stroke(name: str, geometry: Geometry) -> float:
    """The stroke s of a test posture: ρmax for '+', ρmin for '-', the number itself
    for a signed stroke string."""
    name = split_plane(check_posture(name))[0]
    if name == "+":
        return geometry.rho_max
    if name == "-":
        return geometry.rho_min
    s = float(name)
    if not -geometry.leg_length < s < geometry.leg_length:
        raise ValueError(f"stroke {name} mm must lie within ±leg_length ({geometry.leg_length:g})")
    return s


def posture_name(s: float, geometry: Geometry) -> str:
    """The canonical name of the stop at stroke ``s``: '+' / '-' at the geometry's
    ρmax / ρmin (so that the paper's postures keep their keys), else '%+g'."""
    if s == geometry.rho_max:
        return "+"
    if s == geometry.rho_min:
        return "-"
    name = f"{s:+g}"
    if float(name) != s:  # %g rounds to 6 significant digits; keep the exact value
        name = f"{s:+.17g}"
    return check_posture(name)


def stop_order(strokes) -> list[float]:
    """The order a cycle visits its stops, starting and ending at Π0 (s = 0):
    positive strokes ascending, then negative ones descending. Each joint then
    passes each point of its range at most twice, the least any order can do
    (the far ends must be reached and left), i.e. 2·(max − min) of travel for
    leg i's joint, and the paper's Π+ → Π− order is the two-stroke case."""
    strokes = [float(s) for s in strokes]
    return sorted(s for s in strokes if s > 0) + sorted((s for s in strokes if s < 0),
                                                          reverse=True)


def tilt(sign: str, geometry: Geometry) -> float:
    """α = asin(s/L) of a test posture (Π^+: asin(ρmax/L); Π^−: negative)."""
    return float(np.arcsin(stroke(sign, geometry) / geometry.leg_length))


def posture(sign: str, leg: str | None, geometry: Geometry) -> np.ndarray:
    """Nominal joint coordinates ρ of a test posture.

    ``posture("0", None, g)`` is Π0 = (L, L, L), P = 0. ``posture("+", "x", g)`` is
    Π_x^+: ρ_x = L + ρmax and the two other joints at L·cos α, so that P = ρmax·e_x
    and leg x stays parallel to its axis; ``posture("+30", "x", g)`` likewise at
    s = 30 mm.
    """
    L = geometry.leg_length
    if sign == "0":
        return np.full(3, L)
    sign = split_plane(sign)[0]
    if leg not in AXIS_INDEX:
        raise ValueError(f"leg must be one of x, y, z, got {leg!r}")
    rho = np.full(3, L * np.cos(tilt(sign, geometry)))
    rho[AXIS_INDEX[leg]] = L + stroke(sign, geometry)
    return rho


def posture_point(sign: str, leg: str | None, geometry: Geometry) -> np.ndarray:
    """Nominal end point P of a test posture: 0 at Π0, s·e_i at Π_i(s)."""
    p = np.zeros(3)
    if sign != "0":
        if leg not in AXIS_INDEX:
            raise ValueError(f"leg must be one of x, y, z, got {leg!r}")
        p[AXIS_INDEX[leg]] = stroke(sign, geometry)
    return p
