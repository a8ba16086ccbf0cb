"""Exact measurement model: what a dial indicator on leg i, measuring along j,
shows (docs/model.md, "Measurement").

The indicator is fixed to the base in the plane x_i = M (the middle of leg i
at Π0, nominally L/2) and reads the j-coordinate of the leg's axis where the
leg crosses that plane; with tilted actuator axes the carriage leaves the
coordinate axis but the plane stays where the base holds it. The deviation
Δ^s_{i,j} is the reading at Π_i^s minus the reading at Π0; the simulator and
the nonlinear identification both use these functions.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from orthocal.geometry import AXIS_INDEX, BOW_NAMES, Geometry, bow_params, split_params
from orthocal.kinematics import axis_directions, axis_origins, forward_on_axes
from orthocal.postures import check_posture, plane_offset, posture

# (posture: "+", "-" or a signed stroke "+30", each perhaps in a second gauge plane,
# "+@0.25" (orthocal.postures); leg i; direction j)
Key = tuple[str, str, str]
Bows = Mapping[tuple[str, str], float]  # gauge (leg i, direction j) → sagitta h of its plane, mm


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


def _pick(a: np.ndarray, k) -> np.ndarray:
    """``a[..., k]``: one index for every point, or one per row of a (n, 3) array."""
    return a[..., k] if np.ndim(k) == 0 else a[np.arange(a.shape[0]), k]


def _carriage(rho: np.ndarray, i, j, drho: np.ndarray, u: np.ndarray | None,
              c: np.ndarray | None) -> np.ndarray:
    """Coordinate j of carriage i, A_i = c_i + q_i·u_i (q = ρ + Δρ; ``i``, ``j``
    scalars or one per row as for :func:`reading_at`)."""
    q_i = _pick(rho, i) + drho[i]
    a = q_i * (np.asarray(i == j, dtype=float) if u is None else u[i, j])
    return a if c is None else a + c[i, j]


def fraction_at(
    rho: np.ndarray, p: np.ndarray, i, drho: np.ndarray, mount, u: np.ndarray | None = None,
    c: np.ndarray | None = None,
) -> np.ndarray:
    """The fraction t = (A_i − M)/(A_i − p_i) from the carriage A toward P at which
    leg i's axis crosses the base-fixed plane x_i = ``mount`` (arguments as for
    :func:`reading_at`): where the plunger touches the leg. Nominally 1/2 at Π0
    and 1/2 + sin α at Π_i^s (docs/model.md, μ of system (7))."""
    if u is None and c is None:
        q_i = _pick(rho, i) + drho[i]
        return (q_i - mount) / (q_i - _pick(p, i))
    a_i = _carriage(rho, i, i, drho, u, c)
    return (a_i - mount) / (a_i - _pick(p, i))


def reading_at(
    rho: np.ndarray, p: np.ndarray, i, j, drho: np.ndarray, mount: float | np.ndarray,
    u: np.ndarray | None = None, c: np.ndarray | None = None,
) -> np.ndarray:
    """The reading of leg i along j given the joints ``rho`` and the end point ``p``
    (both (..., 3)); ``i`` and ``j`` are axis indices: scalars, or one per row
    when ``rho`` and ``p`` are (n, 3). ``u``: the axis directions (rows), None for
    e_x, e_y, e_z; ``c``: the points of the axes' lines (rows), None for the
    origin (axes that meet). The forward solve stays with the caller, who may
    share it.

    The indicator plane x_i = M is fixed to the base; the carriage
    A = c_i + q_i·u_i (q = ρ + Δρ) leaves the coordinate axis when u_i is tilted
    or the axes do not meet, so the leg's axis A → P crosses the plane at the
    fraction t = (A_i − M)/(A_i − p_i) from A (:func:`fraction_at`), where its
    j-coordinate is A_j + t·(p_j − A_j). With u_i = e_i, c_i = 0 (A_i = q_i,
    A_j = 0) this is the paper's t·p_j, bit for bit.
    """
    t = fraction_at(rho, p, i, drho, mount, u, c)
    if u is None and c is None:
        return t * _pick(p, j)
    a_j = _carriage(rho, i, j, drho, u, c)
    return a_j + t * (_pick(p, j) - a_j)


def bow_at(t, h) -> np.ndarray:
    """What a bow of the leg's surface adds to a reading taken at the fraction ``t``
    along the leg (from the carriage): the parabola through both ends of the leg
    with sagitta ``h`` (mm) at its middle, w(t) = 4·h·t·(1 − t). A
    straight leg (h = 0) adds nothing; a deviation sees w(t_s) − w(t_0)."""
    t = np.asarray(t, dtype=float)
    return 4.0 * np.asarray(h, dtype=float) * t * (1.0 - t)


# The last end points _leg_solve found: its exact arguments' bytes and (P, u, c).
# The simulated gauges of one leg read the same joints one after another (and
# contact_fraction after leg_reading): P does not depend on the gauge or its plane.
_last_leg: tuple[Geometry, bytes, tuple[Any, ...]] | None = None


def _exact(*arrays: np.ndarray | None) -> bytes:
    """The arrays' shapes and values as bytes, None marked: equal bytes, equal inputs."""
    return b"|".join(b"N" if a is None else repr(a.shape).encode() + a.tobytes()
                     for a in arrays)


def _leg_solve(rho, geometry: Geometry, drho, dL, mount, tilt, gap) -> tuple[Any, ...]:
    """(ρ, P, Δρ, M, u, c) of :func:`leg_reading` and :func:`contact_fraction`; P, u
    and c read-only (the last solve is given again for the same exact arguments)."""
    global _last_leg
    drho_v = np.zeros(3) if drho is None else np.asarray(drho, dtype=float)
    rho = np.asarray(rho, dtype=float)
    dL_v, tilt_v, gap_v = (None if a is None else np.asarray(a, dtype=float)
                           for a in (dL, tilt, gap))
    exact = _exact(rho, drho_v, dL_v, tilt_v, gap_v)
    last = _last_leg  # one read: another thread may replace it meanwhile
    if last is not None and last[0] == geometry and last[1] == exact:
        p, u, c = last[2]
    else:
        u, c = axis_directions(tilt_v), axis_origins(gap_v)
        p = forward_on_axes(rho, geometry, drho_v, dL_v, u, c)
        for array in (p, u, c):
            if array is not None:
                array.flags.writeable = False
        _last_leg = (geometry, exact, (p, u, c))
    m = geometry.mount_plane if mount is None else mount
    return rho, p, drho_v, m, u, c


def leg_reading(
    rho,
    leg: str,
    direction: str,
    geometry: Geometry,
    drho=None,
    dL=None,
    mount: float | None = None,
    tilt=None,
    bow: float | None = None,
    gap=None,
) -> np.ndarray:
    """Coordinate along ``direction`` of leg ``leg``'s axis in the base-fixed plane
    x_leg = M (docs/model.md, "Where the indicator plane is").

    The leg runs from the carriage A = c_i + q_i·u_i (q = ρ + Δρ; u_i = e_i unless
    ``tilt`` (mrad) tilts the axes, c_i = 0 unless ``gap`` (mm) says the axes do not
    meet) to P and crosses x_i = M at the fraction
    t = (A_i − M)/(A_i − p_i) from A, where its j-coordinate is
    A_j + t·(p_j − A_j). ``rho`` has shape (..., 3).

    ``bow``: the sagitta h (mm) of the leg's surface that this gauge sees, its
    bow w(t) = 4·h·t·(1 − t) (:func:`bow_at`) added to the reading; None (the
    default): a straight leg, the reading bit for bit as without the argument.
    """
    rho, p, drho_v, m, u, c = _leg_solve(rho, geometry, drho, dL, mount, tilt, gap)
    i = AXIS_INDEX[leg]
    reading = reading_at(rho, p, i, AXIS_INDEX[direction], drho_v, m, u, c)
    if bow is None:
        return reading
    return reading + bow_at(fraction_at(rho, p, i, drho_v, m, u, c), bow)


def contact_fraction(
    rho,
    leg: str,
    geometry: Geometry,
    drho=None,
    dL=None,
    mount: float | None = None,
    tilt=None,
    gap=None,
) -> np.ndarray:
    """The fraction t along leg ``leg`` (from the carriage A toward P) at which the
    gauges of the plane x_leg = M touch it at the joints ``rho`` (..., 3):
    t = (A_i − M)/(A_i − p_i), exact (:func:`fraction_at`; arguments as for
    :func:`leg_reading`). ≈ 1/2 at Π0, 1/2 + ρmax/L at Π_i^+, 1/2 + ρmin/L at Π_i^−."""
    rho, p, drho_v, m, u, c = _leg_solve(rho, geometry, drho, dL, mount, tilt, gap)
    return fraction_at(rho, p, AXIS_INDEX[leg], drho_v, m, u, c)


def deviation(key: Key, geometry: Geometry, params=None) -> float:
    """Exact Δ^s_{i,j} = reading at Π_i^s − reading at Π0 for the parameter
    vector ``params`` (PARAM_NAMES order; a 9-vector means no gaps, a 6-vector
    no tilts either)."""
    return float(deviations([key], geometry, params)[0])


def deviations(keys: Sequence[Key], geometry: Geometry, params=None,
               mount_offsets=None, bow: Bows | None = None) -> np.ndarray:
    """Exact deviations for many keys at once (repeated keys allowed).

    ``params``: PARAM_NAMES order (a 12-, 9- or 6-vector), or an 18-vector of
    FIT_NAMES whose last six are the legs' bows (BOW_NAMES: gauge (leg, direction)
    → sagitta, added to ``bow``'s).

    Each key is read in its gauges' plane: L/2, or the second plane its posture
    names (``"+@0.25"``: L/2 + L·(1/2 − 0.25), orthocal.postures.plane_offset).
    ``mount_offsets``: None, or one number per key, mm: how far the stand of that
    row's gauge sits off that plane (docs/model.md, "Where the indicator plane
    is"); the Π0 reading it is taken against uses the same plane. With None and
    middle planes the result is bit for bit the one without the argument.

    ``bow``: the legs' form as the gauges see it, gauge (leg, direction) → the
    sagitta h (mm) of the leg's surface in that gauge's plane (gauges not named:
    straight); each row's deviation gains w(t_s) − w(t_0), w(t) = 4·h·t·(1 − t)
    (:func:`bow_at`) at the contact fractions of its test posture and of Π0.
    None: straight legs, bit for bit as without the argument.

    Vectorised: one batched forward solve for the test postures of all ``keys``
    and one for Π0 (per-row leg and direction indices), because the nonlinear
    identification evaluates this hundreds of times.
    """
    drho, dL, tilt, gap = split_params(params)
    if len(keys) == 0:
        return np.empty(0)
    fitted = bow_params(params)
    if np.any(fitted != 0.0):
        bow = {**{(n[4], n[5]): float(h) for n, h in zip(BOW_NAMES, fitted, strict=True)},
               **{g: h + float(fitted[BOW_NAMES.index(f"bow_{g[0]}{g[1]}")])
                  for g, h in (bow or {}).items()}}
    table = KeyTable.of(keys, geometry)
    planes = table.planes
    if mount_offsets is not None or bow is not None or planes.any():
        offsets = np.zeros(len(keys)) if mount_offsets is None else \
            np.asarray(mount_offsets, dtype=float).reshape(-1)
        if offsets.shape != (len(keys),):
            raise ValueError(f"mount_offsets needs one value per key ({len(keys)}), "
                             f"got shape {np.shape(mount_offsets)}")
        return _deviations_mounted(table, geometry, drho, dL, tilt, gap, offsets + planes,
                                   None if bow is None else _row_bows(keys, bow))
    rows, legs, dirs, rho_s, rho_0, p_all, u, c = _solve(table, geometry, drho, dL, tilt, gap)
    p_s, p_0 = p_all[:-1], np.broadcast_to(p_all[-1], rho_s.shape)
    m = geometry.mount_plane
    reading_s = reading_at(rho_s, p_s, legs, dirs, drho, m, u, c)
    dev = reading_s - reading_at(np.broadcast_to(rho_0, rho_s.shape), p_0, legs, dirs, drho, m,
                                 u, c)
    return dev[rows]


def row_planes(keys: Sequence[Key], geometry: Geometry, mount_offsets=None) -> np.ndarray:
    """The base-fixed plane x_i = M (mm) each row of ``keys`` is read in: L/2, or
    its posture's second plane, plus its stand's ``mount_offsets`` (None: 0)."""
    m = geometry.mount_plane + KeyTable.of(keys, geometry).planes
    return m if mount_offsets is None else m + np.asarray(mount_offsets, dtype=float)


@dataclass(frozen=True)
class KeyTable:
    """What a list of keys means on the nominal machine, whatever the parameters:
    each key's row among the distinct ones, their leg and direction indices, their
    nominal joints, Π0's, and each key's gauge plane off L/2. The fit evaluates the
    same keys hundreds of times with other parameters; parsing and checking them
    once per list (an LRU cache) is most of what an evaluation cost."""

    rows: np.ndarray
    legs: np.ndarray
    dirs: np.ndarray
    rho_s: np.ndarray
    rho_0: np.ndarray
    planes: np.ndarray

    @staticmethod
    def of(keys: Sequence[Key], geometry: Geometry) -> KeyTable:
        global _last_table
        last = _last_table  # one read: another thread may replace it meanwhile
        # A tuple of keys is immutable: the same object means the same table (the
        # fit passes one tuple at every step; hashing it each time cost more).
        if last is not None and keys is last[0] and last[1] == geometry:
            return last[2]
        table = KeyTable._of(keys, geometry)
        if type(keys) is tuple and all(type(k) is tuple for k in keys):
            _last_table = (keys, geometry, table)
        return table

    @staticmethod
    def _of(keys: Sequence[Key], geometry: Geometry) -> KeyTable:
        try:
            frozen = tuple(tuple(k) for k in keys)
            hash(frozen)
        except TypeError:  # not a sequence of keys: let the checks below say so
            return _key_table(keys, geometry)
        return _cached_key_table(frozen, geometry)


_last_table: tuple[Sequence[Key], Geometry, KeyTable] | None = None


def _key_table(keys: Sequence[Key], geometry: Geometry) -> KeyTable:
    row_of: dict[Key, int] = {}
    # tuple(): a key may come as a list; mypy types tuple() of it as of any length
    rows = [row_of.setdefault(tuple(k), len(row_of)) for k in keys]  # type: ignore[arg-type]
    distinct = list(row_of)
    legs = np.empty(len(distinct), dtype=int)
    dirs = np.empty(len(distinct), dtype=int)
    rho_s = np.empty((len(distinct), 3))
    for n, key in enumerate(distinct):
        sign, leg, direction = check_key(key)
        legs[n], dirs[n] = AXIS_INDEX[leg], AXIS_INDEX[direction]
        rho_s[n] = posture(sign, leg, geometry)
    planes = np.array([plane_offset(k[0], geometry) for k in keys])
    table = KeyTable(np.asarray(rows, dtype=int), legs, dirs, rho_s,
                      posture("0", None, geometry), planes)
    for array in (table.rows, legs, dirs, rho_s, table.rho_0, planes):
        array.flags.writeable = False  # shared by every caller of the cache
    return table


@lru_cache(maxsize=256)
def _cached_key_table(keys: tuple[Key, ...], geometry: Geometry) -> KeyTable:
    return _key_table(keys, geometry)


def _row_bows(keys: Sequence[Key], bow: Bows) -> np.ndarray:
    """The sagitta of each row's gauge plane from a gauge → sagitta mapping."""
    for gauge, h in bow.items():
        if not (isinstance(gauge, tuple) and len(gauge) == 2 and gauge[0] in AXIS_INDEX
                and gauge[1] in AXIS_INDEX and gauge[0] != gauge[1]):
            raise ValueError(f"a bow's gauge is (leg, direction), two different axes, "
                             f"got {gauge!r}")
        if not np.isfinite(h):
            raise ValueError(f"the bow of gauge {gauge!r} is not a finite number: {h!r}")
    return np.array([float(bow.get((k[1], k[2]), 0.0)) for k in keys])


# The last solve (_solve): its table, geometry, parameters' bytes and result. The fit
# with stands reads the same parameters in three planes per step (its residual,
# then its Jacobian's stand columns at offsets 1 and 0: orthocal.stands); the end
# points do not depend on the plane, so the two later calls take the first's.
_last_solve: tuple[KeyTable, Geometry, bytes, tuple[Any, ...]] | None = None


def _solve(table: KeyTable, geometry: Geometry, drho: np.ndarray, dL: np.ndarray,
           tilt: np.ndarray, gap: np.ndarray) -> tuple[Any, ...]:
    """The end points of the table's distinct keys' test postures and of Π0 (its last row),
    in one solve (Newton when tilted or the axes do not meet): (each key's row
    among the distinct ones, their leg and direction indices, their joints, Π0's
    joints, the end points, the axis directions, the axes' points). The arrays
    are read-only: the last solve is given again for the same exact arguments."""
    global _last_solve
    # Repeated keys (one per cycle) share one solve: the fit calls this per step.
    exact = np.concatenate([drho, dL, tilt, gap]).astype(float).tobytes()
    last = _last_solve  # one read: another thread may replace it meanwhile
    if last is not None and last[0] is table and last[1] == geometry and last[2] == exact:
        return last[3]
    rows, legs, dirs, rho_s, rho_0 = table.rows, table.legs, table.dirs, table.rho_s, table.rho_0
    u, c = axis_directions(tilt), axis_origins(gap)
    p_all = forward_on_axes(np.vstack([rho_s, rho_0]), geometry, drho, dL, u, c)
    for array in (p_all, u, c):
        if array is not None:
            array.flags.writeable = False
    solved = (rows, legs, dirs, rho_s, rho_0, p_all, u, c)
    _last_solve = (table, geometry, exact, solved)
    return solved


def _deviations_mounted(table: KeyTable, geometry: Geometry, drho: np.ndarray,
                        dL: np.ndarray, tilt: np.ndarray, gap: np.ndarray,
                        offsets: np.ndarray, bows: np.ndarray | None = None) -> np.ndarray:
    """:func:`deviations` with one indicator plane per row, M = L/2 + offset, and
    (``bows``, one sagitta per row, or None) each row's leg bowed: the same batched
    solves, the readings taken in each row's own plane."""
    rows, legs, dirs, rho_s, rho_0, p_all, u, c = _solve(table, geometry, drho, dL, tilt, gap)
    # expand the distinct solves to the rows, each read in its own plane
    p_s, rho_r = p_all[:-1][rows], rho_s[rows]
    rho_0r = np.broadcast_to(rho_0, rho_r.shape)
    p_0 = np.broadcast_to(p_all[-1], rho_r.shape)
    m = geometry.mount_plane + offsets
    li, di = legs[rows], dirs[rows]
    reading_s = reading_at(rho_r, p_s, li, di, drho, m, u, c)
    dev = reading_s - reading_at(rho_0r, p_0, li, di, drho, m, u, c)
    if bows is None:
        return dev
    t_s = fraction_at(rho_r, p_s, li, drho, m, u, c)
    t_0 = fraction_at(rho_0r, p_0, li, drho, m, u, c)
    return dev + (bow_at(t_s, bows) - bow_at(t_0, bows))
