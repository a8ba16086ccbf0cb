"""Exact kinematics of model (1) for any parameter set.

Leg i is a bar of length L_i = L + ΔL_i from the actuator joint at
(ρ_i + Δρ_i)·e_i to the end point P:

    (p_i − (ρ_i + Δρ_i))² + p_j² + p_k² = L_i²                              (1)

All functions broadcast over leading dimensions: ``p`` and ``rho`` have shape
(..., 3).
"""

from __future__ import annotations

import numpy as np

from orthocal.geometry import Geometry


def _legs(geometry: Geometry, drho, dL) -> tuple[np.ndarray, np.ndarray]:
    drho = np.zeros(3) if drho is None else np.asarray(drho, dtype=float)
    L = geometry.leg_length + (np.zeros(3) if dL is None else np.asarray(dL, dtype=float))
    return drho, L


def inverse(p, geometry: Geometry, drho=None, dL=None) -> np.ndarray:
    """Joint coordinates ρ that put the end point at ``p``:
    ρ_i = p_i + sqrt(L_i² − p_j² − p_k²) − Δρ_i (model.md, inverse kinematics)."""
    p = np.asarray(p, dtype=float)
    drho, L = _legs(geometry, drho, dL)
    sq = p**2
    others = sq.sum(axis=-1, keepdims=True) - sq  # p_j² + p_k² for each i
    radicand = L**2 - others
    if np.any(radicand < 0):
        raise ValueError("point outside the reach of a leg")
    return p + np.sqrt(radicand) - drho


def forward(rho, geometry: Geometry, drho=None, dL=None) -> np.ndarray:
    """End point P for joint coordinates ρ, in closed form.

    With q_i = ρ_i + Δρ_i, k_i = q_i² − L_i² and s = |P|², (1) gives
    p_i = (s + k_i)/(2 q_i); then s = Σ p_i² is the quadratic
    A s² + B s + C = 0 with A = Σ w_i, B = 2 Σ k_i w_i − 1, C = Σ k_i² w_i,
    w_i = 1/(4 q_i²). The working branch is the smaller root (P near the
    origin at Π0), taken as 2C / (−B + sqrt(B² − 4AC)) to avoid cancellation.
    """
    rho = np.asarray(rho, dtype=float)
    drho, L = _legs(geometry, drho, dL)
    q = rho + drho
    k = q**2 - L**2
    w = 1.0 / (4.0 * q**2)
    A = w.sum(axis=-1)
    B = 2.0 * (k * w).sum(axis=-1) - 1.0
    C = (k**2 * w).sum(axis=-1)
    disc = B**2 - 4.0 * A * C
    if np.any(disc < 0) or np.any(B >= 0):
        raise ValueError("joint coordinates outside the assembly domain")
    s = 2.0 * C / (-B + np.sqrt(disc))
    return (s[..., None] + k) / (2.0 * q)
