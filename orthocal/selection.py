"""Model selection (``auto``): the smallest model the data supports.

The candidates are nested, each extending the one before: ``rho`` (Δρ),
``rho+tilt`` (Δρ and the axis tilts), ``full+tilt`` (Δρ, ΔL, tilts; only with
more than two postures per leg). ``L`` and ``full`` are not candidates: ΔL and
Δρ act almost alike (condition 62), so the data cannot prefer one to the
other, and only Δρ can be written to a controller.

The test, for each candidate in turn, is the lack-of-fit F test against the
indicator noise measured in the same run:

    F = [RSS_lof / (K − p)] / σ̂²   ~   F(K − p, ν)   if the model is right

K distinct deviations, p parameters, RSS_lof the generalised residual sum of
squares of the deviation means (weighted by the inverse of their covariance
in units of σ², which the procedure fixes: see :func:`means_covariance`),
σ̂² the variance of one per-cycle deviation estimated independently of the fit
(cycle-to-cycle scatter, or the scatter of readings at a stop) with ν degrees of
freedom. The first candidate whose p-value is at least ``level`` is chosen. At
level 0.001 a machine the smaller model describes is kept with probability
0.999, while a tilt of 0.2 mrad (deviations of ~8 µm) is rejected for ``rho``
far above indicator noise of a few µm (bench/model_selection.py measures both).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from orthocal.calibration import jacobian
from orthocal.geometry import Geometry
from orthocal.identification import (
    Identification,
    IdentificationError,
    _flatten,
    exact_jacobian,
    identify,
)
from orthocal.measurement import Key

CANDIDATES: tuple[str, ...] = ("rho", "rho+tilt", "full+tilt")
LEVEL = 0.001
# Consecutive cycles share their Π0 stop (station/sequencer.py): a per-cycle
# deviation P − (Z_before + Z_after)/2 has variance 1.5·s² with s² the variance
# of one stop mean; deviations of one gauge in the same cycle share both Π0
# stops (covariance 0.5·s²), in adjacent cycles one (0.25·s²).
_SAME_CYCLE, _ADJACENT_CYCLE = 0.5 / 1.5, 0.25 / 1.5
SHARED_ZERO_LAG1 = _ADJACENT_CYCLE  # = 1/6, station.sequencer.SHARED_P0_CORRELATION


@dataclass(frozen=True)
class ModelTest:
    """The lack-of-fit test of one candidate (``F`` None when it was not tested)."""

    model: str
    identifiable: bool
    F: float | None = None
    dof_model: int | None = None
    dof_noise: float | None = None
    p_value: float | None = None
    passed: bool = False
    residual_rms: float | None = None
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.model, "identifiable": self.identifiable, "F": self.F,
                "dof": [self.dof_model, self.dof_noise] if self.F is not None else None,
                "p_value": self.p_value, "passed": self.passed,
                "residual_rms_mm": self.residual_rms, "note": self.note or None}


@dataclass(frozen=True)
class ModelSelection:
    """Result of :func:`select_model`: the model chosen, its identification, the
    tests behind the choice and a sentence saying why."""

    model: str
    identification: Identification
    tests: tuple[ModelTest, ...]
    level: float
    noise_sigma: float
    noise_dof: float
    noise_source: str
    reason: str
    supported: bool = True
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (the run JSON's ``model_selection``)."""
        return {"model": self.model, "test": "lack-of-fit F test against the measured noise",
                "level": self.level, "noise_sigma_mm": self.noise_sigma,
                "noise_dof": self.noise_dof, "noise_source": self.noise_source,
                "supported": self.supported, "reason": self.reason,
                "candidates": [t.to_dict() for t in self.tests], **self.extra}


def _gauge_rows(keys: Sequence[Key]) -> list[tuple[tuple[str, str], int]]:
    """(gauge, cycle index) of each row: a key's repeats are its cycles in order."""
    count: dict[Key, int] = {}
    rows = []
    for key in keys:
        rows.append(((key[1], key[2]), count.get(key, 0)))
        count[key] = count.get(key, 0) + 1
    return rows


def row_correlation(keys: Sequence[Key], shared_zero: bool = True) -> np.ndarray:
    """Correlation of the rows ``keys`` (one per cycle: a key repeated once per
    cycle, in cycle order). Without ``shared_zero`` the rows are independent;
    with it, the station's Π0 sharing correlates rows of one gauge (leg,
    direction): 1/3 in the same cycle, 1/6 in adjacent cycles."""
    n = len(keys)
    C = np.eye(n)
    if shared_zero:
        rows = _gauge_rows(keys)
        for a in range(n):
            for b in range(a + 1, n):
                (ga, ca), (gb, cb) = rows[a], rows[b]
                if ga != gb:
                    continue
                if ca == cb:
                    C[a, b] = C[b, a] = _SAME_CYCLE
                elif abs(ca - cb) == 1:
                    C[a, b] = C[b, a] = _ADJACENT_CYCLE
    return C


def means_covariance(keys: Sequence[Key], shared_zero: bool = True) -> tuple[list[Key], np.ndarray]:
    """Distinct keys and the covariance of their means in units of σ², the
    variance of one per-cycle deviation (rows as for :func:`row_correlation`)."""
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
    station.sequencer.cycle_std_error); corrected here. Raises ValueError when
    no deviation has two cycles."""
    keys, y = _flatten(deviations_in)
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


def with_measured_noise(result: Identification, geometry: Geometry, noise_sigma: float,
                        inflate: float = 1.0, shared_zero: bool = True,
                        noise_dof: float | None = None) -> Identification:
    """``result`` with its covariance from the measured noise instead of the fit's
    residual: least squares' sandwich (JᵀJ)⁻¹ Jᵀ (σ²·C) J (JᵀJ)⁻¹, C the rows'
    correlation (:func:`row_correlation`), times ``inflate``² (e.g. the lack of
    fit F of a model the data reject, so that its errors do not look small).

    Ordinary least squares treats the per-cycle deviations as independent; with
    shared Π0 stops they are not, and its standard errors come out ~10 % too
    large for rho and ~20 % too small for the tilts of rho+tilt (BENCHMARKS.md).
    ``noise_dof``, the degrees of freedom of ``noise_sigma``, becomes the result's
    ``se_dof``: with few cycles σ̂ is itself uncertain, and an interval of k
    standard errors needs k from Student's t, not the normal (:func:`coverage_factor`)."""
    keys = list(result.keys)
    if result.method == "nonlinear":
        J = exact_jacobian(keys, geometry, result.vector, result.model)
    else:
        J = jacobian(keys, geometry, result.model)
    bread = np.linalg.inv(J.T @ J)
    C = row_correlation(keys, shared_zero)
    covariance = (inflate * noise_sigma) ** 2 * bread @ J.T @ C @ J @ bread
    std = np.sqrt(np.diag(covariance))
    correlation = covariance / np.outer(std, std)
    return replace(result, covariance=covariance, correlation=correlation,
                   std_errors={n: float(s) for n, s in zip(result.names, std, strict=True)},
                   se_dof=None if noise_dof is None else float(noise_dof))


def coverage_factor(dof: float | None, coverage: float = 0.95) -> float:
    """k such that ±k standard errors hold the truth with probability ``coverage``
    when the standard errors rest on ``dof`` degrees of freedom (GUM G.3: Student's
    t). Two cycles of a six-gauge run give about 12 dof and k95 = 2.18, not 1.96;
    k99.73 = 3.8, not 3: "within 3 standard errors" fails three times as often as
    the normal promises. ``dof`` None or infinite: the normal's k."""
    from scipy.stats import norm, t  # imported on demand, as in lack_of_fit

    if not (0.0 < coverage < 1.0):
        raise ValueError(f"coverage must lie in (0, 1), got {coverage!r}")
    tail = (1.0 + coverage) / 2.0
    if dof is None or not math.isfinite(dof):
        return float(norm.ppf(tail))
    if dof <= 0:
        raise ValueError(f"coverage_factor needs dof > 0, got {dof!r}")
    return float(t.ppf(tail, dof))


def lack_of_fit(result: Identification, geometry: Geometry, noise_sigma: float,
                noise_dof: float, shared_zero: bool = True) -> ModelTest:
    """The lack-of-fit F test of one identification (see the module docstring).

    The fit's residuals at the deviation means are re-weighted by the inverse
    covariance of the means (a Gauss–Newton step of generalised least squares
    from the ordinary fit, exact to second order in the small residual), so F
    follows F(K − p, ν) whatever the number of cycles per deviation."""
    from scipy.stats import f as f_dist  # imported on demand, as scipy.optimize

    keys = list(result.keys)
    distinct, C = means_covariance(keys, shared_zero)
    p = len(result.names)
    dof_model = len(distinct) - p
    if dof_model <= 0:
        return ModelTest(result.model, True, note="as many parameters as deviations: no test")
    mean_res = np.array([np.mean(result.residuals[[k == d for k in keys]]) for d in distinct])
    J = exact_jacobian(distinct, geometry, result.vector, result.model)
    W = np.linalg.inv(C)
    g = J.T @ W @ mean_res
    rss = float(mean_res @ W @ mean_res - g @ np.linalg.solve(J.T @ W @ J, g))
    F = max(rss, 0.0) / dof_model / noise_sigma**2
    p_value = float(f_dist.sf(F, dof_model, noise_dof))
    return ModelTest(result.model, True, F=float(F), dof_model=dof_model,
                     dof_noise=float(noise_dof), p_value=p_value, passed=False,
                     residual_rms=float(result.residual_rms))


def select_model(
    deviations_in: Mapping | Iterable,
    geometry: Geometry | None = None,
    noise_sigma: float | None = None,
    noise_dof: float | None = None,
    candidates: Sequence[str] = CANDIDATES,
    level: float = LEVEL,
    method: str = "nonlinear",
    shared_zero: bool = True,
    noise_source: str = "given",
) -> ModelSelection:
    """The smallest of ``candidates`` (in the order given, smallest first) whose
    lack of fit the measured noise explains at ``level`` (module docstring).

    ``deviations_in`` as for :func:`orthocal.identify`, a key's repeats being its
    cycles in order; ``noise_sigma`` (mm), ``noise_dof``: the noise of one
    per-cycle deviation and its degrees of freedom, e.g. from
    :func:`noise_from_cycles` (None: from the cycle scatter of these data).
    Candidates that cannot be identified from these keys are skipped, saying
    why. When none passes, the largest identifiable one is used and the result
    says the data show more than any candidate explains (``supported`` False).
    Raises IdentificationError when no candidate can be identified.
    """
    geometry = geometry or Geometry()
    if not (0.0 < level < 1.0):
        raise ValueError(f"level must lie in (0, 1), got {level!r}")
    if noise_sigma is None:
        try:
            noise_sigma, noise_dof = noise_from_cycles(deviations_in, shared_zero)
        except ValueError as exc:
            raise IdentificationError(f"auto needs the noise of the measurement: {exc}") from None
        noise_source = "cycle-to-cycle scatter"
    if not (noise_sigma is not None and math.isfinite(noise_sigma) and noise_sigma > 0):
        raise IdentificationError(f"auto needs a positive noise estimate, got {noise_sigma!r}")
    if noise_dof is None or not noise_dof > 0:
        raise IdentificationError(f"auto needs the noise's degrees of freedom, got {noise_dof!r}")
    tests: list[ModelTest] = []
    fits: dict[str, Identification] = {}
    for model in candidates:
        try:
            fit = identify(deviations_in, geometry, model=model, method=method)
        except IdentificationError as exc:
            tests.append(ModelTest(model, False, note=str(exc)))
            continue
        test = lack_of_fit(fit, geometry, noise_sigma, noise_dof, shared_zero)
        passed = test.p_value is None or test.p_value >= level
        test = ModelTest(**{**test.__dict__, "passed": passed})
        tests.append(test)
        fits[model] = fit
        if passed:
            break
    if not fits:
        raise IdentificationError("auto: no candidate model can be identified from these "
                                  "deviations: " + "; ".join(t.note for t in tests))
    chosen = next((t for t in tests if t.passed), None)
    noise_txt = (f"noise {1000 * noise_sigma:.2f} µm per deviation ({noise_source}, "
                 f"{noise_dof:g} dof)")
    rejected = [t for t in tests if t.F is not None and not t.passed]
    why_not = "; ".join(f"{t.model} leaves more than the noise (F = {t.F:.1f}, "
                        f"p = {t.p_value:.1e} < {level:g})" for t in rejected)
    if chosen is not None:
        reason = (f"{chosen.model}: the smallest model whose residual the measured noise "
                  f"explains ("
                  + (f"F = {chosen.F:.2f} on ({chosen.dof_model}, {chosen.dof_noise:g}) dof, "
                     f"p = {chosen.p_value:.3f} ≥ {level:g}" if chosen.F is not None
                     else chosen.note)
                  + f"; {noise_txt})" + (f"; {why_not}" if why_not else ""))
        return ModelSelection(chosen.model, fits[chosen.model], tuple(tests), level,
                              float(noise_sigma), float(noise_dof), noise_source, reason)
    largest = list(fits)[-1]
    skipped = [t for t in tests if not t.identifiable]
    reason = (f"{largest}: no candidate explains the data at level {level:g} ({why_not}; "
              f"{noise_txt}); the largest identifiable model is used: errors outside the "
              "model remain (play, leg lengths, a loose indicator?)"
              + ("; not identifiable: " + "; ".join(f"{t.model}: {t.note}" for t in skipped)
                 if skipped else ""))
    return ModelSelection(largest, fits[largest], tuple(tests), level, float(noise_sigma),
                          float(noise_dof), noise_source, reason, supported=False)
