"""An identification's covariance from the noise measured in the run, not its fit's residual."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from orthocal.calibration import jacobian
from orthocal.geometry import Geometry
from orthocal.identification import Identification, PriorWeight, exact_jacobian
from orthocal.measurement import Key
from orthocal.noise import row_correlation
from orthocal.stands import (
    incidence,
    prior_penalty,
    ridge_covariance,
    stand_estimates,
    stand_jacobian,
)


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
    if result.stand_model is not None:
        return _with_measured_noise_stands(result, geometry, noise_sigma, inflate,
                                           shared_zero, noise_dof)
    if result.method == "nonlinear":
        J = exact_jacobian(keys, geometry, result.fit_vector, result.model)
    else:
        J = jacobian(keys, geometry, result.model)
    C = row_correlation(keys, shared_zero)
    if result.prior is not None:
        covariance = _joined_sandwich(J, result.prior, (inflate * noise_sigma) ** 2 * C)
    else:
        bread = np.linalg.inv(J.T @ J)
        covariance = (inflate * noise_sigma) ** 2 * bread @ J.T @ C @ J @ bread
    std = np.sqrt(np.diag(covariance))
    correlation = covariance / np.outer(std, std)
    return replace(result, covariance=covariance, correlation=correlation,
                   std_errors={n: float(s) for n, s in zip(result.names, std, strict=True)},
                   se_dof=None if noise_dof is None else float(noise_dof))


def _joined_sandwich(J: np.ndarray, prior: PriorWeight, noise_cov: np.ndarray) -> np.ndarray:
    """The covariance of a fit joined with a prior (orthocal.carry.joined_fit: data
    weighed by 1/σ², prior information I_p) when the rows' noise is ``noise_cov``:
    B·(Jᵀ·Cov(e)·J/σ⁴ + I_p)·B, B = (JᵀJ/σ² + I_p)⁻¹; (JᵀJ/σ² + I_p)⁻¹ itself where
    Cov(e) = σ²·I."""
    w = 1.0 / prior.sigma**2
    B = np.linalg.inv(w * J.T @ J + prior.information)
    cov = B @ (w * w * J.T @ noise_cov @ J + prior.information) @ B
    return (cov + cov.T) / 2.0


def stand_design(result: Identification, geometry: Geometry, keys: Sequence[Key]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(J_θ, J_M, m̂) of a fit with stands at ``keys`` (rows or distinct keys):
    the model's columns read in the identified planes, the stands' exact columns
    (ordered as ``result.stands``) and the stands' estimates."""
    stands = result.stand_model
    assert stands is not None
    names, S = incidence(keys, stands)
    order = list(result.stands)
    S_full = np.zeros((len(keys), len(order)))
    for c, name in enumerate(names):
        S_full[:, order.index(name)] = S[:, c]
    m = result.stand_offsets
    J_t = exact_jacobian(keys, geometry, result.fit_vector, result.model, S_full @ m)
    J_m = stand_jacobian(keys, geometry, result.fit_vector, S_full)
    return J_t, J_m, m


def _with_measured_noise_stands(result: Identification, geometry: Geometry, noise_sigma: float,
                                inflate: float, shared_zero: bool,
                                noise_dof: float | None) -> Identification:
    """:func:`with_measured_noise` of a fit with stands: the penalised least squares'
    sandwich B·(Aᵀ·σ²C·A + Λ·Σ_M·Λ)·B (orthocal.stands.ridge_covariance), the
    noise part times ``inflate``²; the stands' SDs and observability follow."""
    stands = result.stand_model
    assert stands is not None and result.stand_sigma is not None
    keys = list(result.keys)
    J_t, J_m, m = stand_design(result, geometry, keys)
    p = J_t.shape[1]
    noise_cov = (inflate * noise_sigma) ** 2 * row_correlation(keys, shared_zero)
    cov_all = ridge_covariance(np.hstack([J_t, J_m]), p,
                               prior_penalty(result.stand_sigma, stands, len(m)), noise_cov,
                               stands.prior_sd**2)
    covariance = cov_all[:p, :p]
    std = np.sqrt(np.diag(covariance))
    correlation = covariance / np.outer(std, std)
    gauges = {n: e.gauges for n, e in result.stands.items()}
    estimates = stand_estimates(list(result.stands), gauges, m, cov_all[p:, p:], stands)
    return replace(result, covariance=covariance, correlation=correlation,
                   std_errors={n: float(s) for n, s in zip(result.names, std, strict=True)},
                   se_dof=None if noise_dof is None else float(noise_dof), stands=estimates)
