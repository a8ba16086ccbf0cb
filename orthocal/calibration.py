"""Linearised calibration equations, system (7) of the paper (model.md).

    Δ^s_{i,j} = b·Δρ_i + a·Δρ_j − b·ΔL_i − c·ΔL_j                          (7)

with, for the posture's tilt α = asin(s/L) at its stroke s (Π^+: ρmax, Π^−: ρmin,
an intermediate stop Π_i(s): s itself; the derivation holds for any α),

    a = sin α,   b = (0.5 + sin α)·tan α,   c = (0.5 + sin α)/cos α − 0.5.

Extended model (tilted actuator axes, model.md), one more term per row:

    Δ^s_{i,j} = (7) + d·τ_{ij},   d = −L·sin α·(0.5 + sin α)·1e-3 mm/mrad     (7')

where τ_{ij} is the tilt that changes the angle between axes i and j (τ_xy =
tilt_yx, τ_xz = tilt_zx, τ_yz = tilt_zy). Derivation: at Π_i^s the carriage of
leg i sits at (L + s)·u_i, so its j-coordinate is (L + s)·(δu_i)_j; the sphere
equation of leg j shifts P by δp_j = … − s·(δu_j)_i (s = L·sin α, the stroke);
the base-fixed plane x_i = L/2 cuts leg i at μ = 0.5 + sin α from the carriage,
so the reading changes by (1 − μ)(L + s)(δu_i)_j − μ·s·(δu_j)_i, and the Π0
reading by 0.5·L·(δu_i)_j. The difference is −L·sin α·μ·((δu_i)_j + (δu_j)_i):
only the symmetric part, the change of the angle between the two axes, shows.
A rotation of the whole machine (antisymmetric δu) shows in no deviation.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from orthocal.geometry import (
    AXIS_INDEX,
    MODELS,
    MRAD,
    PARAM_NAMES,
    TILT_PAIRS,
    Geometry,
    full_params,
)
from orthocal.measurement import Key, check_key
from orthocal.postures import tilt


def coefficients(sign: str, geometry: Geometry) -> tuple[float, float, float]:
    """(a, b, c) of equation (7) for posture '+', '-' or a signed stroke '+30'."""
    alpha = tilt(sign, geometry)
    s, c_a, t = np.sin(alpha), np.cos(alpha), np.tan(alpha)
    mu = 0.5 + s  # fraction of leg i from its actuator joint to the indicator plane
    return float(s), float(mu * t), float(mu / c_a - 0.5)


def tilt_coefficient(sign: str, geometry: Geometry) -> float:
    """d of equation (7'): mm of deviation per mrad of the angle between the axes
    of leg i and direction j, d = −L·sin α·(0.5 + sin α)·1e-3."""
    a = np.sin(tilt(sign, geometry))
    return float(-geometry.leg_length * a * (0.5 + a) * MRAD)


def jacobian(keys: Sequence[Key], geometry: Geometry, model: str = "full") -> np.ndarray:
    """Rows of system (7) (and (7') for tilts) for ``keys``, columns the parameters
    of ``model`` in PARAM_NAMES order ('rho': Δρ; 'L': ΔL; 'full': Δρ then ΔL;
    'rho+tilt', 'full+tilt': then the tilts, per mrad), shape (len(keys), p)."""
    full = np.zeros((len(keys), len(PARAM_NAMES)))
    coef: dict[str, tuple[float, float, float, float]] = {}
    for row, key in enumerate(keys):
        sign, leg, direction = check_key(key)
        if sign not in coef:
            coef[sign] = (*coefficients(sign, geometry), tilt_coefficient(sign, geometry))
        a, b, c, d = coef[sign]
        i, j = AXIS_INDEX[leg], AXIS_INDEX[direction]
        full[row, i] += b
        full[row, j] += a
        full[row, 3 + i] -= b
        full[row, 3 + j] -= c
        full[row, TILT_PAIRS[frozenset((leg, direction))]] += d
    return full[:, list(MODELS[model])]


def linear_deviations(keys: Sequence[Key], geometry: Geometry, params) -> np.ndarray:
    """Deviations predicted by (7') for ``params`` (9-vector in PARAM_NAMES order,
    or a 6-vector without tilts)."""
    return jacobian(keys, geometry, "full+tilt") @ full_params(params)


def statistical_floor(
    keys: Sequence[Key], geometry: Geometry, model: str, sigma: float
) -> np.ndarray:
    """The best standard error any unbiased estimator can reach with independent
    indicator noise σ on each deviation: σ·sqrt(diag((JᵀJ)⁻¹)) (noise gain × σ)."""
    J = jacobian(keys, geometry, model)
    return sigma * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
