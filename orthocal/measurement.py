"""Exact measurement model: what a dial indicator on leg i, measuring along j,
shows (model.md, "Measurement").

The indicator is fixed to the base in the plane x_i = M (the middle of leg i
at Π0, nominally L/2) and reads the j-coordinate of the leg's axis where the
leg crosses that plane. The deviation Δ^s_{i,j} is the reading at Π_i^s minus
the reading at Π0; the simulator and the nonlinear identification both use
these functions.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from orthocal.geometry import AXIS_INDEX, Geometry, split_params
from orthocal.kinematics import forward
from orthocal.postures import check_posture, posture

Key = tuple[str, str, str]  # (posture: "+", "-" or a signed stroke "+30"; leg i; direction j)


def check_key(key: Key) -> Key:
    """Validate a deviation key ``(sign, leg, direction)``; raises ValueError."""
    if not (isinstance(key, tuple) and len(key) == 3):
        raise ValueError(f"a deviation key is (sign, leg, direction), got {key!r}")
    sign, leg, direction = key
    try:
        check_posture(sign)
    except ValueError as exc:
        raise ValueError(f"{exc} in {key!r}") from None
    if leg not in AXIS_INDEX or direction not in AXIS_INDEX:
        raise ValueError(f"leg and direction must be x, y or z, got {key!r}")
    if leg == direction:
        raise ValueError(f"direction must differ from the leg, got {key!r}")
    return key


def _reading(rho: np.ndarray, p: np.ndarray, i, j, drho: np.ndarray, mount: float) -> np.ndarray:
    """The reading of leg i along j given the joints ``rho`` and the end point ``p``
    (both (..., 3)); ``i`` and ``j`` are axis indices: scalars, or one per row
    when ``rho`` and ``p`` are (n, 3). The forward solve stays with the caller, who may share it."""

    def pick(a: np.ndarray, k) -> np.ndarray:
        # one index for every point, or one per row of a (n, 3) array
        return a[..., k] if np.ndim(k) == 0 else a[np.arange(a.shape[0]), k]

    q_i = pick(rho, i) + drho[i]
    return (q_i - mount) / (q_i - pick(p, i)) * pick(p, j)


def leg_reading(
    rho,
    leg: str,
    direction: str,
    geometry: Geometry,
    drho=None,
    dL=None,
    mount: float | None = None,
) -> np.ndarray:
    """Coordinate along ``direction`` of leg ``leg``'s axis in the plane x_leg = M.

    The leg runs from the actuator joint A = q_i·e_i (q = ρ + Δρ) to P; it crosses
    x_i = M at the fraction t = (q_i − M)/(q_i − p_i) from A, where its
    j-coordinate is t·p_j (A_j = 0). ``rho`` has shape (..., 3).
    """
    drho_v = np.zeros(3) if drho is None else np.asarray(drho, dtype=float)
    rho = np.asarray(rho, dtype=float)
    p = forward(rho, geometry, drho_v, dL)
    m = geometry.mount_plane if mount is None else mount
    return _reading(rho, p, AXIS_INDEX[leg], AXIS_INDEX[direction], drho_v, m)


def deviation(key: Key, geometry: Geometry, params=None) -> float:
    """Exact Δ^s_{i,j} = reading at Π_i^s − reading at Π0 for the parameter
    6-vector ``params`` (PARAM_NAMES order)."""
    return float(deviations([key], geometry, params)[0])


def deviations(keys: Sequence[Key], geometry: Geometry, params=None) -> np.ndarray:
    """Exact deviations for many keys at once (repeated keys allowed).

    Vectorised: one batched forward solve for the test postures of all ``keys``
    and one for Π0 (per-row leg and direction indices), because the nonlinear
    identification evaluates this hundreds of times.
    """
    drho, dL = split_params(params)
    if len(keys) == 0:
        return np.empty(0)
    legs = np.empty(len(keys), dtype=int)
    dirs = np.empty(len(keys), dtype=int)
    rho_s = np.empty((len(keys), 3))
    cache: dict[tuple[str, str], np.ndarray] = {}
    for n, key in enumerate(keys):
        sign, leg, direction = check_key(key)
        legs[n], dirs[n] = AXIS_INDEX[leg], AXIS_INDEX[direction]
        if (sign, leg) not in cache:
            cache[(sign, leg)] = posture(sign, leg, geometry)
        rho_s[n] = cache[(sign, leg)]
    rho_0 = posture("0", None, geometry)
    p_s = forward(rho_s, geometry, drho, dL)
    p_0 = np.broadcast_to(forward(rho_0, geometry, drho, dL), p_s.shape)
    m = geometry.mount_plane
    reading_s = _reading(rho_s, p_s, legs, dirs, drho, m)
    return reading_s - _reading(np.broadcast_to(rho_0, rho_s.shape), p_0, legs, dirs, drho, m)
