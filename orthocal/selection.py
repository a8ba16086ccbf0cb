"""Model selection (``auto``): the smallest model the data supports.

The candidates form a lattice (docs/model.md, "Axes that do not meet"): ``rho``
(Δρ); ``rho+gap`` and ``rho+tilt`` (Δρ and the gaps between the axes, or their
tilts); ``rho+tilt+gap`` and ``full+tilt`` (Δρ, ΔL, tilts; only with more than
two postures per leg); ``full+tilt+gap`` (the whole rigid geometry, four stops
per leg). They are tried by size, smallest first; among the candidates of one
size that pass, the one the data fit best (largest p-value) is chosen. ``L``
and ``full`` are not candidates: ΔL and Δρ act almost alike (condition 62), so
the data cannot prefer one to the other, and only Δρ can be written to a
controller.

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

Stated form and gauge errors (option ``allowance``, orthocal.misfit): the lack
of fit is the smallest that errors within the stated bounds, each with the
shape it makes, can leave; so a bowed leg does not buy tilts, and a misfit of
another shape (gaps) is not excused by it.

Indicator stands (option ``stands``, orthocal.stands): misplaced
stands leave deviations (stand error × leg slope, the legs sloping with Δρ)
that look like tilt. With the option every candidate is fitted with the stands
as random effects of prior SD tolerance/√3, and

- the lack of fit is the generalised residual of the deviation means whose
  covariance is σ²·C + J_M·Σ_M·J_Mᵀ (noise and stands; same F, K − p dof);
- since most of a tilt's signature lies along the stands' columns, where that
  test weighs it against the stands' variance, a candidate must also not be
  improved on by the next one: the drop of that residual when the next
  candidate's parameters join (a likelihood-ratio F test on their number, 3
  for the tilts). Measured by bench/stands_vs_auto.py: misplaced stands (±5 mm) on
  square machines with ±1.5 mm offsets keep ``rho`` where the lack of fit
  alone picks a tilt model in about 3 runs of 4 without the option, and 0.2
  mrad of tilt is still found.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from orthocal.covariance import stand_design
from orthocal.geometry import MODELS, Geometry
from orthocal.identification import Identification, exact_jacobian, identify
from orthocal.inputs import IdentificationError
from orthocal.lattice import ModelTest, also_passing, best_passing, excused_note, lattice_levels
from orthocal.measurement import Key
from orthocal.misfit import Allowance, bounded_rss, columns
from orthocal.noise import key_rows, means_covariance, noise_from_cycles
from orthocal.stands import Stands, describe_stands

CANDIDATES: tuple[str, ...] = ("rho", "rho+gap", "rho+tilt", "rho+tilt+gap", "full+tilt",
                               "full+tilt+gap")
LEVEL = 0.001
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
    #: The stands option when the stands were modelled (None: at L/2, not modelled);
    #: their estimates are the identification's ``stands``.
    stands: Stands | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (the run JSON's ``model_selection``)."""
        out = {"model": self.model, "test": "lack-of-fit F test against the measured noise",
               "level": self.level, "noise_sigma_mm": self.noise_sigma,
               "noise_dof": self.noise_dof, "noise_source": self.noise_source,
               "supported": self.supported, "reason": self.reason,
               "candidates": [t.to_dict() for t in self.tests], **self.extra}
        if self.stands is not None:
            out["test"] += (", the stands as random effects; and against the next "
                            "candidate (likelihood ratio)")
            out["stands"] = {**self.stands.to_dict(), "estimates": {
                n: e.to_dict() for n, e in self.identification.stands.items()}}
        return out


def _means(result: Identification, distinct: Sequence[Key]) -> tuple[np.ndarray, np.ndarray]:
    """(the deviation means, the fit's residual at them) per distinct key."""
    rows = _rows_of(result, distinct)
    values = np.asarray(result.values)
    return (np.array([np.mean(values[r]) for r in rows]),
            np.array([np.mean(result.residuals[r]) for r in rows]))


def _rows_of(result: Identification, distinct: Sequence[Key]) -> list[np.ndarray]:
    """The rows of each of ``distinct`` (means_covariance's, first-appearance order)."""
    order, rows = key_rows(result.keys)
    assert order == list(distinct)
    return rows


def _mean_residuals(result: Identification, distinct: Sequence[Key]) -> np.ndarray:
    """The fit's residual averaged over each distinct key's rows."""
    return np.array([np.mean(result.residuals[r]) for r in _rows_of(result, distinct)])


def _allowed_rss(result: Identification, geometry: Geometry, noise_sigma: float,
                 shared_zero: bool, allowance: Allowance) -> tuple[float, dict[str, Any]]:
    """The generalised residual of ``result`` that errors within ``allowance`` can
    leave, at the least (orthocal.misfit; with the stands' prior in the
    covariance where they are modelled), and what they took."""
    keys = list(result.keys)
    distinct, C = means_covariance(keys, shared_zero)
    means, r = _means(result, distinct)
    if result.stand_model is not None:
        J, J_m, m = stand_design(result, geometry, distinct)
        r = r + J_m @ m
        V = C + (result.stand_model.prior_sd / noise_sigma) ** 2 * (J_m @ J_m.T)
    else:
        J, V = exact_jacobian(distinct, geometry, result.fit_vector, result.model), C
    cols = columns(allowance, distinct, means, geometry, result.fit_vector)
    fit = bounded_rss(r, V, J, cols)
    return fit.rss, fit.to_dict()


def f_upper(dfn: float, dfd: float, F: float) -> float:
    """P(F(dfn, dfd) > F): the upper tail scipy.stats' ``f.sf(F, dfn, dfd)`` gives
    (1 at F ≤ 0), from scipy.special, without scipy.stats' half second of imports
    and per-call overhead (a run's model tests call it dozens of times)."""
    from scipy.special import fdtrc

    return 1.0 if F <= 0 else float(fdtrc(dfn, dfd, F))


def lack_of_fit(result: Identification, geometry: Geometry, noise_sigma: float,
                noise_dof: float, shared_zero: bool = True,
                allowance: Allowance | None = None) -> ModelTest:
    """The lack-of-fit F test of one identification (see the module docstring).

    The fit's residuals at the deviation means are re-weighted by the inverse
    covariance of the means (a Gauss–Newton step of generalised least squares
    from the ordinary fit, exact to second order in the small residual), so F
    follows F(K − p, ν) whatever the number of cycles per deviation.
    ``allowance``: the stated errors the misfit may be excused by, within their
    bounds and with their shapes (orthocal.misfit)."""
    keys = list(result.keys)
    distinct, C = means_covariance(keys, shared_zero)
    p = len(result.names)
    dof_model = len(distinct) - p
    if dof_model <= 0:
        return ModelTest(result.model, True, note="as many parameters as deviations: no test")
    took = None
    if allowance is not None:
        rss, took = _allowed_rss(result, geometry, noise_sigma, shared_zero, allowance)
    elif result.stand_model is not None:
        rss = _marginal_rss(result, geometry, noise_sigma, shared_zero)
    else:
        mean_res = _mean_residuals(result, distinct)
        J = exact_jacobian(distinct, geometry, result.fit_vector, result.model)
        W = np.linalg.inv(C)
        g = J.T @ W @ mean_res
        rss = float(mean_res @ W @ mean_res - g @ np.linalg.solve(J.T @ W @ J, g))
    F = max(rss, 0.0) / dof_model / noise_sigma**2
    p_value = f_upper(dof_model, noise_dof, F)
    if took is not None:  # what the noise alone would have said
        took["p_without_allowance"] = f_upper(
            dof_model, noise_dof,
            took["rss_without_allowance_mm2"] / dof_model / noise_sigma**2)
    return ModelTest(result.model, True, F=float(F), dof_model=dof_model,
                     dof_noise=float(noise_dof), p_value=p_value, passed=False,
                     residual_rms=float(result.residual_rms), allowance=took)


def _marginal_rss(result: Identification, geometry: Geometry, noise_sigma: float,
                  shared_zero: bool = True) -> float:
    """The generalised residual sum of squares (mm², in units of σ² of one
    per-cycle deviation times σ²) of a fit with stands: the deviation means'
    residual with the stands' part put back, r* = r̄ + J_M·m̂, weighted by the
    inverse of its covariance C + J_M·Σ_M·J_Mᵀ/σ², the model's columns
    projected out (a Gauss–Newton step of the marginal generalised least squares
    from the fit, as :func:`lack_of_fit` does without stands). It equals the
    penalised residual Σ r̄ᵀC⁻¹r̄ + σ²·m̂ᵀΣ_M⁻¹m̂ at the marginal optimum."""
    stands = result.stand_model
    assert stands is not None
    keys = list(result.keys)
    distinct, C = means_covariance(keys, shared_zero)
    mean_res = _mean_residuals(result, distinct)
    J_t, J_m, m = stand_design(result, geometry, distinct)
    r_star = mean_res + J_m @ m
    V = C + (stands.prior_sd / noise_sigma) ** 2 * (J_m @ J_m.T)
    W = np.linalg.inv(V)
    g = J_t.T @ W @ r_star
    return float(r_star @ W @ r_star - g @ np.linalg.solve(J_t.T @ W @ J_t, g))


def nested_test(small: Identification, big: Identification, geometry: Geometry,
                noise_sigma: float, noise_dof: float, shared_zero: bool = True,
                allowance: Allowance | None = None) -> tuple[float, int, float] | None:
    """(F, dof, p) of the drop of the generalised residual (:func:`_marginal_rss`)
    from ``small`` to ``big``, the larger model with the same stands: F =
    [(RSS_small − RSS_big)/(p_big − p_small)]/σ̂², F(p_big − p_small, ν) when
    ``small`` is right. None when ``big`` has no more parameters. For fits with
    stands (orthocal.stands): the likelihood-ratio test that sees a tilt where
    the lack of fit, spread over K − p dof, weighs it against the stands.
    ``allowance``: both residuals those the stated errors can leave, at the least
    (:func:`lack_of_fit`)."""
    extra = len(big.names) - len(small.names)
    if extra <= 0 or small.stand_model is None or big.stand_model is None:
        return None
    if allowance is not None:
        drop = (_allowed_rss(small, geometry, noise_sigma, shared_zero, allowance)[0]
                - _allowed_rss(big, geometry, noise_sigma, shared_zero, allowance)[0])
    else:
        drop = (_marginal_rss(small, geometry, noise_sigma, shared_zero)
                - _marginal_rss(big, geometry, noise_sigma, shared_zero))
    F = max(drop, 0.0) / extra / noise_sigma**2
    return float(F), extra, f_upper(extra, noise_dof, F)


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
    stands: Stands | None = None,
    allowance: Allowance | None = None,
) -> ModelSelection:
    """The smallest of ``candidates`` (by their number of parameters; among those
    of one size that pass, the best fit) whose lack of fit the measured noise
    explains at ``level`` (module docstring).

    ``deviations_in`` as for :func:`orthocal.identify`, a key's repeats being its
    cycles in order; ``noise_sigma`` (mm), ``noise_dof``: the noise of one
    per-cycle deviation and its degrees of freedom, e.g. from
    :func:`noise_from_cycles` (None: from the cycle scatter of these data).
    Candidates that cannot be identified from these keys are skipped, saying
    why. When none passes, the largest identifiable one is used and the result
    says the data show more than any candidate explains (``supported`` False).
    Raises IdentificationError when no candidate can be identified.
    ``stands``: model the indicator stands (:class:`orthocal.stands.Stands`: which
    gauges share a stand, their placement tolerance) as the module docstring
    says; the reason then says so and the identification's ``stands`` holds
    their estimates. None (the default): as without the option, bit for bit.
    ``allowance``: the stated form and gauge errors a misfit may be excused by,
    within their bounds and with their shapes (orthocal.misfit); None: none.
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
    if stands is not None:
        return _select_with_stands(deviations_in, geometry, float(noise_sigma),
                                   float(noise_dof), candidates, level, method, shared_zero,
                                   noise_source, stands, allowance)
    if isinstance(deviations_in, Iterable) and not isinstance(deviations_in, Mapping):
        deviations_in = list(deviations_in)  # read more than once
    tests: list[ModelTest] = []
    fits: dict[str, Identification] = {}
    for group in lattice_levels(candidates):
        for model in group:
            try:
                fit = identify(deviations_in, geometry, model=model, method=method)
            except IdentificationError as exc:
                tests.append(ModelTest(model, False, note=str(exc)))
                continue
            test = lack_of_fit(fit, geometry, noise_sigma, noise_dof, shared_zero, allowance)
            passed = test.p_value is None or test.p_value >= level
            tests.append(replace(test, passed=passed))
            fits[model] = fit
        if any(t.passed for t in tests):
            break
    if not fits:
        raise IdentificationError("auto: no candidate model can be identified from these "
                                  "deviations: " + "; ".join(t.note for t in tests))
    chosen = best_passing(tests)
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
                  + f"; {noise_txt})" + also_passing(chosen, tests)
                  + (f"; {why_not}" if why_not else "") + excused_note(chosen, level))
        return ModelSelection(chosen.model, fits[chosen.model], tuple(tests), level,
                              float(noise_sigma), float(noise_dof), noise_source, reason)
    largest = list(fits)[-1]
    skipped = [t for t in tests if not t.identifiable]
    reason = (f"{largest}: no candidate explains the data at level {level:g} ({why_not}; "
              f"{noise_txt}); the largest identifiable model is used: errors outside the "
              "model remain (play, leg lengths, a loose indicator, indicator stands "
              "off the legs' middles, which were taken as placed exactly?)"
              + ("; not identifiable: " + "; ".join(f"{t.model}: {t.note}" for t in skipped)
                 if skipped else ""))
    return ModelSelection(largest, fits[largest], tuple(tests), level, float(noise_sigma),
                          float(noise_dof), noise_source, reason, supported=False)


def _against_next(test: ModelTest, fit: Identification, larger: Sequence[Sequence[str]],
                  fit_of: Any, geometry: Geometry, noise_sigma: float, noise_dof: float,
                  shared_zero: bool, allowance: Allowance | None) -> ModelTest:
    """``test`` with its test against the candidates of the next size that contain
    it and can be identified (:func:`nested_test`): the one that explains the
    most (smallest p) is named."""
    mine = set(MODELS[fit.model])
    for group in larger:
        bigger = [m for m in group if mine < set(MODELS[m]) and fit_of(m) is not None]
        if not bigger:
            continue
        worst = None
        for m in bigger:
            nested = nested_test(fit, fit_of(m), geometry, noise_sigma, noise_dof, shared_zero,
                                 allowance)
            if nested is not None and (worst is None or nested[2] < worst[1][2]):
                worst = (m, nested)
        if worst is None:
            return test
        m, (F, dof, p) = worst
        return replace(test, against=m, F_next=F, dof_next=dof, p_next=p)
    return test


def _select_with_stands(
    deviations_in: Mapping | Iterable, geometry: Geometry, noise_sigma: float, noise_dof: float,
    candidates: Sequence[str], level: float, method: str, shared_zero: bool,
    noise_source: str, stands: Stands, allowance: Allowance | None = None,
) -> ModelSelection:
    """:func:`select_model` with the stands modelled (module docstring): a
    candidate passes when its lack of fit passes and the next identifiable
    candidate does not explain significantly more (:func:`nested_test`)."""
    if isinstance(deviations_in, Iterable) and not isinstance(deviations_in, Mapping):
        deviations_in = list(deviations_in)  # read more than once
    fits: dict[str, Identification] = {}
    notes: dict[str, str] = {}

    def fit_of(model: str) -> Identification | None:
        if model not in fits and model not in notes:
            try:
                fits[model] = identify(deviations_in, geometry, model=model, method=method,
                                       sigma=noise_sigma, stands=stands)
            except IdentificationError as exc:
                notes[model] = str(exc)
        return fits.get(model)

    levels = lattice_levels(candidates)
    tests: list[ModelTest] = []
    for n, group in enumerate(levels):
        for model in group:
            fit = fit_of(model)
            if fit is None:
                tests.append(ModelTest(model, False, note=notes[model]))
                continue
            test = lack_of_fit(fit, geometry, noise_sigma, noise_dof, shared_zero, allowance)
            passed = test.p_value is None or test.p_value >= level
            if passed:  # only then do the next candidates decide
                test = _against_next(test, fit, levels[n + 1:], fit_of, geometry, noise_sigma,
                                     noise_dof, shared_zero, allowance)
                passed = test.p_next is None or test.p_next >= level
            tests.append(replace(test, passed=passed))
        if any(t.passed for t in tests):
            break
    tested = [t for t in tests if t.identifiable]
    if not tested:
        raise IdentificationError("auto: no candidate model can be identified from these "
                                  "deviations: " + "; ".join(t.note for t in tests))
    chosen = best_passing(tests)
    noise_txt = (f"noise {1000 * noise_sigma:.2f} µm per deviation ({noise_source}, "
                 f"{noise_dof:g} dof)")

    def why_rejected(t: ModelTest) -> str:
        if t.F is not None and t.p_value is not None and t.p_value < level:
            return (f"{t.model} leaves more than the noise and the stands explain (F = "
                    f"{t.F:.1f}, p = {t.p_value:.1e} < {level:g})")
        return (f"{t.against} explains significantly more than {t.model} (F = {t.F_next:.1f} "
                f"on ({t.dof_next}, {t.dof_noise:g}) dof, p = {t.p_next:.1e} < {level:g})")

    why_not = "; ".join(why_rejected(t) for t in tested if not t.passed and t.F is not None)
    if chosen is not None:
        ident = fits[chosen.model]
        if chosen.F is not None:
            lof = (f"F = {chosen.F:.2f} on ({chosen.dof_model}, {chosen.dof_noise:g}) dof, "
                   f"p = {chosen.p_value:.3f} ≥ {level:g}")
        else:
            lof = chosen.note
        nxt = ("" if chosen.against is None else
               f"; {chosen.against} explains no significantly more (F = {chosen.F_next:.2f} "
               f"on ({chosen.dof_next}, {chosen.dof_noise:g}) dof, p = {chosen.p_next:.3f})")
        reason = (f"{chosen.model}: the smallest model whose residual the measured noise and "
                  f"the stands explain ({lof}{nxt}; {noise_txt})" + also_passing(chosen, tests)
                  + (f"; {why_not}" if why_not else "") + excused_note(chosen, level)
                  + f"; {describe_stands(ident.stands, stands)}")
        return ModelSelection(chosen.model, ident, tuple(tests), level, noise_sigma, noise_dof,
                              noise_source, reason, stands=stands)
    largest = tested[-1].model
    skipped = [t for t in tests if not t.identifiable]
    reason = (f"{largest}: no candidate explains the data at level {level:g} ({why_not}; "
              f"{noise_txt}); the largest identifiable model is used: errors outside the "
              f"model remain (play, leg lengths, a loose indicator, indicator stands "
              f"further than ±{stands.tolerance:g} mm off the legs' middles?)"
              + ("; not identifiable: " + "; ".join(f"{t.model}: {t.note}" for t in skipped)
                 if skipped else "")
              + f"; {describe_stands(fits[largest].stands, stands)}")
    return ModelSelection(largest, fits[largest], tuple(tests), level, noise_sigma, noise_dof,
                          noise_source, reason, supported=False, stands=stands)
