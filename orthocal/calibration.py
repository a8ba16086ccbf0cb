"""Linearised calibration equations, system (7) of the paper (docs/model.md).

    Δ^s_{i,j} = b·Δρ_i + a·Δρ_j − b·ΔL_i − c·ΔL_j                          (7)

with, for the posture's tilt α = asin(s/L) at its stroke s (Π^+: ρmax, Π^−: ρmin,
an intermediate stop Π_i(s): s itself; the derivation holds for any α),

    a = sin α,   b = (0.5 + sin α)·tan α,   c = (0.5 + sin α)/cos α − 0.5.

Extended model (tilted actuator axes, docs/model.md), one more term per row:

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

Axes that do not meet (docs/model.md, "Axes that do not meet"): the carriage of axis i
sits at c_i + q_i·u_i, c_i the point of its line nearest the origin. One more
pair of terms per row:

    Δ^s_{i,j} = (7') − a·c_{i,j} − b·c_{j,i}                                   (7'')

with a, b of (7) and c_{i,j} = (c_i)_j: c_{x,y} = g_xz/2, c_{x,z} = g_xy/2,
c_{y,x} = g_yz/2, c_{y,z} = −g_xy/2, c_{z,x} = −g_yz/2, c_{z,y} = −g_xz/2.
Derivation: at Π_i^s leg i's carriage moves by c_i, so the reading gains
(1 − μ)·c_{i,j} from the joint end; leg j's sphere equation, (s·e_i − L·cos α·e_j)
·(δP − c_j) = 0, moves P along j by −tan α·c_{j,i}, which the plane sees as μ
times that; at Π0 the reading gains c_{i,j}/2 and P does not move (c_i has no
i-component). The difference is (1/2 − μ)·c_{i,j} − μ·tan α·c_{j,i}, i.e. −a·c_{i,j}
− b·c_{j,i}: a gap acts on a deviation as Δρ does, through the same a and b.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from orthocal.geometry import (
    AXIS_INDEX,
    FIT_NAMES,
    MODELS,
    MRAD,
    TILT_PAIRS,
    Geometry,
    fit_params,
)
from orthocal.measurement import Key, check_key
from orthocal.postures import split_plane, tilt


def coefficients(sign: str, geometry: Geometry) -> tuple[float, float, float]:
    """(a, b, c) of equation (7) for posture '+', '-' or a signed stroke '+30'.
    A second gauge plane (``'+@0.25'``, at the fraction f of the leg from its
    joint at Π0; f = 1/2 in the paper) cuts the leg at μ = f + sin α, and
    b = μ·tan α, c = μ/cos α − f."""
    f = split_plane(sign)[1]
    alpha = tilt(sign, geometry)
    s, c_a, t = np.sin(alpha), np.cos(alpha), np.tan(alpha)
    mu = f + s  # fraction of leg i from its actuator joint to the indicator plane
    return float(s), float(mu * t), float(mu / c_a - f)


def tilt_coefficient(sign: str, geometry: Geometry) -> float:
    """d of equation (7'): mm of deviation per mrad of the angle between the axes
    of leg i and direction j, d = −L·sin α·(f + sin α)·1e-3 (f = 1/2: the middle)."""
    a = np.sin(tilt(sign, geometry))
    return float(-geometry.leg_length * a * (split_plane(sign)[1] + a) * MRAD)


def form_coefficient(sign: str, geometry: Geometry) -> float:
    """e: mm of deviation per mm of sagitta of the leg's bow in the gauge's plane,
    e = w(μ) − w(f) with w(t) = 4·t·(1 − t), μ = f + sin α (the nominal contact
    fractions at Π_i^s and Π0: orthocal.budget.form_vector exactly). At the middle
    e = −4·sin²α."""
    f = split_plane(sign)[1]
    mu = f + np.sin(tilt(sign, geometry))
    return float(4.0 * (mu * (1.0 - mu) - f * (1.0 - f)))


# c_{i,j} = (c_i)_j of (7'') as ±gap/2: (i, j) → (the gap's column in PARAM_NAMES, ±1).
GAP_OF_ORIGIN: dict[tuple[str, str], tuple[int, float]] = {
    ("x", "y"): (10, 1.0), ("x", "z"): (9, 1.0), ("y", "x"): (11, 1.0),
    ("y", "z"): (9, -1.0), ("z", "x"): (11, -1.0), ("z", "y"): (10, -1.0),
}  # fmt: skip


def jacobian(keys: Sequence[Key], geometry: Geometry, model: str = "full") -> np.ndarray:
    """Rows of system (7) (and (7') for tilts, (7'') for gaps) for ``keys``, columns
    the parameters of ``model`` in PARAM_NAMES order ('rho': Δρ; 'L': ΔL; 'full':
    Δρ then ΔL; '…+tilt': then the tilts, per mrad; '…+gap': then the gaps, per
    mm; '…+form': then the legs' bows, per mm of sagitta), shape (len(keys), p).
    Each key is linearised in its own gauge plane (:func:`coefficients`)."""
    full = np.zeros((len(keys), len(FIT_NAMES)))
    coef: dict[str, tuple[float, float, float, float, float]] = {}
    for row, key in enumerate(keys):
        sign, leg, direction = check_key(key)
        if sign not in coef:
            coef[sign] = (*coefficients(sign, geometry), tilt_coefficient(sign, geometry),
                          form_coefficient(sign, geometry))
        a, b, c, d, e = coef[sign]
        i, j = AXIS_INDEX[leg], AXIS_INDEX[direction]
        full[row, i] += b
        full[row, j] += a
        full[row, 3 + i] -= b
        full[row, 3 + j] -= c
        full[row, TILT_PAIRS[frozenset((leg, direction))]] += d
        col_ij, sign_ij = GAP_OF_ORIGIN[(leg, direction)]
        col_ji, sign_ji = GAP_OF_ORIGIN[(direction, leg)]
        full[row, col_ij] -= a * sign_ij / 2.0
        full[row, col_ji] -= b * sign_ji / 2.0
        full[row, FIT_NAMES.index(f"bow_{leg}{direction}")] = e
    return full[:, list(MODELS[model])]


def linear_deviations(keys: Sequence[Key], geometry: Geometry, params) -> np.ndarray:
    """Deviations predicted by (7'') for ``params`` (12-vector in PARAM_NAMES order,
    a 9-vector without gaps or a 6-vector without tilts either, or an 18-vector of
    FIT_NAMES with the legs' bows). Summed by parts, Δρ and ΔL first, so that models
    without tilts, gaps or bows keep the numbers of (7) to the bit."""
    J, v = jacobian(keys, geometry, "full+tilt+gap+form"), fit_params(params)
    return J[:, :6] @ v[:6] + J[:, 6:12] @ v[6:12] + J[:, 12:] @ v[12:]


def statistical_floor(
    keys: Sequence[Key], geometry: Geometry, model: str, sigma: float
) -> np.ndarray:
    """The best standard error any unbiased estimator can reach with independent
    indicator noise σ on each deviation: σ·sqrt(diag((JᵀJ)⁻¹)) (noise gain × σ)."""
    J = jacobian(keys, geometry, model)
    return sigma * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
