"""Linearised calibration equations, system (7) of the paper (model.md).

    Δ^s_{i,j} = b·Δρ_i + a·Δρ_j − b·ΔL_i − c·ΔL_j                          (7)

with, for the posture's tilt α = asin(s/L) at its stroke s (Π^+: ρmax, Π^−: ρmin,
an intermediate stop Π_i(s): s itself; the derivation holds for any α),

    a = sin α,   b = (0.5 + sin α)·tan α,   c = (0.5 + sin α)/cos α − 0.5.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from orthocal.geometry import AXIS_INDEX, MODELS, Geometry
from orthocal.measurement import Key, check_key
from orthocal.postures import tilt


def coefficients(sign: str, geometry: Geometry) -> tuple[float, float, float]:
    """(a, b, c) of equation (7) for posture '+', '-' or a signed stroke '+30'."""
    alpha = tilt(sign, geometry)
    s, c_a, t = np.sin(alpha), np.cos(alpha), np.tan(alpha)
    mu = 0.5 + s  # fraction of leg i from its actuator joint to the indicator plane
    return float(s), float(mu * t), float(mu / c_a - 0.5)


def jacobian(keys: Sequence[Key], geometry: Geometry, model: str = "full") -> np.ndarray:
    """Rows of system (7) for ``keys``, columns the parameters of ``model``
    ('rho': Δρ; 'L': ΔL; 'full': Δρ then ΔL), shape (len(keys), p)."""
    full = np.zeros((len(keys), 6))
    coef: dict[str, tuple[float, float, float]] = {}
    for row, key in enumerate(keys):
        sign, leg, direction = check_key(key)
        if sign not in coef:
            coef[sign] = coefficients(sign, geometry)
        a, b, c = coef[sign]
        i, j = AXIS_INDEX[leg], AXIS_INDEX[direction]
        full[row, i] += b
        full[row, j] += a
        full[row, 3 + i] -= b
        full[row, 3 + j] -= c
    return full[:, list(MODELS[model])]


def linear_deviations(keys: Sequence[Key], geometry: Geometry, params) -> np.ndarray:
    """Deviations predicted by (7) for the 6-vector ``params`` (PARAM_NAMES order)."""
    return jacobian(keys, geometry, "full") @ np.asarray(params, dtype=float)


def statistical_floor(
    keys: Sequence[Key], geometry: Geometry, model: str, sigma: float
) -> np.ndarray:
    """The best standard error any unbiased estimator can reach with independent
    indicator noise σ on each deviation: σ·sqrt(diag((JᵀJ)⁻¹)) (noise gain × σ)."""
    J = jacobian(keys, geometry, model)
    return sigma * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
