"""The noise a run measures on itself: how the deviations of the station's cycles
are correlated (consecutive cycles share their Π0 stop), the noise of one
per-cycle deviation from the cycle-to-cycle scatter or from the scatter of the
readings at a stop, and the coverage factor of an interval on few degrees of
freedom (Student's t, GUM G.3)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from functools import lru_cache

import numpy as np

from orthocal.inputs import flatten_deviations
from orthocal.measurement import Key
from orthocal.postures import split_plane

# Consecutive cycles share their Π0 stop (station.engine.sequencer): a per-cycle
# deviation P − (Z_before + Z_after)/2 has variance 1.5·s² with s² the variance
# of one stop mean; deviations of one gauge in the same cycle share both Π0
# stops (covariance 0.5·s²), in adjacent cycles one (0.25·s²).
_SAME_CYCLE, _ADJACENT_CYCLE = 0.5 / 1.5, 0.25 / 1.5
SHARED_ZERO_LAG1 = _ADJACENT_CYCLE  # = 1/6, station.engine.sequencer.SHARED_P0_CORRELATION


def _gauge_rows(keys: Sequence[Key]) -> list[tuple[tuple[str, str, float], int]]:
    """(gauge, cycle index) of each row: a key's repeats are its cycles in order. A
    gauge is its leg, direction and plane: read in a second plane (``"+@0.75"``) it
    was mounted there in setups of its own, with Π0 readings of their own, and shares
    none with its rows at the leg's middle."""
    count: dict[Key, int] = {}
    rows = []
    for key in keys:
        rows.append(((key[1], key[2], split_plane(key[0])[1]), count.get(key, 0)))
        count[key] = count.get(key, 0) + 1
    return rows


def row_correlation(keys: Sequence[Key], shared_zero: bool = True) -> np.ndarray:
    """Correlation of the rows ``keys`` (one per cycle: a key repeated once per
    cycle, in cycle order). Without ``shared_zero`` the rows are independent;
    with it, the station's Π0 sharing correlates rows of one gauge (leg,
    direction): 1/3 in the same cycle, 1/6 in adjacent cycles."""
    frozen = _frozen(keys)
    if frozen is None:
        return _row_correlation(keys, shared_zero)
    return _cached_row_correlation(frozen, shared_zero).copy()


def _frozen(keys: Sequence[Key]) -> tuple[Key, ...] | None:
    """``keys`` as a hashable tuple, None when they are not hashable (then not cached)."""
    try:
        frozen = tuple(keys)
        hash(frozen)
    except TypeError:
        return None
    return frozen


# A model selection asks for the same rows' correlation a dozen times (each
# candidate's lack of fit, each nested test, each covariance); read-only copies kept.
@lru_cache(maxsize=64)
def _cached_row_correlation(keys: tuple[Key, ...], shared_zero: bool) -> np.ndarray:
    C = _row_correlation(keys, shared_zero)
    C.flags.writeable = False
    return C


def _row_correlation(keys: Sequence[Key], shared_zero: bool) -> np.ndarray:
    n = len(keys)
    C = np.eye(n)
    if shared_zero and n > 1:
        rows = _gauge_rows(keys)
        ids: dict[tuple[str, str, float], int] = {}
        gauge = np.array([ids.setdefault(g, len(ids)) for g, _ in rows])
        cycle = np.array([c for _, c in rows])
        same = gauge[:, None] == gauge[None, :]
        lag = np.abs(cycle[:, None] - cycle[None, :])
        C[same & (lag == 0) & ~np.eye(n, dtype=bool)] = _SAME_CYCLE
        C[same & (lag == 1)] = _ADJACENT_CYCLE
    return C


def key_rows(keys: Sequence[Key]) -> tuple[list[Key], list[np.ndarray]]:
    """The distinct keys in order of first appearance and the indices of each one's
    rows (its cycles), ascending: ``values[rows]`` are the rows ``k == key`` picks."""
    index: dict[Key, list[int]] = {}
    for r, key in enumerate(keys):
        index.setdefault(key, []).append(r)
    return list(index), [np.array(v, dtype=int) for v in index.values()]


def means_covariance(keys: Sequence[Key], shared_zero: bool = True) -> tuple[list[Key], np.ndarray]:
    """Distinct keys and the covariance of their means in units of σ², the
    variance of one per-cycle deviation (rows as for :func:`row_correlation`)."""
    frozen = _frozen(keys)
    if frozen is None:
        return _means_covariance(keys, shared_zero)
    distinct, M = _cached_means_covariance(frozen, shared_zero)
    return list(distinct), M.copy()


@lru_cache(maxsize=64)
def _cached_means_covariance(keys: tuple[Key, ...], shared_zero: bool
                             ) -> tuple[tuple[Key, ...], np.ndarray]:
    distinct, M = _means_covariance(keys, shared_zero)
    M.flags.writeable = False
    return tuple(distinct), M


def _means_covariance(keys: Sequence[Key], shared_zero: bool) -> tuple[list[Key], np.ndarray]:
    distinct = list(dict.fromkeys(keys))
    index = {k: n for n, k in enumerate(distinct)}
    n = len(keys)
    C = row_correlation(keys, shared_zero)
    A = np.zeros((len(distinct), n))
    for r, key in enumerate(keys):
        A[index[key], r] = 1.0
    A /= A.sum(axis=1, keepdims=True)
    return distinct, A @ C @ A.T


def noise_from_cycles(deviations_in: Mapping | Iterable,
                      shared_zero: bool = True) -> tuple[float, int]:
    """σ̂ of one per-cycle deviation and its degrees of freedom from the
    cycle-to-cycle scatter of each deviation, pooled. With shared Π0 stops the
    scatter understates the variance by (1 − 2ρ/c), ρ = 1/6 (as in
    station.engine.sequencer.cycle_std_error); corrected here. Raises ValueError when
    no deviation has two cycles."""
    keys, y = flatten_deviations(deviations_in)
    groups: dict[Key, list[float]] = {}
    for k, v in zip(keys, y, strict=True):
        groups.setdefault(k, []).append(float(v))
    num, dof = 0.0, 0
    for vals in groups.values():
        c = len(vals)
        if c < 2:
            continue
        understate = 1.0 - 2.0 * SHARED_ZERO_LAG1 / c if shared_zero else 1.0
        num += (c - 1) * float(np.var(vals, ddof=1)) / understate
        dof += c - 1
    if dof == 0:
        raise ValueError("no deviation was measured in two cycles or more: no cycle scatter")
    return math.sqrt(num / dof), dof


def noise_from_readings(stop_std: Sequence[float], readings: int) -> tuple[float, int]:
    """σ̂ of one per-cycle deviation from the scatter of ``readings`` readings at
    each stop (``stop_std``: their standard deviations): a stop mean has variance
    σ_r²/n and a deviation P − (Z + Z')/2 1.5 times that. ν = stops·(n − 1)."""
    s = np.asarray(stop_std, dtype=float)
    if s.size == 0 or readings < 2:
        raise ValueError("no stop with two readings or more: no within-stop scatter")
    sigma_r2 = float(np.mean(s**2))
    return math.sqrt(1.5 * sigma_r2 / readings), int(s.size * (readings - 1))


def coverage_factor(dof: float | None, coverage: float = 0.95) -> float:
    """k such that ±k standard errors hold the truth with probability ``coverage``
    when the standard errors rest on ``dof`` degrees of freedom (GUM G.3: Student's
    t). Two cycles of a six-gauge run give about 12 dof and k95 = 2.18, not 1.96;
    k99.73 = 3.8, not 3: "within 3 standard errors" fails three times as often as
    the normal promises. ``dof`` None or infinite: the normal's k."""
    # scipy.special, not scipy.stats: the same functions (t.ppf is stdtrit) without
    # scipy.stats' half second of imports and its per-call argument handling.
    from scipy import special

    if not (0.0 < coverage < 1.0):
        raise ValueError(f"coverage must lie in (0, 1), got {coverage!r}")
    tail = (1.0 + coverage) / 2.0
    if dof is None or not math.isfinite(dof):
        return float(special.ndtri(tail))
    if dof <= 0:
        raise ValueError(f"coverage_factor needs dof > 0, got {dof!r}")
    return float(special.stdtrit(dof, tail))
