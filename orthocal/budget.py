"""The uncertainty budget of an identification: Type B inputs propagated through
the identification's own sensitivity and combined with its Type A part (GUM,
JCGM 100:2008; docs/design.md, "Uncertainty budget").

At the solution the identification is, to first order, linear in the data:
δθ = K·δΔ (:func:`sensitivity`; GUM 5.1.3, the sensitivity coefficients as a
matrix). Each Type B source states the covariance Σ_s it puts on the distinct
deviations (systematic: the same error in every cycle of a deviation, so not
divided by the number of cycles) and contributes u_s(θ_p) = sqrt((K·Σ_s·Kᵀ)_pp)
(GUM 5.2, correlated inputs). Sources independent of one another and of the
Type A part combine in quadrature (GUM 5.1.2), with Welch–Satterthwaite's
effective dof, Type B at ∞ (GUM G.4.1), and U = k·u_c, k from Student's t (G.3).
The sources (:func:`budget_sources`): leg straightness (each gauge plane bowed,
:func:`form_vector`), gauge MPE, gauge resolution, plunger angle (cosine error)
and a temperature step; each builder's docstring gives its model.

Pure functions, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar

import numpy as np

from orthocal.field_mc import Bounded
from orthocal.geometry import AXES, Geometry, split_params
from orthocal.identification import Identification
from orthocal.measurement import Key, bow_at, contact_fraction, deviations, row_planes
from orthocal.noise import coverage_factor
from orthocal.numbers import finite
from orthocal.postures import posture
from orthocal.sensitivities import (
    key_sensitivity,
    rows_of,
)

K = TypeVar("K")
Gauge = tuple[str, str]  # (leg i, direction j): one dial indicator, one gauge plane
#: Linear expansion of steel, 1/K.
STEEL_ALPHA = 11.5e-6
#: The travel over which a gauge's MPE is stated (mm): about what a first round's
#: deviations span ("the few tenths of a millimetre a deviation spans").
MPE_SPAN_MM = 0.2
#: The coverage probability of ``expanded_95_mm``.
COVERAGE = 0.95


# --- the form of the legs ----------------------------------------------------------------


def form_vector(keys: Sequence[Key], geometry: Geometry, params=None,
                mount_offsets=None) -> np.ndarray:
    """g_k per deviation key: the change of the deviation per unit sagitta of its
    gauge plane, g_k = w(t_k) − w(t_0) with w(t) = 4·t(1 − t)
    (orthocal.measurement.bow_at), t_k the contact fraction at the key's test
    posture Π_i^s and t_0 at Π0, both exact (orthocal.measurement.contact_fraction)
    at ``params`` (9- or 6-vector, None: nominal) in each key's plane (L/2, or
    its posture's second plane) plus ``mount_offsets`` (one per key, None: 0). A
    bow of sagitta h in that plane changes the deviation by exactly h·g_k (the
    fractions do not depend on h);
    nominally g = −4·(s/L)², −0.150 at Π^+ and −0.416 at Π^− on the paper's machine."""
    drho, dL, tilt, gap = split_params(params)
    offsets = np.zeros(len(keys)) if mount_offsets is None else \
        np.asarray(mount_offsets, dtype=float).reshape(-1)
    if offsets.shape != (len(keys),):
        raise ValueError(f"mount_offsets needs one value per key ({len(keys)}), "
                         f"got shape {np.shape(mount_offsets)}")
    rho_0 = posture("0", None, geometry)
    g = np.empty(len(keys))
    planes = row_planes(keys, geometry, offsets)
    for n, (sign, leg, _) in enumerate(keys):
        m = planes[n]
        t_k = contact_fraction(posture(sign, leg, geometry), leg, geometry, drho, dL, m, tilt,
                               gap)
        t_0 = contact_fraction(rho_0, leg, geometry, drho, dL, m, tilt, gap)
        g[n] = float(bow_at(t_k, 1.0) - bow_at(t_0, 1.0))
    return g


def sagitta_from_straightness(straightness: float, span: float) -> float:
    """The sagitta h over the whole leg of the bow w = 4h·t(1 − t) that deviates by
    ``straightness`` from its chord over a fraction ``span`` of the leg: h =
    straightness/span². The plunger slides over span ≈ (ρmax − ρmin)/L = 0.516
    of the paper's legs: a straightness over that slide is a 3.76 times larger h."""
    if not (0.0 < span <= 1.0):
        raise ValueError(f"span must be a fraction of the leg in (0, 1], got {span!r}")
    return float(straightness) / span**2


# --- sources ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Propagation:
    """What every source is propagated with (:func:`propagation`): the parameters'
    ``names``, the distinct deviation ``keys``, the sensitivity ``K`` to their
    systematic errors (n_params × n_keys), the identified ``params`` (9-vector),
    each key's plane offset off L/2 (``mount_offsets``), the ``measured``
    deviations (the mean of each key's cycles) and the ``geometry``."""

    names: tuple[str, ...]
    keys: tuple[Key, ...]
    K: np.ndarray
    params: np.ndarray
    mount_offsets: np.ndarray
    measured: np.ndarray
    geometry: Geometry

    def contributions(self, covariance: np.ndarray) -> dict[str, float]:
        """u(θ_p) = sqrt((K·Σ·Kᵀ)_pp) of a deviation covariance Σ (GUM 5.2.2)."""
        var = np.einsum("pk,kl,pl->p", self.K, covariance, self.K)
        return {n: float(math.sqrt(max(v, 0.0))) for n, v in zip(self.names, var, strict=True)}

    def mask(self, gauge: Gauge) -> np.ndarray:
        """1.0 on the keys of ``gauge`` (leg, direction), else 0."""
        return np.array([float((k[1], k[2]) == gauge) for k in self.keys])

    @property
    def gauges(self) -> list[Gauge]:
        """The gauges measured, in the order their keys first appear."""
        return list(dict.fromkeys((k[1], k[2]) for k in self.keys))


def propagation(ident: Identification, geometry: Geometry | None = None) -> Propagation:
    """:class:`Propagation` of an identification (``geometry`` as for :func:`sensitivity`)."""
    geometry = geometry or Geometry()
    keys = list(ident.keys)
    distinct, K = key_sensitivity(ident, geometry)
    P = rows_of(keys, distinct)
    offsets = np.zeros(len(keys)) if ident.mount_offsets is None else ident.mount_offsets
    return Propagation(names=tuple(ident.names), keys=tuple(distinct), K=K, params=ident.fit_vector,
                       mount_offsets=np.asarray(offsets)[[keys.index(k) for k in distinct]],
                       measured=(P.T @ np.asarray(ident.values)) / P.sum(axis=0),
                       geometry=geometry)


@dataclass(frozen=True)
class Source:
    """One input of the budget: ``value_mm`` the half-width of the error it puts on
    one deviation (None when not a length: see ``inputs``), ``u_mm`` its standard
    uncertainty, ``contributions`` u(θ_p) in mm (GUM 5.1.3, 5.2.2), ``dof`` ∞ for
    Type B (GUM G.4.2), ``covariance`` the one it puts on the distinct deviations
    ``keys`` (mm²; for :func:`expected_lack_of_fit`)."""

    name: str
    distribution: str
    value_mm: float | None
    u_mm: float | None
    contributions: dict[str, float]
    type: str = "B"
    dof: float = math.inf
    inputs: dict[str, float] = field(default_factory=dict)
    keys: tuple[Key, ...] = ()
    covariance: np.ndarray | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict[str, Any]:
        """docs/design.md's ``uncertainty_budget.sources`` entry (JSON-ready)."""
        out: dict[str, Any] = {
            "source": self.name, "type": self.type, "distribution": self.distribution,
            "value_mm": finite(self.value_mm), "u_mm": finite(self.u_mm),
            "contributions_mm": {n: finite(v) for n, v in self.contributions.items()}}
        if self.type == "A":
            out["dof"] = finite(self.dof)
        if self.inputs:
            out["inputs"] = {n: finite(v) for n, v in self.inputs.items()}
        return out


def _source(prop: Propagation, name: str, distribution: str, value: float | None,
            u: float | None, covariance: np.ndarray, **inputs: float) -> Source:
    return Source(name, distribution, value, u, prop.contributions(covariance),
                  inputs=dict(inputs), keys=prop.keys, covariance=covariance)


def non_negative(value: float, what: str) -> float:
    """``value`` as a finite float ≥ 0; ValueError naming ``what``."""
    v = float(value)
    if not (math.isfinite(v) and v >= 0.0):
        raise ValueError(f"{what} must be a finite number ≥ 0, got {value!r}")
    return v


def per_name(value: float | Mapping[K, float], names: Sequence[K], what: str) -> dict[K, float]:
    """One value ≥ 0 per name from a number or a mapping name → number."""
    if not isinstance(value, Mapping):
        return dict.fromkeys(names, non_negative(value, what))
    missing = [n for n in names if n not in value]
    if missing:
        raise ValueError(f"{what}: no value for {missing}")
    return {n: non_negative(value[n], what) for n in names}


def _plane_units(prop: Propagation, straightness
                 ) -> tuple[dict[str, float], dict[Gauge, np.ndarray]]:
    """(each leg's straightness s, each gauge plane's deviations per unit sagitta of
    its bow, g_p: :func:`form_vector` on the plane's keys). ``straightness`` as for
    :func:`straightness_sources`."""
    legs = list(dict.fromkeys(g[0] for g in prop.gauges))
    if isinstance(straightness, Sequence):
        if len(straightness) != len(AXES):
            raise ValueError(f"leg straightness: one value or [x, y, z], got {straightness!r}")
        straightness = dict(zip(AXES, straightness, strict=True))
    s_of = per_name(straightness, legs, "leg straightness")
    g = form_vector(prop.keys, prop.geometry, prop.params, prop.mount_offsets)
    return s_of, {gg: g * prop.mask(gg) for gg in prop.gauges}


def _plane_forms(prop: Propagation, straightness
                 ) -> tuple[dict[str, float], dict[Gauge, np.ndarray]]:
    """(each leg's straightness s, each gauge plane's deviations per one standard
    uncertainty of its bow, g_p·u with u = s/√3). ``straightness`` as for
    :func:`straightness_sources`."""
    s_of, units = _plane_units(prop, straightness)
    return s_of, {gg: g * s_of[gg[0]] / math.sqrt(3.0) for gg, g in units.items()}


def straightness_sources(prop: Propagation, straightness) -> list[Source]:
    """Leg straightness (a), one source: each gauge
    plane (leg, direction) of the leg bowed with a sagitta uniform in ±s
    (u = s/√3); the bow h adds h·g_plane to the plane's deviations
    (:func:`form_vector` restricted to its keys), so the plane contributes
    |K_p·g_plane|·u and the source the sum over every plane (the worst sign: a
    leg's planes see one bow, and the legs of one machine may bow alike). ``straightness``:
    s in mm, one value, [x, y, z] or leg → s; the sagitta of the bow over the
    whole leg (:func:`sagitta_from_straightness` for one over the plunger's slide)."""
    s_of, planes = _plane_forms(prop, straightness)
    # The legs of one machine are made alike and may bow alike: every plane's part
    # adds with the worst sign (GUM 5.2.2 with r = ±1 where the correlation is not
    # known), one source; the expected lack of fit keeps independent planes' ``cov``.
    cov = sum((np.outer(gu, gu) for gu in planes.values()),
              np.zeros((len(prop.keys), len(prop.keys))))
    worst = sum(np.abs(prop.K @ gu) for gu in planes.values())
    value = max(s_of.values())
    legs = list(s_of)
    src = _source(prop, "leg straightness", "rectangular", value, value / math.sqrt(3.0),
                  cov, **{f"straightness_{leg}_mm": s_of[leg] for leg in legs})
    return [replace(src, contributions={
        n: float(v) for n, v in zip(prop.names, worst, strict=True)})]


def form_covariance(prop: Propagation, straightness) -> np.ndarray:
    """The covariance (over ``prop.names``) the legs' form leaves in the identified
    parameters, for an interval that must hold whatever the legs do: each gauge
    plane of leg i bowed with a sagitta uniform in ±s_i (u = s/√3), once as one
    bow shared by every plane (the legs of one machine may bow alike: a uniform
    bow is exactly a tilt signature in the legs' middles, docs/model.md) and once
    independently per plane, the two added: Σ = v·vᵀ + Σ_p w_p·w_pᵀ with v = Σ_p
    K·g_p·u, w_p = K·g_p·u (g_p: :func:`form_vector` on plane p's keys).
    ``straightness`` as for :func:`straightness_sources`. Zero where the fit took
    the bows itself (a second gauge plane: the bows are then parameters, not
    errors)."""
    _, planes = _plane_forms(prop, straightness)
    w = [prop.K @ gu for gu in planes.values()]
    v = sum(w, np.zeros(len(prop.names)))
    return np.outer(v, v) + sum((np.outer(x, x) for x in w),
                                np.zeros((len(prop.names), len(prop.names))))


def form_columns(prop: Propagation, straightness, alike: float = 0.0) -> Bounded:
    """The legs' form as what it is, bounded systematic inputs of the identified
    parameters (docs/model.md, "Intervals at the tool"): the bow of gauge plane p of
    leg i has a sagitta h_p within ±s_i and moves the parameters by h_p·K·g_p (g_p:
    :func:`form_vector` on the plane's keys, K the identification's sensitivity).

    h_p = s_i·(a·u₀ + (1 − a)·u_p), a = ``alike``, u₀ and each u_p uniform in ±1 and
    independent: a = 0 (default) every plane's bow rectangular and independent of the
    others'; a = 1 every plane bowed alike (a uniform bow reads exactly as tilts);
    between, that share of each bound common to all planes. |h_p| ≤ s_i either way.
    Columns over ``prop.names``: one per gauge plane in ``prop.gauges`` order (bound
    (1 − a)·s_i), then, for a > 0, the shared one Σ_p K·g_p·s_i (bound a).
    ``straightness`` as for :func:`straightness_sources`. For a = 0 their covariance,
    Σ_p K·g_p·(K·g_p)ᵀ·s_i²/3, is :func:`form_covariance`'s per-plane part."""
    if not 0.0 <= float(alike) <= 1.0:
        raise ValueError(f"alike must lie in [0, 1], got {alike!r}")
    s_of, units = _plane_units(prop, straightness)
    cols = [prop.K @ g for g in units.values()]
    bounds = [(1.0 - alike) * s_of[gg[0]] for gg in units]
    if alike > 0:
        cols.append(sum((c * s_of[gg[0]] for c, gg in zip(cols, units, strict=True)),
                        np.zeros(len(prop.names))))
        bounds.append(float(alike))
    return Bounded(np.column_stack(cols) if cols else np.zeros((len(prop.names), 0)),
                   np.array(bounds), tuple(prop.names))


def _per_deviation(prop: Propagation, name: str, distribution: str, value_of: dict,
                   divisor: float) -> list[Source]:
    """One source per gauge: each of its deviations off independently by ±value
    (standard uncertainty value/divisor)."""
    return [_source(prop, f"{name} {''.join(gauge)}", distribution, value, value / divisor,
                    np.diag((value / divisor) ** 2 * prop.mask(gauge)))
            for gauge, value in value_of.items()]


def mpe_sources(prop: Propagation, mpe, span_mm: float | None = MPE_SPAN_MM) -> list[Source]:
    """Gauge MPE (b), one source per gauge: each deviation it measures
    off by a rectangular ±e_k, independent per deviation and systematic (the same
    in every cycle): u = e_k/√3, contribution sqrt(Σ_k K_pk²·u_k²). e_k is the MPE
    e over the travel a deviation spans: e for a deviation of ``span_mm`` or more,
    in proportion below (a gauge's error is a smooth function of its plunger's
    position: over a few µm of travel, as a converged machine's deviations are, it
    changes by a few µm × its slope); ``span_mm`` None: e on every deviation.
    ``mpe``: mm, one value or gauge (leg, direction) → e."""
    values = per_name(mpe, prop.gauges, "gauge MPE")
    scale = np.ones(len(prop.keys)) if span_mm is None else \
        np.minimum(1.0, np.abs(prop.measured) / span_mm)
    return [_source(prop, f"gauge MPE {''.join(gauge)}", "rectangular", e, e / math.sqrt(3.0),
                    np.diag((e * scale / math.sqrt(3.0)) ** 2 * prop.mask(gauge)),
                    span_mm=span_mm if span_mm is not None else math.nan)
            for gauge, e in values.items()]


def resolution_sources(prop: Propagation, resolution) -> list[Source]:
    """Gauge resolution (c), one source per gauge: a deviation is the
    difference of two readings each quantised by ±r/2 (rectangular), i.e.
    triangular ±r, u = r/√6 (GUM 4.3.9 and F.2.2.1); like :func:`mpe_sources`
    otherwise. ``resolution``: the gauge's step r, mm, one value or gauge → r."""
    return _per_deviation(prop, "gauge resolution", "triangular",
                          per_name(resolution, prop.gauges, "gauge resolution"), math.sqrt(6.0))


def plunger_angle_source(prop: Propagation, angle_deg: float) -> Source:
    """Plunger angle (d): a plunger θ off the direction it should measure
    reads cos θ of the travel, a relative scale error of all the gauge's
    deviations; taken as rectangular over ±c, c = 1 − cos θmax (conservative:
    the real error is one-sided), common to the gauge's deviations and
    independent between gauges: the gauge contributes |K_p·(c·Δ_gauge)|/√3,
    Δ_gauge its measured deviations, the source the quadrature over the gauges."""
    theta = non_negative(angle_deg, "plunger angle")
    c = 1.0 - math.cos(math.radians(theta))
    cov = sum((np.outer(c * prop.measured * prop.mask(gg), c * prop.measured * prop.mask(gg))
               for gg in prop.gauges), np.zeros((len(prop.keys), len(prop.keys)))) / 3.0
    return _source(prop, "plunger angle", "rectangular", None, None, cov,
                   plunger_angle_deg=theta, scale_error=c)


def temperature_source(prop: Propagation, temperature_change: float,
                       alpha: float = STEEL_ALPHA) -> Source:
    """Temperature change (e): a leg of length L grows by α·ΔT·L; as a
    step at an unknown time between the Π0 stops that bracket a reading, their
    mean does not remove it: each deviation off by a rectangular ±α·ΔT·L/2,
    independent per deviation. ``temperature_change``: ΔT in K (or °C)."""
    dt = non_negative(temperature_change, "temperature change")
    half = alpha * dt * prop.geometry.leg_length / 2.0
    u = half / math.sqrt(3.0)
    return _source(prop, "temperature", "rectangular", half, u, u**2 * np.eye(len(prop.keys)),
                   temperature_change_k=dt, alpha_per_k=alpha,
                   leg_length_mm=prop.geometry.leg_length)


def stands_source(prop: Propagation, tolerance: float) -> Source:
    """The indicator stands set by eye within ±``tolerance`` mm of the legs' middles and
    not modelled (docs/model.md, "Where the indicator plane is"): each gauge's stand
    off by an unknown m, rectangular, u = a/√3, moving each of its deviations by
    (∂Δ/∂m)·m (exact: Δ with every plane 1 mm further less Δ as fitted; orthocal.stands),
    independent between gauges. A Type B term where no noise estimate weighs a prior
    on them against the data (one value per deviation)."""
    a = non_negative(tolerance, "stand tolerance")
    keys = list(prop.keys)
    per_mm = (deviations(keys, prop.geometry, prop.params, prop.mount_offsets + 1.0)
              - deviations(keys, prop.geometry, prop.params, prop.mount_offsets))
    u = a / math.sqrt(3.0)
    cov = np.zeros((len(keys), len(keys)))
    for gauge in prop.gauges:
        v = u * per_mm * prop.mask(gauge)
        cov += np.outer(v, v)
    return _source(prop, "indicator stands", "rectangular", None, u, cov,
                   stand_tolerance_mm=a)


def budget_sources(ident: Identification, geometry: Geometry | None = None, *,
                   straightness=None, mpe=None, resolution=None,
                   plunger_angle_deg: float | None = None,
                   temperature_change: float | None = None,
                   alpha: float = STEEL_ALPHA,
                   mpe_span_mm: float | None = MPE_SPAN_MM) -> list[Source]:
    """The standard Type B sources of those inputs that are given (None: left
    out), all propagated through one :func:`propagation` of ``ident``."""
    prop = propagation(ident, geometry)
    out: list[Source] = []
    if straightness is not None:
        out += straightness_sources(prop, straightness)
    if mpe is not None:
        out += mpe_sources(prop, mpe, mpe_span_mm)
    if resolution is not None:
        out += resolution_sources(prop, resolution)
    if plunger_angle_deg is not None:
        out.append(plunger_angle_source(prop, plunger_angle_deg))
    if temperature_change is not None:
        out.append(temperature_source(prop, temperature_change, alpha))
    return out


# --- combination -----------------------------------------------------------------------


def welch_satterthwaite(parts: Sequence[tuple[float, float]]) -> float:
    """ν_eff = u_c⁴ / Σ u_i⁴/ν_i over (u_i, ν_i) (GUM G.4.1, eq. G.2b); parts with
    ν_i = ∞ add to u_c only. ∞ when no part with finite dof contributes."""
    uc2 = sum(u * u for u, _ in parts)
    denom = sum(u**4 / nu for u, nu in parts if math.isfinite(nu) and u > 0.0)
    if denom == 0.0:
        return math.inf
    return uc2**2 / denom


def combine(type_a_se: Mapping[str, float], type_a_dof: float | None,
            sources: Sequence[Source], coverage: float = COVERAGE,
            type_a_name: str = "repeatability") -> dict[str, Any]:
    """docs/design.md's ``uncertainty_budget`` (JSON-ready): per parameter of
    ``type_a_se`` (the identification's standard errors, resting on
    ``type_a_dof`` degrees of freedom, None: ∞), the combined standard
    uncertainty u_c = sqrt(u_A² + Σ u_s²) (GUM 5.1.2, independent sources), the
    effective dof (:func:`welch_satterthwaite`, Type B with ∞), the coverage
    factor k of Student's t at ν_eff (orthocal.noise.coverage_factor; the
    normal's at ∞) and U = k·u_c. The Type A part leads ``sources`` (type "A",
    normal, its dof). Infinite dof are stated as null."""
    names = list(type_a_se)
    for s in sources:
        missing = [n for n in names if n not in s.contributions]
        if missing:
            raise ValueError(f"source {s.name!r} has no contribution to {missing}")
    nu_a = math.inf if type_a_dof is None else float(type_a_dof)
    if not nu_a > 0:
        raise ValueError(f"type A dof must be > 0, got {type_a_dof!r}")
    type_a = Source(type_a_name, "normal", None, None,
                    {n: float(type_a_se[n]) for n in names}, type="A", dof=nu_a)
    every = [type_a, *sources]
    combined, dof, k, expanded = {}, {}, {}, {}
    for n in names:
        parts = [(s.contributions[n], s.dof) for s in every]
        uc = math.sqrt(sum(u * u for u, _ in parts))
        nu = welch_satterthwaite(parts)
        kk = coverage_factor(None if math.isinf(nu) else nu, coverage)
        combined[n], dof[n], k[n], expanded[n] = uc, nu, kk, kk * uc
    return {
        "sources": [s.to_dict() for s in every],
        "combined_mm": {n: finite(v) for n, v in combined.items()},
        "effective_dof": {n: finite(v) for n, v in dof.items()},
        "coverage_factor": {n: finite(v) for n, v in k.items()},
        f"expanded_{round(100 * coverage)}_mm": {n: finite(v) for n, v in expanded.items()},
    }
