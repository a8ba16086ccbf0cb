"""Identification of Δρ, ΔL and the axis tilts from measured deviations
(docs/model.md, "Identification" and "Extended model").

``linear``: the paper's Moore–Penrose solution of the linearised system (7).
``nonlinear``: least squares on the exact model (1), started from the linear
solution; it removes the linearisation bias of (7), several µm at offsets of a
few mm.

Statistics follow ordinary least squares: σ̂ = sqrt(RSS/(n − p)), covariance
σ̂²·(JᵀJ)⁻¹ with J the Jacobian at the solution, standard errors its diagonal's
root. A known indicator noise ``sigma`` may replace σ̂ (e.g. with few
redundant deviations, where σ̂ rests on very few degrees of freedom).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from orthocal.batched import deviations_batch
from orthocal.calibration import jacobian, linear_deviations
from orthocal.geometry import FIT_NAMES, MODELS, PARAM_NAMES, TILT_NAMES, Geometry, fit_params
from orthocal.inputs import IdentificationError, flatten_deviations
from orthocal.measurement import Key, deviations
from orthocal.noise import noise_from_cycles
from orthocal.numbers import finite
from orthocal.stands import (
    StandEstimate,
    Stands,
    incidence,
    prior_penalty,
    ridge_covariance,
    stand_estimates,
    stand_gauges,
    stand_jacobian,
)

METHODS = ("linear", "nonlinear")
# Relative singular value below which a parameter combination counts as not
# identifiable; the worst well-posed case (full model, 12 deviations) sits at 1/62.
_RANK_TOL = 1e-9
# σ (mm) below which the start of a fit with stands is not weighted (see there).
_START_SIGMA = 1e-3


@dataclass(frozen=True)
class PriorWeight:
    """What a joined fit (orthocal.carry.joined_fit) added to the data's normal
    equations: the prior's ``information`` over the fit's names (mm⁻², mrad⁻²; zero
    rows and columns for names without a prior) against data rows weighed by
    ``sigma`` (mm). The covariance and the sensitivity of such a fit need it: its
    data Jacobian alone may be singular (a uniform bow is a tilt at the middles)."""

    information: np.ndarray
    sigma: float


@dataclass(frozen=True)
class Identification:
    """Result of :func:`identify`. Lengths in mm."""

    model: str
    method: str
    names: tuple[str, ...]
    parameters: dict[str, float]
    std_errors: dict[str, float]
    covariance: np.ndarray
    correlation: np.ndarray
    residual_rms: float
    sigma: float
    dof: int
    condition_number: float
    keys: tuple[Key, ...]
    values: np.ndarray
    residuals: np.ndarray
    predicted: dict[Key, float] = field(default_factory=dict)
    converged: bool = True
    #: Degrees of freedom behind ``std_errors``: the fit's ``dof`` when they come
    #: from its own residual, the noise estimate's when from the measured noise
    #: (orthocal.covariance.with_measured_noise). Sets the coverage factor.
    se_dof: float | None = None
    #: The indicator stands, when they were modelled (``identify(..., stands=)``):
    #: each stand's position, mm off L/2, with its posterior SD, or not observable
    #: (orthocal.stands). Empty without the option.
    stands: dict[str, StandEstimate] = field(default_factory=dict)
    #: The option the stands were modelled with (None: not modelled).
    stand_model: Stands | None = None
    #: σ of one deviation that weighed the stands' prior against the data (mm).
    stand_sigma: float | None = None
    #: Another model that explains the same deviations as well (``ambiguous_with``:
    #: the legs' bows where these are the axes' tilts; at the legs' middles a uniform
    #: bow is a tilt, docs/model.md "Leg form against tilts and gaps") and how far its
    #: parameters lie from these, per shared parameter (mm): what the data cannot
    #: decide. Empty where nothing was found to explain them as well.
    ambiguity_mm: dict[str, float] = field(default_factory=dict)
    ambiguous_with: str | None = None
    #: An earlier measurement of some parameters joined into this fit as
    #: pseudo-observations (orthocal.carry.joined_fit), None for the data's alone.
    prior: PriorWeight | None = None
    #: How an earlier measurement joined into this fit (orthocal.carry: ``carried``,
    #: ``joined_fit``) moves it: ∂θ/∂ℓ_p over ``names`` × ``names``, nonzero only in the
    #: columns of the prior's names, so that the prior's error enters the parameters as
    #: prior_gain · δℓ_p (docs/model.md, "Rounds that carry an earlier round", (14)).
    #: None for the data's alone.
    prior_gain: np.ndarray | None = None

    @property
    def std_error_dof(self) -> float:
        return float(self.dof if self.se_dof is None else self.se_dof)

    @property
    def stand_offsets(self) -> np.ndarray:
        """The stands' estimated offsets (mm off L/2) in the order of ``stands``."""
        return np.array([e.offset for e in self.stands.values()])

    @property
    def mount_offsets(self) -> np.ndarray | None:
        """Each row's indicator-plane offset from L/2 as identified (mm), for
        :func:`orthocal.deviations`; None when the stands were not modelled."""
        if self.stand_model is None:
            return None
        _, S = incidence(self.keys, self.stand_model)
        return S @ self.stand_offsets

    @property
    def vector(self) -> np.ndarray:
        """The machine's twelve parameters in PARAM_NAMES order (those not in the
        model are 0)."""
        return self.fit_vector[:len(PARAM_NAMES)]

    @property
    def fit_vector(self) -> np.ndarray:
        """Every parameter the fit may name, FIT_NAMES order: the twelve of the
        geometry, then the legs' bows (those not in the model are 0); what the
        exact model needs to give back the fit's model values."""
        return np.array([self.parameters.get(n, 0.0) for n in FIT_NAMES])

    def to_dict(self) -> dict:
        """JSON-ready summary (docs/design.md's identify fields plus statistics)."""

        return {
            "model": self.model,
            "method": self.method,
            "parameters": {k: finite(v) for k, v in self.parameters.items()},
            "std_errors": {k: finite(v) for k, v in self.std_errors.items()},
            "residual_rms_mm": finite(self.residual_rms),
            "sigma_mm": finite(self.sigma),
            "dof": self.dof,
            "std_errors_dof": finite(self.std_error_dof),
            "condition_number": finite(self.condition_number),
            "n_deviations": len(self.keys),
            "correlation": {
                "names": list(self.names),
                "matrix": [[finite(v) for v in row] for row in self.correlation],
            },
            "predicted": {"".join(k): finite(v) for k, v in self.predicted.items()},
            "converged": self.converged,
        } | ({} if self.stand_model is None else {"stands": {
            **self.stand_model.to_dict(),
            "sigma_mm": finite(self.stand_sigma) if self.stand_sigma is not None else None,
            "estimates": {n: e.to_dict() for n, e in self.stands.items()}}}) \
          | ({} if not self.ambiguity_mm else {
              "ambiguous_with": self.ambiguous_with,
              "ambiguity_mm": {k: finite(v) for k, v in self.ambiguity_mm.items()}})


def _postures_per_leg(keys: Sequence[Key]) -> int:
    """The fewest distinct test postures any measured leg was seen in."""
    seen: dict[str, set[str]] = {}
    for sign, leg, _ in keys:
        seen.setdefault(leg, set()).add(sign)
    return min((len(v) for v in seen.values()), default=0)


def _why_inseparable(involved: Sequence[str], keys: Sequence[Key]) -> str:
    """The reason in words for the usual rank deficiency, '' when there is no known one."""
    has_l = any(n.startswith("dL_") for n in involved)
    has_tilt = any(n in TILT_NAMES for n in involved)
    if has_l and has_tilt and _postures_per_leg(keys) <= 2:
        return (": with two postures per leg ΔL cannot be separated from the tilts (a common "
                "change of offsets, leg lengths and axis angles leaves every deviation as it "
                "is); measure more stops per leg, or identify rho+tilt")
    return ""


def _check_identifiable(
    J: np.ndarray, names: Sequence[str], n_distinct: int, keys: Sequence[Key] = ()
) -> float:
    """Refuse what the data cannot determine; return the condition number of J."""
    p = J.shape[1]
    if n_distinct < p:
        raise IdentificationError(
            f"too few deviations: {n_distinct} distinct deviation(s) for {p} parameters "
            f"({', '.join(names)})"
        )
    _, s, vt = np.linalg.svd(J, full_matrices=False)
    if s[-1] <= _RANK_TOL * s[0]:
        null = vt[-1]
        involved = [nm for nm, w in zip(names, null, strict=True) if abs(w) > 0.1]
        why = _why_inseparable(involved, keys) or (
            "; measure more legs or directions, or identify fewer parameters")
        raise IdentificationError(
            "not identifiable from these deviations: "
            f"{', '.join(involved)} cannot be separated (rank {int(np.sum(s > _RANK_TOL * s[0]))}"
            f" < {p}){why}"
        )
    return float(s[0] / s[-1])


# Said in every report: the measurements see angles between legs' lines, never the
# machine's orientation against the base (docs/model.md, "Extended model").
ROTATION_NOTE = (
    "A rotation of the whole machine against the base cannot be identified: it changes "
    "no deviation (every leg still translates along its own line). Only the angles "
    "between the actuator axes are observable; the tilts are stated in the frame of "
    "the x axis and the x–y plane of the x and y axes."
)


def cannot_identify(keys: Sequence[Key], geometry: Geometry | None = None,
                    model: str = "full+tilt") -> list[str]:
    """What these deviations can never determine, in sentences for the report:
    always a rotation of the whole machine; and, when ``model`` is rank-deficient
    with these ``keys``, which parameters cannot be separated and why."""
    geometry = geometry or Geometry()
    notes = [ROTATION_NOTE]
    if model not in MODELS:
        raise IdentificationError(f"model must be one of {sorted(MODELS)}, got {model!r}")
    keys = list(keys)
    names = tuple(FIT_NAMES[c] for c in MODELS[model])
    try:
        _check_identifiable(jacobian(keys, geometry, model), names, len(set(keys)), keys)
    except IdentificationError as exc:
        notes.append(f"Model {model}: {exc}.")
    return notes


def exact_jacobian(
    keys: Sequence[Key], geometry: Geometry, params=None, model: str = "full",
    mount_offsets=None,
) -> np.ndarray:
    """Jacobian of the exact deviations (1') at ``params`` (9-vector, or a 6-vector
    without tilts), columns the parameters of ``model``; central differences with
    h = 1e-5 mm or mrad (truncation error O(h²·curvature) ≈ 1e-12, far below any
    µm). At zero it equals (7'). ``mount_offsets``: each row's indicator plane
    off L/2 (mm; :func:`orthocal.measurement.deviations`), None for L/2."""
    base = fit_params(params)
    h = 1e-5
    cols = list(MODELS[model])
    # every column's two evaluations in one batched solve (orthocal.batched): one by
    # one, numpy's per-call overhead was most of a fit's time
    steps = np.zeros((2 * len(cols), len(FIT_NAMES)))
    steps[0::2][np.arange(len(cols)), cols] = h
    steps[1::2][np.arange(len(cols)), cols] = -h
    D = deviations_batch(keys, geometry, base + steps, mount_offsets)
    return ((D[0::2] - D[1::2]) / (2 * h)).T


def identify(
    deviations_in: Mapping | Iterable,
    geometry: Geometry | None = None,
    model: str = "rho",
    method: str = "nonlinear",
    sigma: float | None = None,
    stands: Stands | None = None,
) -> Identification:
    """Identify the parameters of ``model`` from measured deviations.

    ``deviations_in`` maps ``(sign, leg, direction)`` keys, e.g. ``("+", "x", "y")``,
    to a deviation in mm or to a sequence of repeated measurements of it; any
    subset of the 12 deviations that determines the model will do.
    ``model``: 'rho' (Δρ only), 'L' (ΔL only), 'full' (both; ill-conditioned),
    'rho+tilt' (Δρ and the three axis tilts, mrad) or 'full+tilt' (all nine; needs
    more than two postures per leg).
    ``method``: 'linear' (pseudoinverse of (7)) or 'nonlinear' (exact model (1)).
    ``sigma``: known noise σ of one deviation; default σ̂ from the residuals.
    ``stands``: model the indicator stands' positions too (:class:`orthocal.stands.Stands`:
    which gauges share a stand, their placement tolerance): random effects with
    the tolerance's prior, the parameters by least squares and the stands by
    their posterior mean (orthocal.stands; docs/model.md, "Where the indicator plane
    is"). The prior is weighed against the data by σ of one deviation:
    ``sigma``, or (None) the cycle-to-cycle scatter of the repeats
    (orthocal.noise.noise_from_cycles). The result's ``stands`` holds each
    stand's offset from L/2 with its SD, or says it is not observable. None (the
    default): the stands are taken at L/2, as without this option.
    """
    geometry = geometry or Geometry()
    if model not in MODELS:
        raise IdentificationError(f"model must be one of {sorted(MODELS)}, got {model!r}")
    if method not in METHODS:
        raise IdentificationError(f"method must be one of {METHODS}, got {method!r}")
    if sigma is not None and not (np.isfinite(sigma) and sigma > 0):
        raise IdentificationError(f"sigma must be a positive number, got {sigma!r}")
    keys, y = flatten_deviations(deviations_in)
    cols = MODELS[model]
    names = tuple(FIT_NAMES[c] for c in cols)
    J0 = jacobian(keys, geometry, model) if keys else np.zeros((0, len(cols)))
    condition = _check_identifiable(J0, names, len(set(keys)), keys)
    if stands is not None:
        return _identify_with_stands(deviations_in, keys, y, geometry, model, method, sigma,
                                     stands, J0, condition)

    x_lin = np.linalg.pinv(J0) @ y
    full = np.zeros(len(FIT_NAMES))
    full[list(cols)] = x_lin
    converged = True
    if method == "nonlinear":
        # Imported here: scipy.optimize costs ~0.3 s, which the station would
        # otherwise spend at start-up, before its first move.
        from scipy.optimize import least_squares

        def residual(x: np.ndarray) -> np.ndarray:
            trial = np.zeros(len(FIT_NAMES))
            trial[list(cols)] = x
            return deviations(keys, geometry, trial) - y

        def jac(x: np.ndarray) -> np.ndarray:
            trial = np.zeros(len(FIT_NAMES))
            trial[list(cols)] = x
            return exact_jacobian(keys, geometry, trial, model)

        try:
            sol = least_squares(
                residual, x_lin, jac=jac, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14
            )
        except ValueError as exc:  # the exact model left its assembly domain
            raise IdentificationError(f"nonlinear fit failed: {exc}") from None
        full[list(cols)] = sol.x
        converged = bool(sol.success)
        J = jac(sol.x)
    else:
        J = J0

    if method == "nonlinear":
        model_values = deviations(keys, geometry, full)
    else:
        model_values = linear_deviations(keys, geometry, full)
    fit = _Fit.of(y, model_values, len(cols))
    scale = sigma if sigma is not None else fit.sigma_hat
    jtj_inv = np.linalg.inv(J.T @ J)
    d = np.sqrt(np.diag(jtj_inv))
    return fit.identification(model, method, cols, full, keys, scale**2 * jtj_inv,
                              jtj_inv / np.outer(d, d), condition, converged)


@dataclass(frozen=True)
class _Fit:
    """The residuals of a fit (:meth:`of`), and what they give."""

    y: np.ndarray
    model_values: np.ndarray
    residuals: np.ndarray
    rss: float
    dof: int

    @classmethod
    def of(cls, y: np.ndarray, model_values: np.ndarray, p: int) -> _Fit:
        """A fit of ``p`` parameters whose model gives ``model_values`` for ``y``."""
        residuals = y - model_values
        return cls(y, model_values, residuals, float(residuals @ residuals), len(y) - p)

    @property
    def sigma_hat(self) -> float:
        """√(RSS/dof), the noise the residuals show (nan without dof)."""
        return float(np.sqrt(self.rss / self.dof)) if self.dof > 0 else float("nan")

    def identification(self, model: str, method: str, cols: Sequence[int], full: np.ndarray,
                       keys: list[Key], covariance: np.ndarray, correlation: np.ndarray,
                       condition: float, converged: bool, **extra: Any) -> Identification:
        """The result, parameters ``full[cols]`` with the standard errors of
        ``covariance``; ``extra``: the stands' fields."""
        names = tuple(FIT_NAMES[c] for c in cols)
        std = np.sqrt(np.diag(covariance))
        predicted: dict[Key, float] = {}
        for key, value in zip(keys, self.model_values, strict=True):
            predicted.setdefault(key, float(value))
        return Identification(
            model=model,
            method=method,
            names=names,
            parameters={nm: float(full[c]) for nm, c in zip(names, cols, strict=True)},
            std_errors={nm: float(s) for nm, s in zip(names, std, strict=True)},
            covariance=covariance,
            correlation=correlation,
            residual_rms=float(np.sqrt(self.rss / len(self.y))),
            sigma=self.sigma_hat,
            dof=self.dof,
            condition_number=condition,
            keys=tuple(keys),
            values=self.y,
            residuals=self.residuals,
            predicted=predicted,
            converged=converged,
            **extra,
        )


def _stand_sigma(deviations_in, sigma: float | None) -> tuple[float, float | None]:
    """σ of one deviation that weighs the stands' prior, and its dof (None: given)."""
    if sigma is not None:
        return float(sigma), None
    try:
        s, dof = noise_from_cycles(deviations_in)
    except ValueError as exc:
        raise IdentificationError(
            "modelling the stands needs the noise of one deviation, to weigh their prior: "
            f"give sigma, or measure two cycles or more ({exc})") from None
    if not s > 0:
        raise IdentificationError("modelling the stands needs a positive noise; the repeats "
                                  "do not scatter: give sigma")
    return s, float(dof)


def _identify_with_stands(
    deviations_in, keys: list[Key], y: np.ndarray, geometry: Geometry, model: str, method: str,
    sigma: float | None, stands: Stands, J0: np.ndarray, condition: float,
) -> Identification:
    """:func:`identify` with the stands as random effects (orthocal.stands):
    minimise Σ r²/σ² + Σ m²/σ_M² over the model's parameters θ and the stands m,
    r the rows' residuals of the exact model read in the planes L/2 + S·m."""
    if method != "nonlinear":
        raise IdentificationError(
            "the stands act through the product of their offset and the legs' slopes, which "
            "the linearised system (7) lacks: model the stands with method 'nonlinear'")
    sig, sig_dof = _stand_sigma(deviations_in, sigma)
    rows = tuple(keys)  # one object for every step's KeyTable (orthocal.measurement)
    cols = list(MODELS[model])
    p = len(cols)
    stand_names, S = incidence(keys, stands)
    k = len(stand_names)
    penalty = prior_penalty(sig, stands, k)

    def full_of(theta: np.ndarray) -> np.ndarray:
        v = np.zeros(len(FIT_NAMES))
        v[cols] = theta
        return v

    # Start: the linear solution without stands, then the stands' columns from the
    # exact model at it and a penalised linear solve (twice: the columns follow θ).
    # The start's penalty is at least that of 1 µm of noise: (7)'s linearisation
    # error (µm) must not drive the weakly seen combinations of stands far off.
    theta = np.linalg.pinv(J0) @ y
    m = np.zeros(k)
    lam = np.zeros((p + k, p + k))
    lam[p:, p:] = prior_penalty(max(sig, _START_SIGMA), stands, k)
    for _ in range(2):
        A = np.hstack([J0, stand_jacobian(keys, geometry, full_of(theta), S)])
        x = np.linalg.solve(A.T @ A + lam, A.T @ y)
        theta, m = x[:p], x[p:]
    from scipy.optimize import least_squares

    prior_w = 1.0 / stands.prior_sd

    def residual(x: np.ndarray) -> np.ndarray:
        r = deviations(rows, geometry, full_of(x[:p]), S @ x[p:]) - y
        return np.concatenate([r / sig, x[p:] * prior_w])

    def jac(x: np.ndarray) -> np.ndarray:
        full = full_of(x[:p])
        Jt = exact_jacobian(rows, geometry, full, model, S @ x[p:])
        Jm = stand_jacobian(rows, geometry, full, S)
        lower = np.hstack([np.zeros((k, p)), prior_w * np.eye(k)])
        return np.vstack([np.hstack([Jt, Jm]) / sig, lower])

    try:
        sol = least_squares(residual, np.concatenate([theta, m]), jac=jac, method="lm",
                            xtol=1e-14, ftol=1e-14, gtol=1e-14)
    except ValueError as exc:
        raise IdentificationError(f"nonlinear fit failed: {exc}") from None
    theta, m = sol.x[:p], sol.x[p:]
    converged = bool(sol.success)
    full = full_of(theta)
    A = np.hstack([exact_jacobian(keys, geometry, full, model, S @ m),
                   stand_jacobian(keys, geometry, full, S)])
    fit = _Fit.of(y, deviations(keys, geometry, full, S @ m), p)
    cov_all = ridge_covariance(A, p, penalty, sig**2 * np.eye(len(y)), stands.prior_sd**2)
    covariance = cov_all[:p, :p]
    std = np.sqrt(np.diag(covariance))
    gauges = stand_gauges(stand_names, stands, keys)
    return fit.identification(
        model, method, cols, full, keys, covariance, covariance / np.outer(std, std),
        condition, converged, se_dof=sig_dof,
        stands=stand_estimates(stand_names, gauges, m, cov_all[p:, p:], stands),
        stand_model=stands, stand_sigma=sig)
