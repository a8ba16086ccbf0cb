"""Exact kinematics of model (1) and of the extended model with tilted axes that
need not meet.

Leg i is a bar of length L_i = L + ΔL_i from the actuator joint (carriage)
A_i = c_i + (ρ_i + Δρ_i)·u_i to the end point P:

    |P − A_i| = L_i                                                         (1')

with u_i the direction of actuator axis i (docs/model.md, "Extended model"):
u_x = e_x, u_y = normalise(e_y + t_yx·e_x), u_z = normalise(e_z + t_zx·e_x +
t_zy·e_y), tilts t in mrad; and c_i a point of axis i's line (docs/model.md, "Axes
that do not meet"): c_x = (0, g_xz/2, g_xy/2), c_y = (g_yz/2, 0, −g_xy/2),
c_z = (−g_yz/2, −g_xz/2, 0), gaps g in mm. With zero tilts and gaps u_i = e_i,
c_i = 0 and (1') is the paper's

    (p_i − (ρ_i + Δρ_i))² + p_j² + p_k² = L_i²                              (1)

All functions broadcast over leading dimensions: ``p`` and ``rho`` have shape
(..., 3).
"""

from __future__ import annotations

import numpy as np

from orthocal.geometry import MRAD, Geometry

# Newton on the sphere equations stops when its step is below this (mm).
_NEWTON_TOL = 1e-12
_NEWTON_MAX_STEPS = 30


def _legs(geometry: Geometry, drho, dL) -> tuple[np.ndarray, np.ndarray]:
    drho = np.zeros(3) if drho is None else np.asarray(drho, dtype=float)
    L = geometry.leg_length + (np.zeros(3) if dL is None else np.asarray(dL, dtype=float))
    return drho, L


def axis_directions(tilt=None) -> np.ndarray | None:
    """Rows u_x, u_y, u_z of the actuator axes for tilts (t_yx, t_zx, t_zy) in mrad
    (docs/model.md, "Extended model"); None when every tilt is zero, so that callers
    keep the paper's closed forms (and today's numbers to the bit)."""
    if tilt is None:
        return None
    t = np.asarray(tilt, dtype=float) * MRAD
    if t.shape != (3,):
        raise ValueError(f"expected 3 tilts (tilt_yx, tilt_zx, tilt_zy), got shape {t.shape}")
    if not np.any(t):
        return None
    u = np.array([[1.0, 0.0, 0.0], [t[0], 1.0, 0.0], [t[1], t[2], 1.0]])
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def axis_origins(gap=None) -> np.ndarray | None:
    """Rows c_x, c_y, c_z: where each actuator axis's line passes the origin, for
    gaps (g_xy, g_xz, g_yz) in mm (docs/model.md, "Axes that do not meet": the origin
    midway between each pair of axes); None when every gap is zero, so that
    callers keep the closed forms of axes that meet."""
    if gap is None:
        return None
    g = np.asarray(gap, dtype=float)
    if g.shape != (3,):
        raise ValueError(f"expected 3 gaps (gap_xy, gap_xz, gap_yz), got shape {g.shape}")
    if not np.any(g):
        return None
    g_xy, g_xz, g_yz = g / 2.0
    return np.array([[0.0, g_xz, g_xy], [g_yz, 0.0, -g_xy], [-g_yz, -g_xz, 0.0]])


def inverse(p, geometry: Geometry, drho=None, dL=None, tilt=None, gap=None) -> np.ndarray:
    """Joint coordinates ρ that put the end point at ``p``.

    |P − c_i − q_i·u_i| = L_i is a quadratic in q_i = ρ_i + Δρ_i whose working root
    (carriage beyond P) is q_i = u_i·(P − c_i) + sqrt(L_i² − |d_i − (u_i·d_i)·u_i|²),
    d_i = P − c_i; with u_i = e_i, c_i = 0 it is ρ_i = p_i + sqrt(L_i² − p_j² − p_k²)
    − Δρ_i (docs/model.md).
    """
    p = np.asarray(p, dtype=float)
    drho, L = _legs(geometry, drho, dL)
    u = axis_directions(tilt)
    c = axis_origins(gap)
    if u is None and c is None:
        sq = p**2
        along = p
        others = sq.sum(axis=-1, keepdims=True) - sq  # p_j² + p_k² for each i
    else:
        u = np.eye(3) if u is None else u
        d = p[..., None, :] - (0.0 if c is None else c)  # rows P − c_i
        along = (d * u).sum(axis=-1)  # u_i·(P − c_i) for each i
        perp = d - along[..., :, None] * u
        others = (perp**2).sum(axis=-1)
    radicand = L**2 - others
    if (radicand < 0).any():
        raise ValueError("point outside the reach of a leg")
    return along + np.sqrt(radicand) - drho


def _forward_orthogonal(q: np.ndarray, L: np.ndarray) -> np.ndarray:
    """Closed-form P for carriages at q_i·e_i (docs/model.md, forward kinematics)."""
    k = q**2 - L**2
    w = 1.0 / (4.0 * q**2)
    A = w.sum(axis=-1)
    B = 2.0 * (k * w).sum(axis=-1) - 1.0
    C = (k**2 * w).sum(axis=-1)
    disc = B**2 - 4.0 * A * C
    if (disc < 0).any() or (B >= 0).any():  # methods: no wrapper per call
        raise ValueError("joint coordinates outside the assembly domain")
    s = 2.0 * C / (-B + np.sqrt(disc))
    return (s[..., None] + k) / (2.0 * q)


def forward(rho, geometry: Geometry, drho=None, dL=None, tilt=None, gap=None) -> np.ndarray:
    """End point P for joint coordinates ρ.

    Orthogonal axes (tilts zero or None), closed form: with q_i = ρ_i + Δρ_i,
    k_i = q_i² − L_i² and s = |P|², (1) gives p_i = (s + k_i)/(2 q_i); then
    s = Σ p_i² is the quadratic A s² + B s + C = 0 with A = Σ w_i,
    B = 2 Σ k_i w_i − 1, C = Σ k_i² w_i, w_i = 1/(4 q_i²). The working branch is
    the smaller root (P near the origin at Π0), taken as 2C / (−B + sqrt(B² − 4AC))
    to avoid cancellation.

    Tilted axes: no closed form. Newton on the three sphere equations
    F_i(P) = |P − A_i|² − L_i² = 0 (Jacobian rows 2(P − A_i)) from the orthogonal
    solution of the same q, L, all points at once, until the step is below 1e-12 mm
    (three or four steps for tilts of a few mrad: the start is off by ~q·tilt).
    Axes that do not meet (``gap``, mm) likewise: the carriages sit at c_i + q_i·u_i.
    """
    return forward_on_axes(rho, geometry, drho, dL, axis_directions(tilt), axis_origins(gap))


def forward_on_axes(rho, geometry: Geometry, drho, dL, u: np.ndarray | None,
                    c: np.ndarray | None = None) -> np.ndarray:
    """:func:`forward` for axis directions ``u`` and points ``c`` already computed
    (None: e_x, e_y, e_z; lines through the origin)."""
    rho = np.asarray(rho, dtype=float)
    drho, L = _legs(geometry, drho, dL)
    q = rho + drho
    if u is None and c is None:
        return _forward_orthogonal(q, L)
    return solve_spheres(q, L, np.eye(3) if u is None else u, c)


def carriages(q: np.ndarray, u: np.ndarray | None, c: np.ndarray | None = None) -> np.ndarray:
    """Carriage positions A_i = c_i + q_i·u_i, shape (..., 3, 3) (rows A_i)."""
    a = q[..., :, None] * (np.eye(3) if u is None else u)
    return a if c is None else a + c


def solve_spheres(q: np.ndarray, L: np.ndarray, u: np.ndarray,
                  c: np.ndarray | None = None) -> np.ndarray:
    """P with |P − c_i − q_i·u_i| = L_i for any axis directions ``u`` and points
    ``c`` (rows; None: through the origin): Newton from the orthogonal closed
    form, all points of ``q`` (..., 3) at once."""
    p = _forward_orthogonal(q, L)
    a = carriages(q, u, c)
    for _ in range(_NEWTON_MAX_STEPS):
        d = p[..., None, :] - a  # rows P − A_i
        f = (d**2).sum(axis=-1) - L**2
        step = np.linalg.solve(2.0 * d, f[..., None])[..., 0]
        p = p - step
        if step.size == 0 or float(np.max(np.abs(step))) < _NEWTON_TOL:
            return p
    raise ValueError("forward kinematics did not converge (joint coordinates near a singularity)")
