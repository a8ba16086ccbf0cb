"""Indicator stands as nuisance parameters (docs/model.md, "Where the
indicator plane is").

The operator sets each dial-indicator stand "at the middle of the leg" by eye:
the gauge of leg i along j reads in the base-fixed plane x_i = L/2 + m, m
millimetres off (``stand_ij``, mm from L/2). A deviation depends on m only
through the product (stand error × change of the leg's slope between Π0 and
Π_i^s), and the legs slope because of the offsets Δρ: on a square machine with
offsets of 1–2 mm, stands ±5 mm off leave several µm that a model without them
reads as tilt. So the stands enter the model, as random effects:

- each stand m_s has the prior N(0, σ_M²), σ_M = tolerance/√3 (a placement
  uniform within ±tolerance of L/2, the station's knowledge: :class:`Stands`);
- the deviations are exactly linear in m (the reading is
  A_j + (A_i − M)/(A_i − p_i)·(p_j − A_j), and M moves neither A nor P), so
  the stand's column ∂Δ/∂m = Δ(m = 1) − Δ(m = 0) is exact, computed from the
  exact model (:func:`orthocal.measurement.deviations` with ``mount_offsets``)
  at the current Δρ, tilts;
- identification minimises Σ r²/σ² + Σ m²/σ_M² (the model's parameters by
  least squares, the stands by their posterior mean, the BLUP), and the lack of
  fit is the generalised residual of the deviations whose covariance carries
  J_M·Σ_M·J_Mᵀ beside the noise (orthocal.selection).

With Δρ ≈ 0 a stand's column vanishes: it changes no deviation, the data say
nothing about it and its estimate stays the prior; it is then reported as not
observable (:data:`OBSERVABLE_RATIO`), and it costs nothing.

Pure functions, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from orthocal.geometry import AXIS_INDEX, Geometry
from orthocal.measurement import Key, deviations
from orthocal.postures import MIDDLE, split_plane

Gauge = tuple[str, str]  # (leg i, direction j): one dial indicator
GAUGES: tuple[Gauge, ...] = tuple((i, j) for i in "xyz" for j in "xyz" if i != j)
#: The operator's "middle of the leg by eye": ±5 mm.
DEFAULT_TOLERANCE = 5.0
#: A stand counts as observable when the data, not the prior, place it: its
#: posterior SD at most the prior's/√2, i.e. the deviations alone would place it
#: within its prior SD. Otherwise it is reported as not observable.
OBSERVABLE_RATIO = 1.0 / math.sqrt(2.0)


def stand_name(leg: str, direction: str) -> str:
    """The default name of the stand of the gauge of leg ``leg`` along ``direction``:
    ``stand_xy`` is the stand of the gauge on leg x measuring along y."""
    return f"stand_{leg}{direction}"


@dataclass(frozen=True)
class Stands:
    """What the station knows of its indicator stands (the option ``stands=`` of
    :func:`orthocal.identify` and :func:`orthocal.select_model`).

    ``tolerance``: mm; each stand lies within ±tolerance of L/2, uniformly (prior
    SD tolerance/√3). ``groups``: which gauges share a stand, gauge (leg,
    direction) → stand name; gauges not named have their own stand,
    ``stand_<leg><direction>`` (the default: one stand per gauge, i.e. per (leg,
    direction) pair of deviation keys). A stand holds gauges of one leg only: its
    plane is x_leg = M. ``mounts``: where a key's rows come from more than one
    mounting (a verification's further passes take the gauges off and set them
    again by eye), the number of its rows (cycles) of each mounting, in row
    order; each mounting is a stand of its own (``stand_xy@2``, …), so the
    stands' errors average over the mountings as the noise does over cycles.
    Keys not named: one mounting.
    """

    tolerance: float = DEFAULT_TOLERANCE
    groups: Mapping[Gauge, str] | None = field(default=None, hash=False)
    mounts: Mapping[Key, tuple[int, ...]] | None = field(default=None, hash=False)

    def __post_init__(self) -> None:
        if not (isinstance(self.tolerance, int | float) and math.isfinite(self.tolerance)
                and self.tolerance > 0):
            raise ValueError(f"stand tolerance must be a positive number of mm, "
                             f"got {self.tolerance!r}")
        legs: dict[str, str] = {}
        for gauge, name in (self.groups or {}).items():
            if not (isinstance(gauge, tuple) and len(gauge) == 2 and gauge[0] in AXIS_INDEX
                    and gauge[1] in AXIS_INDEX and gauge[0] != gauge[1]):
                raise ValueError(f"a gauge is (leg, direction), two different axes, "
                                 f"got {gauge!r}")
            if not (isinstance(name, str) and name):
                raise ValueError(f"stand name of gauge {gauge!r} must be a non-empty string")
            if legs.setdefault(name, gauge[0]) != gauge[0]:
                raise ValueError(f"stand {name!r} holds gauges of legs {legs[name]} and "
                                 f"{gauge[0]}: a stand's plane x_i = M belongs to one leg")

    @property
    def prior_sd(self) -> float:
        """SD of a stand's position, mm: uniform within ±tolerance."""
        return self.tolerance / math.sqrt(3.0)

    def stand_of(self, leg: str, direction: str) -> str:
        """The name of the stand holding the gauge of ``leg`` along ``direction``."""
        return (self.groups or {}).get((leg, direction)) or stand_name(leg, direction)

    def mounting_of(self, key: Key, row: int) -> int:
        """Which mounting (0: the first) the ``row``-th row of ``key`` was read in."""
        # tuple(): a key may come as a list; mypy types tuple() of it as of any length
        counts = (self.mounts or {}).get(tuple(key))  # type: ignore[arg-type]
        if not counts:
            return 0
        return min(int(np.searchsorted(np.cumsum(counts), row, side="right")), len(counts) - 1)

    def to_dict(self) -> dict[str, Any]:
        groups: dict[str, list[str]] = {}
        for leg, direction in GAUGES:
            groups.setdefault(self.stand_of(leg, direction), []).append(leg + direction)
        return {"tolerance_mm": float(self.tolerance), "prior_sd_mm": self.prior_sd,
                "groups": groups}


def row_stands(keys: Sequence[Key], stands: Stands) -> list[str]:
    """The name of the stand each row of ``keys`` was read on: its gauge's stand (in
    a second gauge plane another stand, ``stand_xy~0.75``: another mounting), and
    for a key's later mountings (``stands.mounts``) a stand of their own (``@2``, …)."""
    seen: dict[Key, int] = {}
    out = []
    for k in keys:
        row = seen[k] = seen.get(k, -1) + 1
        mounting = stands.mounting_of(k, row)
        at = split_plane(k[0])[1]
        out.append(stands.stand_of(k[1], k[2]) + ("" if at == MIDDLE else f"~{at:g}")
                   + (f"@{mounting + 1}" if mounting else ""))
    return out


def incidence(keys: Sequence[Key], stands: Stands) -> tuple[tuple[str, ...], np.ndarray]:
    """(stand names in order of first appearance, S) with S[r, s] = 1 when row
    ``keys[r]`` is read by a gauge on stand s (:func:`row_stands`): its plane offset
    is (S·m)[r]."""
    names: dict[str, int] = {}
    cols = [names.setdefault(name, len(names)) for name in row_stands(keys, stands)]
    S = np.zeros((len(keys), len(names)))
    S[np.arange(len(keys)), cols] = 1.0
    return tuple(names), S


def stand_gauges(names: Sequence[str], stands: Stands,
                 keys: Sequence[Key] = ()) -> dict[str, tuple[Gauge, ...]]:
    """The gauges behind each stand name (those of the rows ``keys`` first, in row
    order)."""
    out: dict[str, list[Gauge]] = {n: [] for n in names}
    for k, name in zip(keys, row_stands(keys, stands), strict=True):
        g = (k[1], k[2])
        if name in out and g not in out[name]:
            out[name].append(g)
    return {n: tuple(v) for n, v in out.items()}


def stand_jacobian(keys: Sequence[Key], geometry: Geometry, params, S: np.ndarray) -> np.ndarray:
    """∂Δ/∂m of each row (columns the stands of ``S``, mm per mm), exact: the
    deviations are linear in the plane offset (module docstring), so the column
    is Δ(offset 1) − Δ(offset 0) of the exact model at ``params`` (9-vector)."""
    if len(keys) == 0:
        return np.zeros((0, S.shape[1]))
    n = len(keys)
    per_row = (deviations(keys, geometry, params, np.ones(n))
               - deviations(keys, geometry, params, np.zeros(n)))
    return per_row[:, None] * S


def prior_penalty(sigma: float, stands: Stands, n_stands: int) -> np.ndarray:
    """Λ of the stand block: σ²/σ_M² on its diagonal (the prior's weight against
    rows of noise σ), as the matrix added to JᵀJ of the stands."""
    return np.eye(n_stands) * (sigma / stands.prior_sd) ** 2


def ridge_covariance(A: np.ndarray, n_params: int, penalty: np.ndarray, noise_cov: np.ndarray,
                     prior_var: float) -> np.ndarray:
    """Covariance of the error of x̂ = (AᵀA + Λ)⁻¹Aᵀy, x = (θ, m), when
    y = A·x + e, e ~ (0, ``noise_cov``) and each stand m ~ (0, ``prior_var``):
    B·(Aᵀ·Cov(e)·A + Λ·Σ_m·Λ)·B with B = (AᵀA + Λ)⁻¹, Λ = ``penalty`` on the
    stand block (the first ``n_params`` columns are the model's parameters,
    without prior). With Cov(e) = σ²·I and Λ = σ²/σ_M² this is σ²·B, the
    posterior covariance; with correlated noise it is the honest sandwich."""
    p = A.shape[1]
    lam = np.zeros((p, p))
    lam[n_params:, n_params:] = penalty
    B = np.linalg.inv(A.T @ A + lam)
    prior = np.zeros((p, p))
    prior[n_params:, n_params:] = prior_var * np.eye(p - n_params)
    return B @ (A.T @ noise_cov @ A + lam @ prior @ lam) @ B


@dataclass(frozen=True)
class StandEstimate:
    """One stand's position as identified: ``offset`` mm off L/2 (posterior mean),
    ``std_error`` its posterior SD, ``observable`` False when the data leave the
    prior almost as it was (:data:`OBSERVABLE_RATIO`): the offsets were too small
    for this stand to change the deviations; its ``offset`` is then ≈ 0 and says
    nothing."""

    name: str
    gauges: tuple[Gauge, ...]
    offset: float
    std_error: float
    prior_sd: float
    observable: bool

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"gauges": ["".join(g) for g in self.gauges],
                               "observable": self.observable, "prior_sd_mm": self.prior_sd}
        if self.observable:
            out.update(offset_mm=float(self.offset), std_error_mm=float(self.std_error))
        else:
            out.update(offset_mm=None, std_error_mm=None,
                       note="not observable: the offsets Δρ are too small for this stand "
                            "to change the deviations")
        return out

    def describe(self) -> str:
        if self.observable:
            return f"{self.name} {self.offset:+.2f} ± {self.std_error:.2f} mm"
        return f"{self.name} not observable"


def stand_estimates(names: Sequence[str], gauges: Mapping[str, tuple[Gauge, ...]],
                    offsets: np.ndarray, covariance: np.ndarray,
                    stands: Stands) -> dict[str, StandEstimate]:
    """:class:`StandEstimate` of each stand from its posterior mean and the stand
    block of the posterior covariance."""
    sd = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    return {n: StandEstimate(n, tuple(gauges.get(n, ())), float(offsets[s]), float(sd[s]),
                             stands.prior_sd, bool(sd[s] <= OBSERVABLE_RATIO * stands.prior_sd))
            for s, n in enumerate(names)}


def describe_stands(estimates: Mapping[str, StandEstimate], stands: Stands) -> str:
    """One phrase for a report's reason: what was modelled and what came out."""
    seen = [e.describe() for e in estimates.values() if e.observable]
    unseen = [e.name for e in estimates.values() if not e.observable]
    text = (f"indicator stands modelled ({len(estimates)} stand(s) within ±{stands.tolerance:g} mm "
            f"of L/2, prior SD {stands.prior_sd:.2f} mm)")
    if seen:
        text += ": " + ", ".join(seen)
    if unseen:
        text += ("; " if seen else ": ") + "not observable (offsets too small to show them): " \
            + ", ".join(unseen)
    return text
