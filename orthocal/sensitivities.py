"""The sensitivity of an identification to its data: δθ = K·δΔ at the solution (GUM 5.1.3)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from orthocal.calibration import jacobian, linear_deviations
from orthocal.geometry import FIT_NAMES, Geometry
from orthocal.identification import Identification, exact_jacobian
from orthocal.measurement import Key, deviations
from orthocal.stands import incidence, prior_penalty, stand_jacobian

# How far (mm) the geometry given may reproduce an identification's model values off.
_GEOMETRY_TOL = 1e-9


def check_geometry(ident: Identification, geometry: Geometry) -> None:
    """Refuse a geometry that does not reproduce the identification's model values:
    the sensitivity would be that of another machine."""
    keys = list(ident.keys)
    if ident.method == "nonlinear":
        again = deviations(keys, geometry, ident.fit_vector, ident.mount_offsets)
    else:
        again = linear_deviations(keys, geometry, ident.fit_vector)
    model_values = np.asarray(ident.values) - np.asarray(ident.residuals)
    if not np.allclose(again, model_values, rtol=0.0, atol=_GEOMETRY_TOL):
        raise ValueError("this geometry does not reproduce the identification's model values: "
                         "give the geometry it was identified with")


def fit_design(ident: Identification, geometry: Geometry
               ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """(J_θ, J_M, Λ, C) of the identification at its solution: the Jacobian of its
    parameters (rows its ``keys``), and with stands their exact columns, their
    prior's penalty σ²/σ_M² (orthocal.stands) and the residual's curvature
    term (:func:`_stand_curvature`), else None, None, None."""
    keys = list(ident.keys)
    if ident.method != "nonlinear":
        return jacobian(keys, geometry, ident.model), None, None, None
    J_t = exact_jacobian(keys, geometry, ident.fit_vector, ident.model, ident.mount_offsets)
    if ident.stand_model is None:
        return J_t, None, None, None
    assert ident.stand_sigma is not None
    _, S = incidence(keys, ident.stand_model)  # columns in the order of ident.stands
    J_m = stand_jacobian(keys, geometry, ident.fit_vector, S)
    lam = prior_penalty(ident.stand_sigma, ident.stand_model, S.shape[1])
    return J_t, J_m, lam, _stand_curvature(ident, geometry)


def estimate_gain(J_t: np.ndarray, J_m: np.ndarray | None, lam: np.ndarray | None,
                  curvature: np.ndarray | None = None) -> np.ndarray:
    """The full linear map from the rows to the estimates (θ, then the stands)."""
    if J_m is None or lam is None:
        return np.linalg.pinv(J_t)
    A = np.hstack([J_t, J_m])
    p = J_t.shape[1]
    hessian = A.T @ A
    hessian[p:, p:] += lam
    if curvature is not None:
        hessian = hessian + curvature
    return np.linalg.solve(hessian, A.T)


def _stand_curvature(ident: Identification, geometry: Geometry) -> np.ndarray:
    """Σ_k r_k·∇²f_k over x = (θ, m) of a fit with stands, r = f − y at the
    solution: the residual's term of the objective's Hessian. Central differences
    of A = [J_θ, J_M] with steps of 1e-3 (mm, mrad; A is linear in m, smooth in θ)."""
    assert ident.stand_model is not None
    keys = list(ident.keys)
    _, S = incidence(keys, ident.stand_model)
    cols = [FIT_NAMES.index(n) for n in ident.names]
    x0 = np.concatenate([ident.fit_vector[cols], ident.stand_offsets])

    def A_at(x: np.ndarray) -> np.ndarray:
        full = np.zeros(len(FIT_NAMES))
        full[cols] = x[: len(cols)]
        return np.hstack([exact_jacobian(keys, geometry, full, ident.model, S @ x[len(cols):]),
                          stand_jacobian(keys, geometry, full, S)])

    f_minus_y, h = -np.asarray(ident.residuals), 1e-3
    steps = h * np.eye(len(x0))
    C = np.column_stack([(A_at(x0 + d) - A_at(x0 - d)).T @ f_minus_y / (2 * h) for d in steps])
    return 0.5 * (C + C.T)


def sensitivity(ident: Identification, geometry: Geometry | None = None) -> np.ndarray:
    """K (n_params × n_rows, rows ``ident.keys``): δθ = K·δΔ, the change of the
    identified parameters per change of each measured deviation, at the solution
    (GUM 5.1.3, the sensitivity coefficients).

    A fit joined with a prior (its ``prior``): the data's share of its gain, the
    prior's information added to JᵀJ as the stands' is. The identification's own
    Jacobian J (orthocal.identification.exact_jacobian
    at the solution; (7) for the linear method), pseudo-inverted: K = J⁺. With
    the stands modelled (orthocal.stands) the estimate minimises
    |f(θ, m) − y|² + mᵀΛm, A = [J_θ, J_M], Λ = σ²/σ_M² on the stands, and
    K is the parameters' rows of (AᵀA + Λ + C)⁻¹Aᵀ, the stands taking their
    share of a deviation error as the fit does; C = Σ r_k·∇²f_k is the
    residual's curvature term, kept here because the stands' block of AᵀA is
    weak (~1e-5: the stands act through the offsets' small slopes) and the
    residual times the cross-curvature ∂J_M/∂θ (~1e-6) moves K by ~0.5 %;
    without stands it moves K by < 1e-4 and is left out.

    ``geometry``: the one identified with (None: the default Geometry); one that
    does not reproduce the identification's model values raises ValueError.
    """
    geometry = geometry or Geometry()
    check_geometry(ident, geometry)
    if ident.prior is not None:
        # a fit joined with a prior (orthocal.carry.joined_fit): the data's share of
        # its gain, (JᵀJ + σ²·I_p)⁻¹Jᵀ; the prior takes the rest
        J_t = fit_design(ident, geometry)[0]
        s2 = ident.prior.sigma**2
        return np.linalg.solve(J_t.T @ J_t + s2 * ident.prior.information, J_t.T)
    return estimate_gain(*fit_design(ident, geometry))[: len(ident.names)]


def key_sensitivity(ident: Identification, geometry: Geometry | None = None
                    ) -> tuple[list[Key], np.ndarray]:
    """(distinct keys, K_d): the sensitivity to a systematic error of each distinct
    deviation, the same in all its cycles: K_d[:, d] = Σ_rows of key d K[:, r]."""
    keys = list(ident.keys)
    distinct = list(dict.fromkeys(keys))
    return distinct, sensitivity(ident, geometry) @ rows_of(keys, distinct)


def rows_of(keys: Sequence[Key], distinct: Sequence[Key]) -> np.ndarray:
    """P (n_rows × n_distinct): P[r, d] = 1 when row r measures key d."""
    index = {k: n for n, k in enumerate(distinct)}
    P = np.zeros((len(keys), len(distinct)))
    P[np.arange(len(keys)), [index[k] for k in keys]] = 1.0
    return P
