"""What one round tells the next: the axes' layout, which no offset changes
(docs/model.md, "Axes that do not meet" and "Writing the offsets back").

After a write-back only the joint offsets have changed: the tilts and the gaps
between the axes are what the earlier rounds measured too. A verification that
identifies them again from its own twelve deviations alone pays for it in its Δρ
(noise gain 2.92 under ``rho+tilt+gap`` against 1.87 under ``rho``), and that is
the figure the closed loop judges "converged" by. Here the earlier rounds' pooled
layout ℓ_p (covariance Σ_p, independent data) joins the round's own fit θ̂ = (Δρ̂,
ℓ̂) (covariance C) as what it is, a measurement of the same ℓ:

    C' = (C⁻¹ + Pᵀ·Σ_p⁻¹·P)⁻¹,     θ' = C'·(C⁻¹·θ̂ + Pᵀ·Σ_p⁻¹·ℓ_p)

(P picks ℓ out of θ): generalised least squares of the two, exact to first order
in the parameters' change. Δρ gains through its correlation with ℓ in this
round's fit, never loses: C' ≤ C.

A round whose own fit is singular (the legs' bows at the middles alone: a uniform
bow is a tilt) has no θ̂ nor C to join. :func:`joined_fit` joins in information
form instead, the prior as pseudo-observations beside the data (docs/model.md, "The
second gauge plane", equation (12)):

    θ' = argmin |y − f(θ)|²/σ² + (Pθ − ℓ_p)ᵀ·Σ_p⁻¹·(Pθ − ℓ_p),
    C' = (Jᵀ·J/σ² + Pᵀ·Σ_p⁻¹·P)⁻¹

by Gauss–Newton on the exact model (one solve for the linear one); full rank as soon
as the prior holds what the data cannot tell.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from orthocal.calibration import jacobian, linear_deviations
from orthocal.geometry import FIT_NAMES, MODELS, Geometry
from orthocal.identification import (
    Identification,
    IdentificationError,
    PriorWeight,
    exact_jacobian,
)
from orthocal.inputs import flatten_deviations
from orthocal.measurement import deviations

# Gauss–Newton of a joined fit: steps at most, and the step (mm, mrad) it stops under.
_MAX_STEPS = 30
_STEP_TOL = 1e-12
# Relative eigenvalue of the joined normal matrix below which it is singular.
_RANK_TOL = 1e-12


@dataclass(frozen=True)
class Prior:
    """An earlier, independent measurement of parameters ``names``: ``values`` with
    ``covariance`` (units of the names: mm, mrad)."""

    names: tuple[str, ...]
    values: np.ndarray
    covariance: np.ndarray

    @classmethod
    def of(cls, ident: Identification, names: Sequence[str]) -> Prior:
        """``ident``'s estimate of ``names`` with their joint covariance."""
        idx = [ident.names.index(n) for n in names]
        cov = np.asarray(ident.covariance, dtype=float)[np.ix_(idx, idx)]
        return cls(tuple(names), np.array([ident.parameters[n] for n in names]), cov)

    def over(self, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """(Pᵀ·Σ_p⁻¹·P, Pᵀ·Σ_p⁻¹·ℓ_p) over ``names``: the prior's information and its
        right-hand side, zero for names it does not hold."""
        missing = [n for n in self.names if n not in names]
        if missing:
            raise ValueError(f"the prior holds {missing}, which the model has not")
        idx = [list(names).index(n) for n in self.names]
        inv = np.linalg.inv(self.covariance)
        info = np.zeros((len(names), len(names)))
        info[np.ix_(idx, idx)] = (inv + inv.T) / 2.0
        rhs = np.zeros(len(names))
        rhs[idx] = inv @ self.values
        return info, rhs


def carried(own: Identification, geometry: Geometry, names: Sequence[str],
            values: np.ndarray, covariance: np.ndarray) -> Identification:
    """``own`` (a round's fit) joined with an independent measurement of its
    parameters ``names`` (``values`` with ``covariance``: the earlier rounds'
    pooled layout), module docstring. The residuals are the data's at the joined
    parameters."""
    idx = [own.names.index(n) for n in names]
    C = np.asarray(own.covariance, dtype=float)
    theta = np.array([own.parameters[n] for n in own.names])
    prior_info = np.linalg.inv(np.asarray(covariance, dtype=float))
    info = np.linalg.inv(C)
    joined_info = info.copy()
    joined_info[np.ix_(idx, idx)] += prior_info
    rhs = info @ theta
    rhs[idx] += prior_info @ np.asarray(values, dtype=float)
    cov = np.linalg.inv(joined_info)
    cov = (cov + cov.T) / 2.0
    new = cov @ rhs
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    params = {n: float(v) for n, v in zip(own.names, new, strict=True)}
    # ∂θ'/∂ℓ_p = C'·Pᵀ·Σ_p⁻¹ for this prior; a prior ``own`` already carried enters
    # through θ̂, which θ' takes with the gain C'·C⁻¹ (docs/model.md, (14))
    gain = np.zeros((len(own.names), len(own.names)))
    gain[:, idx] = cov[:, idx] @ prior_info
    if own.prior_gain is not None:
        gain += cov @ info @ own.prior_gain
    joined = replace(own, parameters=params,
                     std_errors={n: float(s) for n, s in zip(own.names, std, strict=True)},
                     covariance=cov, correlation=cov / np.outer(std, std), prior_gain=gain)
    if own.method != "nonlinear":
        return joined
    model_values = deviations(list(own.keys), geometry, joined.fit_vector, own.mount_offsets)
    residuals = np.asarray(own.values) - model_values
    predicted: dict = {}
    for key, value in zip(own.keys, model_values, strict=True):
        predicted.setdefault(key, float(value))
    return replace(joined, residuals=residuals, predicted=predicted,
                   residual_rms=float(np.sqrt(np.mean(residuals**2))))


def joined_fit(deviations_in: Mapping | Sequence, geometry: Geometry, model: str,
               prior: Prior, sigma: float, method: str = "nonlinear") -> Identification:
    """``model`` fitted to ``deviations_in`` (as for orthocal.identify) with ``prior``
    as pseudo-observations, data rows weighed by ``sigma`` (mm): equation (12) of
    docs/model.md (module docstring). Its covariance is C', its ``prior`` what was
    added to the data's normal equations (orthocal.covariance and
    orthocal.sensitivities read it). Raises IdentificationError where data and
    prior together still leave a combination undetermined."""
    if model not in MODELS:
        raise IdentificationError(f"model must be one of {sorted(MODELS)}, got {model!r}")
    if not (np.isfinite(sigma) and sigma > 0):
        raise IdentificationError(f"sigma must be a positive number, got {sigma!r}")
    keys, y = flatten_deviations(deviations_in)
    cols = list(MODELS[model])
    names = tuple(FIT_NAMES[c] for c in cols)
    info, rhs = prior.over(names)
    w = 1.0 / sigma**2

    def full_of(theta: np.ndarray) -> np.ndarray:
        v = np.zeros(len(FIT_NAMES))
        v[cols] = theta
        return v

    J = jacobian(keys, geometry, model)
    H = w * J.T @ J + info
    condition = _condition(H, names)
    theta = np.linalg.solve(H, w * J.T @ y + rhs)  # (7) is linear: exact there
    converged = True
    if method == "nonlinear":
        converged = False
        for _ in range(_MAX_STEPS):
            J = exact_jacobian(keys, geometry, full_of(theta), model)
            r = y - deviations(keys, geometry, full_of(theta))
            H = w * J.T @ J + info
            step = np.linalg.solve(H, w * J.T @ r + rhs - info @ theta)
            theta = theta + step
            if np.max(np.abs(step)) < _STEP_TOL:
                converged = True
                break
        J = exact_jacobian(keys, geometry, full_of(theta), model)
        H = w * J.T @ J + info
        model_values = deviations(keys, geometry, full_of(theta))
    else:
        model_values = linear_deviations(keys, geometry, full_of(theta))
    cov = np.linalg.inv(H)
    cov = (cov + cov.T) / 2.0
    std = np.sqrt(np.diag(cov))
    residuals = y - model_values
    gain = cov @ info  # ∂θ'/∂ℓ_p at the solution: (JᵀJ/σ² + I_p)⁻¹·Pᵀ·Σ_p⁻¹, (14)
    dof = len(y) - len(cols)
    predicted: dict = {}
    for key, value in zip(keys, model_values, strict=True):
        predicted.setdefault(key, float(value))
    return Identification(
        model=model, method=method, names=names,
        parameters={n: float(v) for n, v in zip(names, theta, strict=True)},
        std_errors={n: float(v) for n, v in zip(names, std, strict=True)},
        covariance=cov, correlation=cov / np.outer(std, std),
        residual_rms=float(np.sqrt(np.mean(residuals**2))),
        sigma=float(np.sqrt(residuals @ residuals / dof)) if dof > 0 else float("nan"),
        dof=dof, condition_number=condition, keys=tuple(keys), values=y,
        residuals=residuals, predicted=predicted, converged=converged,
        prior=PriorWeight(information=info, sigma=float(sigma)), prior_gain=gain)


def _condition(H: np.ndarray, names: Sequence[str]) -> float:
    """The condition number of the joined system (√ of its normal matrix's, scaled
    to unit diagonal); IdentificationError where it is singular."""
    d = np.sqrt(np.clip(np.diag(H), 1e-300, None))
    ev, vec = np.linalg.eigh(H / np.outer(d, d))
    if ev[0] <= _RANK_TOL * ev[-1]:
        involved = [n for n, v in zip(names, vec[:, 0], strict=True) if abs(v) > 0.1]
        raise IdentificationError(f"not identifiable with the prior: {', '.join(involved)} "
                                  "cannot be separated")
    return float(np.sqrt(ev[-1] / ev[0]))


#: How many times this fit's data the floor of :func:`prior_floor` assumes: "however
#: often the same stops are read again" made finite.
FLOOR_REPEATS = 100


def prior_floor(ident: Identification, geometry: Geometry) -> dict[str, float]:
    """The standard error of each parameter of the joined fit ``ident`` that its prior
    leaves however often the same stops were read again: (n·Jᵀ·J/σ² + I_p)^(-1/2)'s
    diagonal at n = :data:`FLOOR_REPEATS`, equation (12) of docs/model.md with the
    data's information n times over. Where the data alone cannot tell a combination
    (a uniform bow from a tilt at the legs' middles), the prior's uncertainty of it
    stays, and so does what it moves of Δρ: no further pass at the same stops can
    shrink that part. {} for a fit without a prior."""
    if ident.prior is None:
        return {}
    J = exact_jacobian(list(ident.keys), geometry, ident.fit_vector, ident.model)
    H = FLOOR_REPEATS * (J.T @ J) / ident.prior.sigma**2 + ident.prior.information
    C = np.linalg.inv(H)
    return {n: float(np.sqrt(max(C[i, i], 0.0))) for i, n in enumerate(ident.names)}


@dataclass(frozen=True)
class CarriedPrior:
    """How the prior a round carried was made and how it entered the round's Δρ: the
    prior ℓ_p (over ``names``) is Σ_s W_s·ℓ_s over earlier, independent fits ℓ_s
    (``weights``: source key → W_s, len(names) × the source's size: its own names for
    a fit carried whole, the pooling weights Σ_p·Σ_s⁻¹ for a pool), and it moves the
    round's Δρ by ``gain``·δℓ_p (3 × len(names): Δρ's rows of the fit's prior_gain)."""

    names: tuple[str, ...]
    gain: np.ndarray
    weights: Mapping[Any, np.ndarray]


def drho_gain(ident: Identification, names: Sequence[str]) -> np.ndarray:
    """∂Δρ/∂ℓ_p of a fit that carried a prior over ``names`` (3 × len(names); zeros for
    a fit that carried none): the Δρ rows of its ``prior_gain``."""
    out = np.zeros((3, len(names)))
    if ident.prior_gain is None:
        return out
    rows = [ident.names.index(f"drho_{a}") for a in "xyz"]
    for c, name in enumerate(names):
        if name in ident.names:
            out[:, c] = ident.prior_gain[rows, ident.names.index(name)]
    return out


def cross_covariance(k: CarriedPrior, r: CarriedPrior | None,
                     own_r: Mapping[Any, np.ndarray],
                     source_cov: Callable[[Any, Any], np.ndarray | None]) -> np.ndarray:
    """Cov(Δρ̂_k, Δρ̂_r) (3 × 3) of a round k that carried the prior ``k`` and an earlier
    round r (``r``: the prior it carried, None if none), docs/model.md, (14):

        Cov(Δρ̂_k, Δρ̂_r) = G_k · Σ_s W_ks · Cov(ℓ_s, Δρ̂_r),
        Cov(ℓ_s, Δρ̂_r) = X_s,rᵀ + Σ_s' Cov(ℓ_s, ℓ_s')·W_rs'ᵀ·G_rᵀ

    k's own data being independent of everything before it. ``own_r``: X_s,r =
    Cov(Δρ̂_r, ℓ_s) (3 × the source's size) for each source s that round r's own data
    made; ``source_cov(s, s')``: Cov(ℓ_s, ℓ_s') of two sources, None where independent."""
    total = np.zeros((len(k.names), 3))
    for s, W in k.weights.items():
        with_r = np.zeros((W.shape[1], 3)) if s not in own_r else np.asarray(own_r[s]).T
        if r is not None:
            for s2, W2 in r.weights.items():
                c = source_cov(s, s2)
                if c is not None:
                    with_r = with_r + c @ W2.T @ r.gain.T
        total += W @ with_r
    return k.gain @ total
