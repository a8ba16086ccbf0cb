"""The station's own test of a joint's positioning error against a length reference
(docs/model.md, "The station's own joint test"): where its targets go, what the gauge
on the carriage reads at each, and the table (:class:`orthocal.JointTable`) with its
expanded uncertainty that the readings give. Pure.

The set-up: a length reference on the base, parallel to axis i, with faces at
calibrated distances f_k from its datum face f_0; a dial indicator clamped to
carriage i, its plunger along the axis, pointing toward lower ρ (plunger s = −1,
"-") or higher ρ (s = +1, "+"). Face k stands on the plunger's side, further from
the gauge than the datum face by f_k − f_0:

    F_k = F_0 − s·(f_k − f_0)                                                      (J8)

A reading is the plunger's push-in, r = s·(x − F) + c, x the carriage's true position
(x = ρ + Δρ + ε(ρ, dir), up to a constant). Target k is the null of face k: the joint
commanded where face k stands at the plunger as face 0 stood at the datum,

    ρ_k = ρ_0 − s·(f_k − f_0)                                                      (J9)

where the gauge reads, relative to the datum,

    r_k − r_0 = s·[(ρ_k − ρ_0) + ε_k − ε_0] + (f_k − f_0)  =  s·(ε_k − ε_0)          (J10)

and the deviation found at target k, whatever was commanded there, is

    ε_k − ε_0 = s·[(r_k − r_0) − (f_k − f_0)] − (ρ_k − ρ_0)                          (J11)

The datum is read first and again last; a linear drift of the reading between the two
(the stand warming, the reference's temperature) is taken out in the order the targets
were read (J12). Lengths in mm.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from orthocal.budget import MPE_SPAN_MM
from orthocal.joint_error import JointTable

#: The plunger's way along the joint: "-" toward lower ρ, "+" toward higher ρ.
PLUNGERS: dict[str, int] = {"-": -1, "+": 1}
#: The temperature a reference's calibration refers to (ISO 1), °C.
REFERENCE_TEMPERATURE_C = 20.0
# An irregular pattern (the golden ratio's fractional parts) for the targets' offsets:
# fixed, so that a plan and its resume place the targets alike.
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def plunger_sign(plunger: str | int) -> int:
    """s of (J8): −1 for "-" (toward lower ρ), +1 for "+"."""
    if isinstance(plunger, str):
        if plunger not in PLUNGERS:
            raise ValueError(f"plunger must be '-' or '+', got {plunger!r}")
        return PLUNGERS[plunger]
    if plunger not in (-1, 1):
        raise ValueError(f"plunger must be -1 or +1, got {plunger!r}")
    return int(plunger)


def iso_targets(lo_mm: float, hi_mm: float, count: int) -> np.ndarray:
    """``count`` targets from ``lo_mm`` to ``hi_mm``, both ends exact, the others off the
    even spacing p by an irregular r_k within ±p/4 (ISO 230-2: targets P_k = k·p + r_k,
    r_k different at each, so that a periodic error of the screw is not met at one
    phase at every target, where its period divides p, and taken for none)."""
    if count < 2:
        raise ValueError(f"a test needs at least two targets, got {count}")
    if not (math.isfinite(lo_mm) and math.isfinite(hi_mm) and lo_mm < hi_mm):
        raise ValueError(f"targets need lo < hi, got [{lo_mm}, {hi_mm}]")
    p = (hi_mm - lo_mm) / (count - 1)
    k = np.arange(count, dtype=float)
    r = 0.5 * p * (np.mod(k * _GOLDEN, 1.0) - 0.5)
    r[0] = r[-1] = 0.0
    return lo_mm + k * p + r


def null_targets(datum_mm: float, faces_mm: Sequence[float], plunger: str | int
                 ) -> np.ndarray:
    """ρ_k of (J9): the joint where each face stands at the plunger as face 0 (the
    first) stood at the datum ρ_0 = ``datum_mm``."""
    s = plunger_sign(plunger)
    f = np.asarray(faces_mm, dtype=float)
    return float(datum_mm) - s * (f - f[0])


def reference_lengths(faces_mm: Sequence[float], alpha_per_k: float,
                      temperature_c: float = REFERENCE_TEMPERATURE_C) -> np.ndarray:
    """The faces' distances at ``temperature_c``: f·(1 + α·(T − 20 °C)), their calibration
    being at 20 °C (the machine's joints are tested as they stand, at T)."""
    return np.asarray(faces_mm, dtype=float) * (
        1.0 + alpha_per_k * (temperature_c - REFERENCE_TEMPERATURE_C))


def gauge_readings(targets_mm: Sequence[float], faces_mm: Sequence[float],
                   plunger: str | int, forward_error_mm: Sequence[float],
                   reverse_error_mm: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """What the gauge reads at each target approached in +ρ and in −ρ, relative to its
    reading at the datum (the first target) in the middle of the two (J10):
    s·[(ρ_k − ρ_0) + ε_k − ε̄_0] + (f_k − f_0), ε the joint's error at the target from
    each side (``forward_error_mm``, ``reverse_error_mm``: a screw's and its lost
    motion's, docs/model.md (J1), (J2)), ε̄_0 their mean at the datum."""
    s = plunger_sign(plunger)
    t, f = np.asarray(targets_mm, dtype=float), np.asarray(faces_mm, dtype=float)
    ef, er = np.asarray(forward_error_mm, dtype=float), np.asarray(reverse_error_mm, dtype=float)
    mid = 0.5 * (ef[0] + er[0])
    base = s * (t - t[0]) + (f - f[0])
    return base + s * (ef - mid), base + s * (er - mid)


@dataclass(frozen=True, eq=False)
class StationTable:
    """What a station's test of one joint found: ``table`` (targets ascending, the
    deviations from both sides relative to the datum's, u95 per target), the standard
    uncertainties it combines per target (``parts``: name → mm, in the table's order),
    the datum's drift over the test (``drift_mm``: closing less opening), the
    repeatability (``noise_mm``, a single approach's standard deviation, on
    ``noise_dof``) and the sides taken from a neighbour's reversal (``inferred``:
    (target mm, "forward" | "reverse"), where the soft limits leave no room to
    approach from that side)."""

    table: JointTable
    parts: dict[str, np.ndarray]
    drift_mm: float
    noise_mm: float
    noise_dof: int
    inferred: tuple[tuple[float, str], ...]


def _means(values: np.ndarray) -> np.ndarray:
    """Each row's mean over its finite entries (NaN where none)."""
    finite = np.isfinite(values)
    counts = finite.sum(axis=1)
    sums = np.where(finite, values, 0.0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def _pooled(groups: Sequence[np.ndarray]) -> tuple[float, int]:
    """The pooled standard deviation of the approaches about their group means, and
    its degrees of freedom (groups of one add none)."""
    ss, dof = 0.0, 0
    for g in groups:
        g = g[np.isfinite(g)]
        if g.size > 1:
            ss += float(np.sum((g - g.mean()) ** 2))
            dof += g.size - 1
    return (math.sqrt(ss / dof) if dof else 0.0), dof


def _fill_sides(targets: np.ndarray, fwd: np.ndarray, rev: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, tuple[tuple[float, str], ...]]:
    """A side a target was not approached from: its other side plus (or less) the
    reversal at the nearest target approached from both."""
    both = np.flatnonzero(np.isfinite(fwd) & np.isfinite(rev))
    fwd, rev = fwd.copy(), rev.copy()
    inferred: list[tuple[float, str]] = []
    for k in range(targets.size):
        if np.isfinite(fwd[k]) and np.isfinite(rev[k]):
            continue
        if not (np.isfinite(fwd[k]) or np.isfinite(rev[k])):
            raise ValueError(f"target {targets[k]:.3f} mm was approached from neither side")
        if both.size == 0:
            raise ValueError("no target was approached from both sides: no reversal")
        j = both[np.argmin(np.abs(targets[both] - targets[k]))]
        reversal = fwd[j] - rev[j]
        if np.isfinite(fwd[k]):
            rev[k] = fwd[k] - reversal
            inferred.append((float(targets[k]), "reverse"))
        else:
            fwd[k] = rev[k] + reversal
            inferred.append((float(targets[k]), "forward"))
    return fwd, rev, tuple(inferred)


def station_table(targets_mm: Sequence[float], faces_mm: Sequence[float] | np.ndarray,
                  plunger: str | int, forward_mm, reverse_mm,
                  closing_forward_mm: Sequence[float], closing_reverse_mm: Sequence[float],
                  *, reference_u95_mm: Sequence[float] | float, mpe_mm: float,
                  alpha_per_k: float, temperature_change_k: float,
                  positions_mm: Sequence[float] | None = None) -> StationTable:
    """The table of one joint's test (J11)–(J13).

    ``targets_mm`` (n,): the targets as commanded, in the order read, the datum first;
    ``faces_mm`` (n,): the faces set at them (their distances at the test's temperature,
    :func:`reference_lengths`); ``forward_mm``/``reverse_mm`` (n, R): each approach's
    mean reading from below / from above (NaN: not approached from that side);
    ``closing_*`` (R,): the datum's, read again last. The drift line (J12)

        D(k) = D_open + (D_close − D_open)·k/n

    through the datum's means (its sides read both times) is each target's r_0 in
    (J11). The expanded uncertainty (J13) per target is 2·sqrt(Σ u²) of: the
    reference's calibration, ``reference_u95_mm`` (of each face from the datum: one
    value, or one per face) / 2; the gauge, ``mpe_mm`` over the reading's span from
    the datum (in proportion below 0.2 mm, as the run's budget reads an MPE),
    rectangular; the reference's temperature, α·ΔT·|f_k − f_0|, rectangular, ΔT =
    ``temperature_change_k`` (the reference against the joint's own steel at the test's
    temperature); the noise, the pooled scatter of the approaches over the target's own
    and the datum line's."""
    s = plunger_sign(plunger)
    t, f = np.asarray(targets_mm, dtype=float), np.asarray(faces_mm, dtype=float)
    fwd_all = np.atleast_2d(np.asarray(forward_mm, dtype=float))
    rev_all = np.atleast_2d(np.asarray(reverse_mm, dtype=float))
    close_f = np.asarray(closing_forward_mm, dtype=float).reshape(-1)
    close_r = np.asarray(closing_reverse_mm, dtype=float).reshape(-1)
    n = t.size
    if f.shape != (n,) or fwd_all.shape[0] != n or rev_all.shape[0] != n:
        raise ValueError(f"one face and one row of approaches per target ({n})")
    rho = t if positions_mm is None else np.asarray(positions_mm, dtype=float)
    m_f, m_r = _means(fwd_all), _means(rev_all)
    open_sides = [float(m_f[0]), float(m_r[0])]
    shut_sides = [float(np.nanmean(c)) if np.isfinite(c).any() else math.nan
                  for c in (close_f, close_r)]
    used = [i for i in (0, 1) if math.isfinite(open_sides[i]) and math.isfinite(shut_sides[i])]
    if not used:
        raise ValueError("the datum was not read from one side at both its visits")
    d_open = float(np.mean([open_sides[i] for i in used]))
    d_shut = float(np.mean([shut_sides[i] for i in used]))
    w = np.arange(n, dtype=float) / n
    line = d_open + (d_shut - d_open) * w  # (J12)
    dev_f = s * ((m_f - line) - (f - f[0])) - (rho - rho[0])  # (J11)
    dev_r = s * ((m_r - line) - (f - f[0])) - (rho - rho[0])
    dev_f, dev_r, inferred = _fill_sides(t, dev_f, dev_r)
    groups = [*fwd_all, *rev_all, close_f, close_r]
    noise, dof = _pooled(groups)
    counts = np.isfinite(fwd_all).sum(axis=1) + np.isfinite(rev_all).sum(axis=1)
    datum_count = sum(int(np.isfinite((close_f, close_r)[i]).sum()) for i in used)
    var_line = ((1.0 - w) ** 2 + w**2) * noise**2 / max(datum_count, 1)
    u_noise = np.sqrt(noise**2 / np.maximum(counts, 1) + var_line)
    span = np.fmax(np.abs(m_f - line), np.abs(m_r - line))
    u_gauge = mpe_mm * np.minimum(1.0, np.nan_to_num(span) / MPE_SPAN_MM) / math.sqrt(3.0)
    u_ref = np.broadcast_to(np.asarray(reference_u95_mm, dtype=float), (n,)) / 2.0
    u_ref = np.where(np.arange(n) == 0, 0.0, u_ref)
    u_temp = alpha_per_k * temperature_change_k * np.abs(f - f[0]) / math.sqrt(3.0)
    parts = {"reference": u_ref, "gauge": u_gauge, "temperature": u_temp, "noise": u_noise}
    u95 = 2.0 * np.sqrt(sum(p**2 for p in parts.values()))  # (J13)
    order = np.argsort(t)
    table = JointTable(t[order], dev_f[order], dev_r[order], u95[order])
    return StationTable(table, {k: np.asarray(v, dtype=float)[order] for k, v in parts.items()},
                        d_shut - d_open, noise, dof, inferred)
