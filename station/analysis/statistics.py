"""The statistics of a measurement: outlier rejection within a stop, the gauges'
pooled noise, the standard error of a deviation over cycles that share their Π0
stops, and the measurement a phase hands to the identification.

Deviation of a cycle = mean at Π_i^s − mean of the two Π0 stops bracketing it
(cancels linear drift of gauge and machine). Within a stop, a reading far from
its siblings (median ± k·1.4826·MAD, floored at the gauge resolution) is
rejected. With ``target_std_error_mm`` a setup stops as soon as its deviations'
standard error reaches it (≥ 2 cycles; see :func:`cycle_std_error`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TypedDict

import numpy as np
from pydantic import Field

from station.record.result import Setup as SetupRecord

MAD_SCALE = 1.4826  # MAD of a normal sample × this ≈ σ


def split_key(key: str) -> tuple[str, str, str]:
    """A JSON deviation key ("+xy", "+30xy", "-50.5zx") as (posture, leg, direction)."""
    return key[:-2], key[-2], key[-1]


def reject_outliers(
    values: Sequence[float], k: float, floor: float, scale: float | None = None
) -> list[bool]:
    """Mask of kept readings: |r − median| ≤ max(k·1.4826·MAD, k·scale, floor).

    ``scale`` is the gauge's pooled robust scatter about its stop medians over the
    run so far (see :class:`NoiseScale`). With five readings per stop the stop's own
    MAD is often near zero by chance (and exactly zero on quantised data), which
    alone would reject a few percent of perfectly normal readings; the pooled
    scale keeps the bound at k·σ while a knock of tenths of a mm still stands out.
    """
    v = np.asarray(values, dtype=float)
    if v.size < 3:
        return [True] * int(v.size)
    med = float(np.median(v))
    mad = float(np.median(np.abs(v - med)))
    bound = max(k * MAD_SCALE * mad, k * (scale or 0.0), floor)
    return [bool(abs(x - med) <= bound + 1e-12) for x in v]


class NoiseScale:
    """Robust σ of one gauge's readings, pooled over every stop so far:
    1.4826 · median |r| with r the residuals about each stop's mean scaled by
    sqrt(n/(n−1)) (unbiased for normal noise). Residuals about the stop *median*
    would read low: one reading of every odd-sized stop is the median itself.
    A knocked stop contributes n residuals to a pool of hundreds, so the median
    ignores it."""

    def __init__(self) -> None:
        self._abs_dev: list[float] = []

    def add(self, values: Sequence[float]) -> None:
        v = np.asarray(values, dtype=float)
        if v.size >= 3:
            scale = math.sqrt(v.size / (v.size - 1))
            self._abs_dev.extend((np.abs(v - v.mean()) * scale).tolist())

    @property
    def sigma(self) -> float | None:
        return MAD_SCALE * float(np.median(self._abs_dev)) if self._abs_dev else None


# Consecutive cycles share their Π0 stop: with independent noise at every stop,
# a deviation P_k − (Z_{k−1} + Z_k)/2 has variance 1.5·s² and covariance s²/4
# with the next cycle's, a lag-1 correlation of 1/6.
SHARED_P0_CORRELATION = 1.0 / 6.0


def cycle_std_error(cycles: Sequence[Mapping[str, float]]) -> float:
    """Standard error of a deviation's mean over ``cycles`` (one setup's per-cycle
    deviations, ≥ 2 cycles), from their scatter across cycles.

    The variance is pooled over the setup's deviations (same gauges, same
    machine): a per-deviation estimate has one degree of freedom at two cycles,
    and requiring all four of them below a target stops late on the largest
    draw. The shared Π0 makes the scatter understate the per-cycle variance by
    (1 − 2ρ/c) while the mean's variance exceeds variance/c by (1 + 2ρ(c−1)/c);
    uncorrected, a setup stops ~18 % above its target."""
    c = len(cycles)
    if c < 2:
        return math.inf
    var = float(np.mean([np.var([cy[k] for cy in cycles], ddof=1) for k in cycles[0]]))
    rho = SHARED_P0_CORRELATION
    factor = (c + 2.0 * (c - 1) * rho) / (c - 2.0 * rho)
    return math.sqrt(var * factor / c)


@dataclass
class StopStat:
    mean: float
    std: float | None  # of the kept readings
    kept: int
    rejected: list[float]


class SetupOutcome(SetupRecord):
    """How a setup went: result.json's ``setups[]`` entry (station.record.result.Setup,
    its fields declared there once) and what the engine keeps beside it, left out of
    the record: the setup's index and which cycles it used."""

    index: int = Field(exclude=True)
    cycles: list[int] = Field(default_factory=list, exclude=True)


class DeviationStats(TypedDict):
    """One deviation over its cycles: mean (mm), sample standard deviation (mm; None
    from one cycle) and the number of cycles."""

    mean: float
    std: float | None
    n: int


@dataclass
class Measurement:
    phase: str
    # key "+xy" -> per-cycle deviations (the used pass of its setup)
    deviations: dict[str, list[float]]
    setups: list[SetupOutcome]
    within_std: list[float]  # std of the readings at each stop, for the noise estimate
    # joint axis -> each cycle's measurement of its reversal (mm; orthocal.lost_motion)
    reversal: dict[str, list[float]] = field(default_factory=dict)
    # key -> its cycles from each mounting of its gauges, in order (pooled passes:
    # one per pass); the stands were set again for each (orthocal.Stands.mounts)
    mounts: dict[str, list[int]] = field(default_factory=dict)
    # keys whose first cycles here continue the mounting the pass before ended with
    # (gauges left on: station.engine.kept)
    continued: tuple[str, ...] = ()

    def stats(self) -> dict[str, DeviationStats]:
        out: dict[str, DeviationStats] = {}
        for key, vals in self.deviations.items():
            arr = np.asarray(vals)
            out[key] = {"mean": float(arr.mean()),
                        "std": float(arr.std(ddof=1)) if arr.size > 1 else None,
                        "n": int(arr.size)}
        return out

    @property
    def noise_mm(self) -> float | None:
        if not self.within_std:
            return None
        return float(math.sqrt(np.mean(np.square(self.within_std))))

    def for_identify(self) -> dict[tuple[str, str, str], list[float]]:
        return {split_key(k): list(v) for k, v in self.deviations.items()}

    def mounts_for_identify(self) -> dict[tuple[str, str, str], tuple[int, ...]]:
        """The keys read in more than one mounting: their cycles of each."""
        return {split_key(k): tuple(v) for k, v in self.mounts.items() if len(v) > 1}


def pooled(first: Measurement, more: Measurement) -> Measurement:
    """One round's passes as one measurement (the same machine, the same offsets):
    every deviation's cycles of both, every setup's outcome, every stop's scatter.
    Each cycle's deviation is referenced to its own bracketing Π0 stops, so cycles
    of another mounting join without a common zero."""
    keys = list(first.deviations) + [k for k in more.deviations if k not in first.deviations]
    axes = list(first.reversal) + [a for a in more.reversal if a not in first.reversal]
    return Measurement(
        first.phase,
        {k: [*first.deviations.get(k, []), *more.deviations.get(k, [])] for k in keys},
        [*first.setups, *more.setups], [*first.within_std, *more.within_std],
        {a: [*first.reversal.get(a, []), *more.reversal.get(a, [])] for a in axes},
        {k: _joined_mounts(_mounts(first, k), _mounts(more, k), k in more.continued)
         for k in keys})


def _joined_mounts(first: list[int], more: list[int], continued: bool) -> list[int]:
    """A key's cycles per mounting over two passes; ``continued``: the second's first
    mounting is the first's last, kept on."""
    if continued and first and more:
        return [*first[:-1], first[-1] + more[0], *more[1:]]
    return [*first, *more]


def _mounts(m: Measurement, key: str) -> list[int]:
    """``key``'s cycles of each mounting in ``m`` (one mounting unless it says)."""
    if key not in m.deviations:
        return []
    return list(m.mounts.get(key) or [len(m.deviations[key])])
