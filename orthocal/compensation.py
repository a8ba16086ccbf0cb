"""The identified machine in the controller (docs/model.md, "The geometry in the
controller"): what a controller commands when it knows the machine the run
identified, and how far the tool then lands from where it was sent.

A controller turns a tool point p into joints through its kinematics. With the
identified machine θ_c (Δρ left after the offsets written, ΔL, tilts, gaps) in
its kinematics it commands

    ρ = IK_c(p) = inverse(p, geometry, Δρ_c, ΔL_c, tilt_c, gap_c)          (K1)

(the kinematics route: orthoglidekins.comp). A controller that keeps its nominal
kinematics commands ρ = IK_nominal(p'), so a program rewritten to

    p' = FK_nominal(IK_c(p))                                                (K2)

makes it command the same joints (the program route: ``orthocal compensate``).
Either way the real machine θ puts the tool at

    P(p) = FK_θ(IK_c(p)),      E_c(p) = P(p) − p                            (K3)

which is zero where θ_c is θ: what is left is the identification's error and
whatever the controller was not told. Pure: numpy arrays in, numpy arrays out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthocal.accuracy import (
    DIFF_STEP,
    FRAMES,
    ErrorField,
    covariance_matrix,
    field_stats,
    fit_frame,
    parameter_vector,
)
from orthocal.geometry import PARAM_NAMES, Geometry, split_params
from orthocal.joint_error import Direction, JointErrors
from orthocal.kinematics import forward, inverse


def controller_joints(points, geometry: Geometry, theta_c) -> np.ndarray:
    """ρ = IK_c(p) (K1): the joints a controller with the machine ``theta_c`` (12-,
    9- or 6-vector of PARAM_NAMES, or a dict by name) in its kinematics commands for
    the tool points ``points`` (..., 3) mm. ValueError beyond a leg's reach."""
    drho, dL, tilt, gap = split_params(parameter_vector(theta_c))
    return inverse(np.asarray(points, dtype=float), geometry, drho, dL, tilt, gap)


def compensated_points(points, geometry: Geometry, theta_c) -> np.ndarray:
    """p' = FK_nominal(IK_c(p)) (K2): where to send a controller with nominal
    kinematics so that it commands the joints the machine ``theta_c`` needs for p."""
    return forward(controller_joints(points, geometry, theta_c), geometry)


def nominal_path(points_sent, geometry: Geometry, theta_c) -> np.ndarray:
    """Where the tool of the machine ``theta_c`` goes when a nominal controller is
    sent to ``points_sent``: FK_c(IK_nominal(p')), the inverse of (K2)."""
    drho, dL, tilt, gap = split_params(parameter_vector(theta_c))
    return forward(inverse(np.asarray(points_sent, dtype=float), geometry), geometry,
                   drho, dL, tilt, gap)


def landed(joints, geometry: Geometry, truth, joint_errors: JointErrors | None = None,
           direction: Direction = "mean") -> np.ndarray:
    """P = FK_θ(ρ): where the real machine ``truth`` puts the tool for joints ρ
    (the joint frame of θ: the offsets in the controller are already in its Δρ).
    ``joint_errors``: each joint's ε (docs/model.md, "Joint positioning errors"),
    taken at the joints commanded and ``direction``: P = FK_θ(ρ + ε(ρ, direction)).
    The offsets written since the joints were tested move where on its screw a
    joint stands by o, which this leaves out: ε'·o, 0.1 µm for 100 µm/m and 1 mm.
    None: exact joints, bit for bit as without the argument."""
    drho, dL, tilt, gap = split_params(parameter_vector(truth))
    rho = np.asarray(joints, dtype=float)
    if joint_errors is not None:
        rho = joint_errors.joints(rho, direction)
    return forward(rho, geometry, drho, dL, tilt, gap)


def compensated_error(points, geometry: Geometry, truth, theta_c,
                      joint_errors: JointErrors | None = None,
                      direction: Direction = "mean") -> np.ndarray:
    """E_c(p) = FK_θ(IK_c(p)) − p (K3), (n, 3) mm; ``joint_errors`` and
    ``direction`` as for :func:`landed` (None: exact joints)."""
    p = np.asarray(points, dtype=float)
    return landed(controller_joints(p, geometry, theta_c), geometry, truth, joint_errors,
                  direction) - p


def compensated_field(points, geometry: Geometry, truth, theta_c,
                      frame: str = "translation", joint_errors: JointErrors | None = None,
                      direction: Direction = "mean") -> ErrorField:
    """(K3) over ``points`` after ``frame`` (docs/model.md, "Accuracy at the tool"),
    with its RMS and max of |E|; ``joint_errors`` and ``direction`` as for
    :func:`landed` (None: exact joints)."""
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    p = np.asarray(points, dtype=float)
    fitted = fit_frame(p, compensated_error(p, geometry, truth, theta_c, joint_errors,
                                            direction), frame)
    rms, mx = field_stats(fitted)
    return ErrorField(frame, rms, mx, fitted, p, np.zeros(3))


def truth_jacobian(points, geometry: Geometry, truth, theta_c, frame: str,
                   columns) -> np.ndarray:
    """∂ fit_frame(E_c)/∂θ over the real machine's parameters ``columns`` (3n ×
    len(columns), mm per mm or mrad), the controller's joints held: central
    differences (h = DIFF_STEP) of the exact forward kinematics."""
    p = np.asarray(points, dtype=float)
    rho = controller_joints(p, geometry, theta_c)
    theta = parameter_vector(truth)
    G = np.empty((p.size, len(columns)))
    for k, c in enumerate(columns):
        step = np.zeros(len(PARAM_NAMES))
        step[c] = DIFF_STEP
        plus = fit_frame(p, landed(rho, geometry, theta + step) - p, frame)
        minus = fit_frame(p, landed(rho, geometry, theta - step) - p, frame)
        G[:, k] = (plus - minus).ravel() / (2 * DIFF_STEP)
    return G


@dataclass(frozen=True, eq=False)
class CompensatedInterval:
    """The tool error with the machine ``theta_c`` in the controller, predicted
    (see :func:`compensated_interval`): RMS and max of |E| (mm) and their
    ``level`` intervals; ``point_rms_mm`` the |E| expected at each point (the root
    mean square over the parameters' error), whose RMS over the points is
    ``rms_mm``."""

    field: ErrorField
    rms_mm: float
    max_mm: float
    point_rms_mm: np.ndarray
    rms_interval_mm: tuple[float, float]
    max_interval_mm: tuple[float, float]
    level: float
    dof: float | None
    method: str


def _draws(k: int, dof: float | None, draws: int, seed: int) -> np.ndarray:
    """``draws`` standard normal (or Student t with ``dof``) k-vectors."""
    rng = np.random.default_rng(seed)
    z = rng.standard_normal((draws, k))
    if dof is not None and np.isfinite(dof):
        if dof <= 0:
            raise ValueError(f"dof must be > 0, got {dof}")
        z /= np.sqrt(rng.chisquare(dof, size=(draws, 1)) / dof)
    return z


def _root(cov: np.ndarray) -> np.ndarray:
    """L with L·Lᵀ = cov (+ 1e-12 of its largest variance on the diagonal, so that a
    covariance singular by an exact correlation factors too): Cholesky, which is
    unique and continuous in cov, so the Monte Carlo draws are the same machines on
    every CPU and BLAS (an eigenvector basis is not: near-equal eigenvalues turn it)."""
    scale = float(np.max(np.diag(cov)))
    try:
        return np.linalg.cholesky(cov + np.eye(len(cov)) * 1e-12 * scale)
    except np.linalg.LinAlgError:  # not positive semi-definite beyond rounding: its part
        w, V = np.linalg.eigh(cov)  # that is, which any root gives alike
        return V * np.sqrt(np.clip(w, 0.0, None))


def compensated_interval(theta_c, estimate, covariance, dof: float | None, points,
                         geometry: Geometry | None = None, frame: str = "translation",
                         systematic=None, level: float = 0.95, draws: int = 4000,
                         seed: int = 0, absent=None) -> CompensatedInterval:
    """The tool error (K3) a controller with the machine ``theta_c`` leaves on the
    real machine, which the run knows as ``estimate`` (12-vector: θ_c where the
    controller was told a parameter, the run's best value where it was not) with
    the covariance ``covariance`` (any form :func:`covariance_matrix` takes) on
    ``dof`` degrees of freedom (None: normal).

    Linearised in the real machine's error δ: F(θ) = F₀ + G·δ, F₀ the fitted field
    at the estimate (zero where the controller was told everything), G
    (:func:`truth_jacobian`) over the parameters with a variance.

    - ``rms_mm``: the root mean square over δ of the field's RMS,
      sqrt(‖F₀‖² + tr(GᵀG·Σ)/n) (Σ·ν/(ν − 2) for Student t): the figure to expect
      when the estimate's error is what its covariance says. It takes the
      statistical covariance alone;
    - ``max_mm``: the median over δ of max |E|;
    - the intervals: from the (1 − level)/2 quantile over δ drawn from Σ to the
      (1 + level)/2 quantile over δ drawn from Σ + ``systematic`` (what bounded
      systematic errors, the legs' form, may leave in the parameters: anywhere
      from none to their bound), Monte Carlo with ``draws`` seeded draws.

    ``absent`` (12 booleans, default none): the parameters the controller is not told
    because the model test did not keep them, whose estimate is then noise about a
    value that may well be nominal. Their estimate's own noise is in F₀ already, so
    ``rms_mm`` takes |F₀|² less its expectation tr(G_a·Σ_a·G_aᵀ) (an unbiased
    estimate of their field, never below zero) where it would otherwise count that
    noise twice; and the interval's lower end is also taken where they are exactly
    nominal (the model test's hypothesis, drawn over the told parameters' error
    alone), the lesser of the two, since a quantile of |F₀ + G·δ| over δ never reaches
    a field the Gaussian cannot draw.

    ``field`` is F₀, ``point_rms_mm`` sqrt(|F₀_k|² + tr(G_k·Σ·G_kᵀ)) at each point k.
    A parameter with no variance is taken as exactly known."""
    geometry = geometry or Geometry()
    if not 0 < level < 1:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    theta_c = parameter_vector(theta_c)
    estimate = parameter_vector(estimate)
    cov = covariance_matrix(covariance)
    wide = cov if systematic is None else cov + covariance_matrix(systematic)
    if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(wide))):
        raise ValueError("covariance has non-finite entries")
    p = np.asarray(points, dtype=float)
    base = compensated_field(p, geometry, estimate, theta_c, frame)
    F0 = base.field.ravel()
    n = len(p)
    columns = [c for c in range(len(PARAM_NAMES)) if wide[c, c] > 0]
    if not columns:
        return CompensatedInterval(base, base.rms_mm, base.max_mm,
                                   np.linalg.norm(base.field, axis=1), (base.rms_mm,) * 2,
                                   (base.max_mm,) * 2, level, None, "no parameter error")
    G = truth_jacobian(p, geometry, estimate, theta_c, frame, columns)
    stat = [k for k, c in enumerate(columns) if cov[c, c] > 0]
    t_var = 1.0 if dof is None or not np.isfinite(dof) or dof <= 2 else dof / (dof - 2.0)
    B = G[:, stat] @ _root(cov[np.ix_(*[[columns[k] for k in stat]] * 2)]) if stat else \
        np.zeros((G.shape[0], 1))
    point_var = t_var * (B**2).reshape(n, -1).sum(axis=1)  # each point's 3 rows
    point_rms = np.sqrt(np.linalg.norm(base.field, axis=1)**2 + point_var)
    rms = float(np.sqrt(np.mean(point_rms**2)))
    stat_rms, stat_max = _field_draws(F0, B, _draws(B.shape[1], dof, draws, seed), n)
    wide_root = G @ _root(wide[np.ix_(columns, columns)])
    wide_rms, wide_max = _field_draws(F0, wide_root, _draws(len(columns), dof, draws, seed),
                                      n)
    lo, hi = (1.0 - level) / 2.0, (1.0 + level) / 2.0
    if absent is not None and np.any(absent):
        rms, low_rms, low_max = _absent(p, geometry, estimate, theta_c, frame, cov, dof,
                                        np.asarray(absent, dtype=bool), F0, t_var,
                                        draws, seed, lo)
        lower = (min(float(np.quantile(stat_rms, lo)), low_rms),
                 min(float(np.quantile(stat_max, lo)), low_max))
    else:
        lower = (float(np.quantile(stat_rms, lo)), float(np.quantile(stat_max, lo)))
    law = "normal" if dof is None or not np.isfinite(dof) else f"Student t, {dof:g} dof"
    return CompensatedInterval(
        field=base, rms_mm=rms, max_mm=float(np.median(stat_max)), point_rms_mm=point_rms,
        rms_interval_mm=(lower[0], float(np.quantile(wide_rms, hi))),
        max_interval_mm=(lower[1], float(np.quantile(wide_max, hi))),
        level=level, dof=None if dof is None or not np.isfinite(dof) else float(dof),
        method=("the real machine's error propagated through the exact model, linearised "
                f"({law}; Monte Carlo quantiles, {draws} draws)"))


def _absent(p: np.ndarray, geometry: Geometry, estimate: np.ndarray, theta_c: np.ndarray,
            frame: str, cov: np.ndarray, dof: float | None, absent: np.ndarray,
            F0: np.ndarray, t_var: float, draws: int, seed: int,
            lo: float) -> tuple[float, float, float]:
    """For :func:`compensated_interval`'s ``absent``: the expected RMS with their noise
    counted once, (|F₀|² − tr_a)⁺ + tr_t over the points (a: absent, t: told; F₀
    holds the absent ones' noise, the told ones' error is the controller's), and
    the lower quantiles of RMS and max where they are exactly nominal."""
    n = len(p)
    nominal = np.where(absent, theta_c, estimate)
    told = [c for c in range(len(PARAM_NAMES)) if not absent[c] and cov[c, c] > 0]
    cols = [c for c in np.flatnonzero(absent) if cov[c, c] > 0]
    tr_a = tr_t = 0.0
    if cols:
        G_a = truth_jacobian(p, geometry, estimate, theta_c, frame, cols)
        tr_a = t_var * float(np.sum((G_a @ _root(cov[np.ix_(cols, cols)]))**2))
    F_nom = compensated_field(p, geometry, nominal, theta_c, frame).field.ravel()
    if not told:
        norms = np.linalg.norm(F_nom.reshape(n, 3), axis=1)
        rms = float(np.sqrt(max(float(F0 @ F0) - tr_a, 0.0) / n))
        return rms, float(np.sqrt(np.mean(norms**2))), float(norms.max())
    G_t = truth_jacobian(p, geometry, nominal, theta_c, frame, told)
    B = G_t @ _root(cov[np.ix_(told, told)])
    tr_t = t_var * float(np.sum(B**2))
    rms = float(np.sqrt((max(float(F0 @ F0) - tr_a, 0.0) + tr_t) / n))
    low_rms, low_max = _field_draws(F_nom, B, _draws(B.shape[1], dof, draws, seed + 1), n)
    return rms, float(np.quantile(low_rms, lo)), float(np.quantile(low_max, lo))


def _field_draws(F0: np.ndarray, B: np.ndarray, z: np.ndarray,
                 n: int) -> tuple[np.ndarray, np.ndarray]:
    """RMS and max of |E| of F0 + B·z for each row of z."""
    rms = np.empty(len(z))
    mx = np.empty(len(z))
    for lo in range(0, len(z), 500):  # the whole field per draw: in chunks
        d = (F0 + z[lo:lo + 500] @ B.T).reshape(-1, n, 3)
        norms2 = np.einsum("dnk,dnk->dn", d, d)
        rms[lo:lo + 500] = np.sqrt(norms2.mean(axis=1))
        mx[lo:lo + 500] = np.sqrt(norms2.max(axis=1))
    return rms, mx
