"""Exact deviations for many parameter vectors at once (docs/model.md,
"Measurement"): what :func:`orthocal.measurement.deviations` gives for each row of
a (B, 18) array of FIT_NAMES vectors, in one batched forward solve.

The nonlinear fit's Jacobian (:func:`orthocal.identification.exact_jacobian`) is
2·p evaluations of the same keys at parameter vectors h apart; one by one they
cost numpy's per-call overhead 2·p times over, most of a fit's time. The
readings are :func:`orthocal.measurement.reading_at`'s, written for a batch:
the carriage A = c_i + q_i·u_i with u = I and c = 0 where a row has no tilt or
gap, which gives the closed forms' numbers bit for bit (q·1 = q, 0 + t·p = t·p);
rows without tilts or gaps take the closed-form forward solve, the others one
Newton solve together (each within 1e-12 mm, as alone).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from orthocal.geometry import BOW_NAMES, FIT_NAMES, MRAD, PARAM_NAMES, Geometry
from orthocal.kinematics import forward_on_axes
from orthocal.measurement import Key, KeyTable, bow_at

_N_PARAMS = len(PARAM_NAMES)


def axis_directions_batch(tilts: np.ndarray) -> np.ndarray:
    """Rows u_x, u_y, u_z for each row of tilts (B, 3), mrad: (B, 3, 3), the identity
    where a row's tilts are zero (:func:`orthocal.kinematics.axis_directions`)."""
    t = np.asarray(tilts, dtype=float) * MRAD
    u = np.zeros((t.shape[0], 3, 3))
    u[:, 0, 0] = u[:, 1, 1] = u[:, 2, 2] = 1.0
    u[:, 1, 0], u[:, 2, 0], u[:, 2, 1] = t[:, 0], t[:, 1], t[:, 2]
    return u / np.linalg.norm(u, axis=2, keepdims=True)


def axis_origins_batch(gaps: np.ndarray) -> np.ndarray:
    """Rows c_x, c_y, c_z for each row of gaps (B, 3), mm: (B, 3, 3), zero where a
    row's gaps are zero (:func:`orthocal.kinematics.axis_origins`)."""
    g = np.asarray(gaps, dtype=float) / 2.0
    c = np.zeros((g.shape[0], 3, 3))
    c[:, 0, 1], c[:, 0, 2] = g[:, 1], g[:, 0]
    c[:, 1, 0], c[:, 1, 2] = g[:, 2], -g[:, 0]
    c[:, 2, 0], c[:, 2, 1] = -g[:, 2], -g[:, 1]
    return c


def _forward_batch(rho: np.ndarray, geometry: Geometry, drho: np.ndarray, dL: np.ndarray,
                   u: np.ndarray, c: np.ndarray, straight: np.ndarray) -> np.ndarray:
    """End points (B, K, 3) of the joints ``rho`` (K, 3) under each row's Δρ, ΔL
    (B, 3): closed form for the rows ``straight`` (no tilt, no gap), one Newton solve
    for the others (:func:`orthocal.kinematics.forward_on_axes`)."""
    p = np.empty((drho.shape[0], *rho.shape))
    if straight.any():
        p[straight] = forward_on_axes(rho, geometry, drho[straight][:, None],
                                      dL[straight][:, None], None)
    bent = ~straight
    if bent.any():
        p[bent] = forward_on_axes(rho, geometry, drho[bent][:, None], dL[bent][:, None],
                                  u[bent][:, None], c[bent][:, None])
    return p


def _readings(q_i: np.ndarray, p: np.ndarray, li: np.ndarray, di: np.ndarray,
              m: np.ndarray, u: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(reading, contact fraction t) of each row's gauge, (B, N) each:
    :func:`orthocal.measurement.reading_at` and ``fraction_at`` for a batch."""
    rows = np.arange(li.size)
    a_i = q_i * u[:, li, li] + c[:, li, li]
    a_j = q_i * u[:, li, di] + c[:, li, di]
    t = (a_i - m) / (a_i - p[:, rows, li])
    return a_j + t * (p[:, rows, di] - a_j), t


def deviations_batch(keys: Sequence[Key], geometry: Geometry, params_rows,
                     mount_offsets=None) -> np.ndarray:
    """Exact deviations of ``keys`` for each row of ``params_rows`` (B × 18, FIT_NAMES
    order, the legs' bows included): (B, len(keys)), each row what
    :func:`orthocal.measurement.deviations` gives for that vector (within 1e-12 mm
    where tilts or gaps call for Newton). ``mount_offsets``: as there."""
    P = np.asarray(params_rows, dtype=float)
    if P.ndim != 2 or P.shape[1] != len(FIT_NAMES):
        raise ValueError(f"expected rows of {len(FIT_NAMES)} parameters {FIT_NAMES}, got "
                         f"shape {P.shape}")
    if len(keys) == 0:
        return np.empty((P.shape[0], 0))
    table = KeyTable.of(keys, geometry)
    offsets = np.zeros(len(keys)) if mount_offsets is None else \
        np.asarray(mount_offsets, dtype=float).reshape(-1)
    if offsets.shape != (len(keys),):
        raise ValueError(f"mount_offsets needs one value per key ({len(keys)}), "
                         f"got shape {np.shape(mount_offsets)}")
    drho, dL, tilt, gap = (P[:, k:k + 3] for k in range(0, _N_PARAMS, 3))
    u, c = axis_directions_batch(tilt), axis_origins_batch(gap)
    straight = ~(np.any(tilt != 0.0, axis=1) | np.any(gap != 0.0, axis=1))
    p_all = _forward_batch(np.vstack([table.rho_s, table.rho_0]), geometry, drho, dL, u, c,
                           straight)
    rows, li, di = table.rows, table.legs[table.rows], table.dirs[table.rows]
    m = geometry.mount_plane + (offsets + table.planes)
    q_s = table.rho_s[rows, li][None, :] + drho[:, li]
    q_0 = table.rho_0[li][None, :] + drho[:, li]
    p_s = p_all[:, :-1][:, rows]
    p_0 = np.broadcast_to(p_all[:, -1:], p_s.shape)
    reading_s, t_s = _readings(q_s, p_s, li, di, m, u, c)
    reading_0, t_0 = _readings(q_0, p_0, li, di, m, u, c)
    bows = P[:, _N_PARAMS:][:, _bow_columns(table, rows)]
    return (reading_s - reading_0) + (bow_at(t_s, bows) - bow_at(t_0, bows))


def _bow_column_table() -> np.ndarray:
    """The BOW_NAMES column of the gauge (leg, direction), by their axis indices (−1
    where leg and direction are one axis: no gauge)."""
    names = "xyz"
    table = np.full((3, 3), -1, dtype=int)
    for leg in range(3):
        for d in range(3):
            if leg != d:
                table[leg, d] = BOW_NAMES.index(f"bow_{names[leg]}{names[d]}")
    return table


_BOW_COLUMN = _bow_column_table()


def _bow_columns(table: KeyTable, rows: np.ndarray) -> np.ndarray:
    """The BOW_NAMES column of each key's gauge (leg, direction): looked up, not
    searched by name per key (the fit's Jacobian asks at every step)."""
    return _BOW_COLUMN[table.legs[rows], table.dirs[rows]]
