"""Test postures Π0, Π_i^+ and Π_i^− of the nominal machine (model.md, "Test postures")."""

from __future__ import annotations

import numpy as np

from orthocal.geometry import AXIS_INDEX, Geometry

SIGNS = ("+", "-")


def tilt(sign: str, geometry: Geometry) -> float:
    """α = asin(ρmax/L) for Π^+, asin(ρmin/L) for Π^− (negative)."""
    if sign == "+":
        return float(np.arcsin(geometry.rho_max / geometry.leg_length))
    if sign == "-":
        return float(np.arcsin(geometry.rho_min / geometry.leg_length))
    raise ValueError(f"posture sign must be '+' or '-', got {sign!r}")


def posture(sign: str, leg: str | None, geometry: Geometry) -> np.ndarray:
    """Nominal joint coordinates ρ of a test posture.

    ``posture("0", None, g)`` is Π0 = (L, L, L), P = 0. ``posture("+", "x", g)`` is
    Π_x^+: ρ_x = L + ρmax and the two other joints at L·cos α, so that P = ρmax·e_x
    and leg x stays parallel to its axis.
    """
    L = geometry.leg_length
    if sign == "0":
        return np.full(3, L)
    if leg not in AXIS_INDEX:
        raise ValueError(f"leg must be one of x, y, z, got {leg!r}")
    stroke = geometry.rho_max if sign == "+" else geometry.rho_min
    rho = np.full(3, L * np.cos(tilt(sign, geometry)))
    rho[AXIS_INDEX[leg]] = L + stroke
    return rho


def posture_point(sign: str, leg: str | None, geometry: Geometry) -> np.ndarray:
    """Nominal end point P of a test posture: 0 at Π0, ρmax·e_i or ρmin·e_i at Π_i^±."""
    p = np.zeros(3)
    if sign != "0":
        p[AXIS_INDEX[leg]] = geometry.rho_max if sign == "+" else geometry.rho_min
    return p
