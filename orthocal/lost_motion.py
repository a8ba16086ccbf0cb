"""Lost motion (reversal): what a joint's dead band does to the readings, how the
station measures it, and the Δρ it states (docs/model.md, "Lost motion (reversal)";
ISO 230-2's reversal value B).

A joint follows its counted position ρ_i through a dead band of width B_i: after
a move up its carriage sits at ρ_i − B_i/2 of the band's middle, after a move down
at ρ_i + B_i/2. Every stop whose readings enter an identification is approached
by every joint from one side (``approach``); the deviations are then those of a
machine whose joints all sit B/2 to that side, and the fit finds Δρ at that edge
of the band (below: Δρ − B/2). The station states the middle of the band (ISO
230-2's mean bidirectional position), so a joint is off by −B/2 arriving from
below and +B/2 from above, never by B: :func:`band_middle`.

B is measured at Π0: there leg i of a setup lies along axis i, and a shift δ of
joint j ≠ i moves the end point along j by δ, the middle of leg i by about δ/2
(:func:`reversal_gain`), what the gauge along j sees; a shift of joint i slides
leg i along itself, which no gauge of leg i sees. So reading Π0 approached from
one side and again from the other gives B_j and B_k from the two gauges of each
setup, every cycle (:func:`estimate_reversal`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from orthocal.geometry import AXES, Geometry
from orthocal.identification import Identification
from orthocal.loop import FALSE_ALARM
from orthocal.measurement import leg_reading
from orthocal.noise import coverage_factor
from orthocal.postures import posture

APPROACHES = ("below", "above", "as-planned")


def approach_sign(approach: str) -> int:
    """+1 where the joints arrive from above (they sit B/2 above the band's middle),
    −1 from below, 0 as planned (the paper's order: the joints arrive from either
    side, and no single edge of the band is what a fit finds)."""
    if approach not in APPROACHES:
        raise ValueError(f"approach must be one of {APPROACHES}, got {approach!r}")
    return {"below": -1, "above": 1, "as-planned": 0}[approach]


def reversal_gain(leg: str, direction: str, geometry: Geometry,
                  mount: float | None = None) -> float:
    """∂(reading of the gauge on ``leg`` along ``direction``)/∂q_direction at Π0: how
    much of a shift of joint ``direction`` that gauge sees (≈ 0.5, the gauge at the
    leg's middle; exact model (1), differentiated numerically)."""
    if leg == direction:
        raise ValueError("a gauge of leg i along i sees no joint's shift at Π0")
    j = AXES.index(direction)
    rho0 = posture("0", None, geometry)
    h = 1e-3
    step = np.zeros(3)
    step[j] = h
    up = leg_reading(rho0 + step, leg, direction, geometry, mount=mount)
    down = leg_reading(rho0 - step, leg, direction, geometry, mount=mount)
    return float((up - down) / (2 * h))


@dataclass(frozen=True)
class Reversal:
    """Each joint's reversal value (mm), its standard error and the degrees of
    freedom behind them; ``n`` measurements per joint (None: not measured)."""

    value: dict[str, float | None]
    std_errors: dict[str, float | None]
    dof: float | None
    n: dict[str, int]

    def half(self, axis: str) -> tuple[float, float]:
        """(B/2, its standard error) of joint ``axis`` (0, 0 where not measured)."""
        v, se = self.value.get(axis), self.std_errors.get(axis)
        return (0.0 if v is None else 0.5 * v), (0.0 if se is None else 0.5 * se)


def estimate_reversal(samples: Mapping[str, Sequence[float]],
                      floor_mm: float = 0.0) -> Reversal:
    """B per joint from its measurements (mm: each the difference of one gauge's Π0
    readings approached from the two sides, over :func:`reversal_gain`): their mean,
    the standard error from their scatter pooled over the joints (the same gauges,
    the same kind of stop), floored at ``floor_mm`` per measurement (the gauges'
    quantisation: noise-free readings do not scatter), on N − (joints) dof."""
    values: dict[str, float | None] = {}
    n: dict[str, int] = {}
    squares, dof = 0.0, 0
    for axis in AXES:
        data = np.asarray(samples.get(axis, ()), dtype=float)
        n[axis] = int(data.size)
        if data.size == 0:
            values[axis] = None
            continue
        values[axis] = float(data.mean())
        squares += float(np.sum((data - data.mean()) ** 2))
        dof += int(data.size) - 1
    sigma = math.sqrt(squares / dof) if dof > 0 else math.nan
    if not math.isfinite(sigma) or sigma < floor_mm:
        sigma = floor_mm if dof > 0 or floor_mm > 0 else math.nan
    ses = {a: (None if values[a] is None or not math.isfinite(sigma)
               else sigma / math.sqrt(n[a])) for a in AXES}
    return Reversal(values, ses, float(dof) if dof > 0 else None, n)


def band_middle(ident: Identification, reversal: Reversal, approach: str) -> Identification:
    """``ident`` (a fit of deviations taken with every stop approached from one side:
    its Δρ is that edge of the band) with Δρ at the middle of each joint's band: Δρ −
    sign·B/2 (below: + B/2), the variance of B/2 added to each Δρ's. The degrees of
    freedom combine both (Welch–Satterthwaite). As planned, nothing is shifted (no
    one edge was measured); without Δρ in the model, nothing either."""
    sign = approach_sign(approach)
    names = list(ident.names)
    if sign == 0 or not any(f"drho_{a}" in names for a in AXES):
        return ident
    params = dict(ident.parameters)
    cov = np.array(ident.covariance, dtype=float)
    fit_var, b_var = [], []
    for a in AXES:
        name = f"drho_{a}"
        if name not in names:
            continue
        half, half_se = reversal.half(a)
        params[name] = float(params[name]) - sign * half
        k = names.index(name)
        fit_var.append(float(cov[k, k]))
        b_var.append(half_se**2)
        cov[k, k] += half_se**2
    se = {n: (float(math.sqrt(cov[k, k])) if math.isfinite(cov[k, k]) else ident.std_errors[n])
          for k, n in enumerate(names)}
    d = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    corr = cov / np.outer(d, d)
    return replace(ident, parameters=params, std_errors=se, covariance=cov,
                   correlation=corr, se_dof=_welch(fit_var, ident.std_error_dof, b_var,
                                                   reversal.dof))


def edge_of(reversal: Reversal, approach: str) -> dict[str, float]:
    """Where the one approach leaves each joint against the middle of its band (mm, by
    Δρ name): +B/2 from above, −B/2 from below, 0 as planned (no one side)."""
    sign = approach_sign(approach)
    return {f"drho_{a}": sign * reversal.half(a)[0] for a in AXES}


def _welch(a: Sequence[float], nu_a: float | None, b: Sequence[float],
           nu_b: float | None) -> float | None:
    """Welch–Satterthwaite dof of the sums a + b (the worst over the parameters)."""
    out: list[float] = []
    for va, vb in zip(a, b, strict=True):
        if vb <= 0:
            out.append(math.inf if nu_a is None else nu_a)
            continue
        if nu_a is None or nu_b is None:
            return nu_a if nu_b is None else nu_b
        out.append((va + vb) ** 2 / (va**2 / nu_a + vb**2 / nu_b))
    worst = min(out) if out else None
    return None if worst is None or not math.isfinite(worst) else float(worst)


def tool_reversal_mm(jacobians: np.ndarray, reversal: Mapping[str, float | None]) -> float:
    """The largest tool-point error B/2 per joint can add where the side a point is
    reached from is not known: max over the points (``jacobians``, (n, 3, 3): ∂P/∂q
    at each) and the sides (each joint ±B/2) of |J·δ| (mm)."""
    half = np.array([0.5 * (reversal.get(a) or 0.0) for a in AXES])
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    shifts = signs * half  # (8, 3)
    moved = np.einsum("nij,sj->nsi", np.asarray(jacobians, dtype=float), shifts)
    return float(np.max(np.linalg.norm(moved, axis=-1))) if moved.size else 0.0


def standing_out(value: Mapping[str, float | None], std_errors: Mapping[str, float | None],
                 dof: float | None) -> dict[str, float]:
    """The joints whose reversal stands out of its noise by the station's rule for every
    "act" (docs/design.md, "The decision table"): beyond k_act standard errors, k_act
    from Student's t on ``dof`` for orthocal.loop.FALSE_ALARM. A reversal is a play and never
    negative: a value at or below zero, one not beyond k_act, or one without a standard
    error is nothing to compensate."""
    k = coverage_factor(dof, 1.0 - FALSE_ALARM)
    out = {}
    for axis, v in value.items():
        se = std_errors.get(axis)
        if v is not None and se is not None and v - k * se > 0.0:
            out[axis] = v
    return out
