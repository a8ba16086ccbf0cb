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

from collections.abc import Sequence
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
from orthocal.field_mc import (
    Bounded,
    active_columns,
    field_inputs,
    figures,
    parameter_inputs,
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
                   columns, joint_errors: JointErrors | None = None,
                   direction: Direction = "mean") -> np.ndarray:
    """∂ fit_frame(E_c)/∂θ over the real machine's parameters ``columns`` (3n ×
    len(columns), mm per mm or mrad), the controller's joints held: central
    differences (h = DIFF_STEP) of the exact forward kinematics; ``joint_errors``
    and ``direction`` as for :func:`landed`."""
    p = np.asarray(points, dtype=float)
    rho = controller_joints(p, geometry, theta_c)
    theta = parameter_vector(truth)
    G = np.empty((p.size, len(columns)))
    for k, c in enumerate(columns):
        step = np.zeros(len(PARAM_NAMES))
        step[c] = DIFF_STEP
        plus, minus = (fit_frame(p, landed(rho, geometry, t, joint_errors, direction) - p,
                                 frame) for t in (theta + step, theta - step))
        G[:, k] = (plus - minus).ravel() / (2 * DIFF_STEP)
    return G


@dataclass(frozen=True, eq=False)
class CompensatedInterval:
    """The tool error with the machine ``theta_c`` in the controller, predicted
    (see :func:`compensated_interval`): RMS and max of |E| (mm) and their
    ``level`` intervals; ``field`` the plug-in (K3) at the estimate;
    ``point_rms_mm`` the root mean square of |E| at each point over the draws."""

    field: ErrorField
    rms_mm: float
    max_mm: float
    point_rms_mm: np.ndarray
    rms_interval_mm: tuple[float, float]
    max_interval_mm: tuple[float, float]
    level: float
    dof: float | None
    method: str


def joint_jacobian(points, geometry: Geometry, truth, theta_c,
                   joint_errors: JointErrors | None = None,
                   direction: Direction = "mean") -> np.ndarray:
    """∂E_c,k/∂q_k (n, 3, 3): the tool's raw error at each point per error of the real
    machine's counted joints at the controller's joints IK_c(p), central differences
    of the exact forward kinematics at ``truth`` (``joint_errors`` and ``direction``
    as for :func:`landed`)."""
    p = np.asarray(points, dtype=float)
    rho = controller_joints(p, geometry, theta_c)
    theta = parameter_vector(truth)
    J = np.empty((len(p), 3, 3))
    for i in range(3):
        step = np.zeros(len(PARAM_NAMES))
        step[i] = DIFF_STEP
        J[:, :, i] = (landed(rho, geometry, theta + step, joint_errors, direction)
                      - landed(rho, geometry, theta - step, joint_errors, direction)
                      ) / (2 * DIFF_STEP)
    return J


def compensated_interval(theta_c, estimate, covariance, dof: float | None, points,
                         geometry: Geometry | None = None, frame: str = "translation",
                         systematic=None, level: float = 0.95, draws: int = 4000,
                         seed: int = 0, absent=None, *,
                         bounded: Bounded | Sequence[Bounded] = (), field_draws=None,
                         joint_draws=None, joint_errors: JointErrors | None = None,
                         direction: Direction = "mean") -> CompensatedInterval:
    """The tool error (K3) a controller with the machine ``theta_c`` leaves on the
    real machine, which the run knows as ``estimate`` (12-vector: θ_c where the
    controller was told a parameter, the run's best value where it was not), with
    95 % intervals by Monte Carlo over the joint distribution of the estimate's
    error (docs/model.md, "Intervals at the tool"; orthocal.field_mc):
    ``covariance`` (any form :func:`covariance_matrix` takes; Student t on ``dof``,
    None: normal), ``systematic`` a systematic part known by its covariance alone
    (normal), ``bounded`` rectangular ones over the parameters (e.g. the legs' form,
    orthocal.budget.form_columns), ``field_draws`` and ``joint_draws`` the real
    machine's further errors as :func:`orthocal.tool_interval.after_interval` takes
    them (the joints' through :func:`joint_jacobian`); ``joint_errors`` and
    ``direction`` the real machine's joint tables as known (:func:`landed`).

    Linearised in the real machine's error δ: F(θ) = F₀ − G·δ, F₀ the fitted field
    at the estimate (zero where the controller was told everything), G
    (:func:`truth_jacobian`) over the parameters an input moves. The error of a
    parameter the controller was told is the truth's, not the plug-in's (F₀ is zero
    whatever it is): drawn, it gives the distribution of the field left, plain S1.
    ``absent`` (12 booleans, default none): the parameters the controller is not told
    because the model test did not keep them, whose estimate is noise about a value
    that may well be nominal: their error is in F₀, and the interval inverts F₀'s
    noncentral distribution so that it reaches a field where they are nominal.

    ``field`` is F₀; a parameter no input moves is taken as exactly known."""
    geometry = geometry or Geometry()
    theta_c = parameter_vector(theta_c)
    estimate = parameter_vector(estimate)
    cov = covariance_matrix(covariance)
    sys_cov = None if systematic is None else covariance_matrix(systematic)
    kept = [bounded] if isinstance(bounded, Bounded) else list(bounded)
    for c in (cov, sys_cov):
        if c is not None and not np.all(np.isfinite(c)):
            raise ValueError("covariance has non-finite entries")
    p = np.asarray(points, dtype=float)
    base = compensated_field(p, geometry, estimate, theta_c, frame, joint_errors, direction)
    columns = active_columns(cov, sys_cov, kept)
    G = truth_jacobian(p, geometry, estimate, theta_c, frame, columns, joint_errors,
                       direction)
    fields = field_inputs(p, frame, field_draws, joint_draws, lambda: joint_jacobian(
        p, geometry, estimate, theta_c, joint_errors, direction))
    observed = np.zeros(len(PARAM_NAMES), dtype=bool) if absent is None else \
        np.asarray(absent, dtype=bool)
    inputs = parameter_inputs(G, columns, cov, dof, systematic=sys_cov, bounded=kept,
                              observed=observed, fields=fields)
    fig = figures(base.field, inputs, level, draws, seed)
    law = "normal" if dof is None or not np.isfinite(dof) else f"Student t, {dof:g} dof"
    return CompensatedInterval(
        field=base, rms_mm=fig.rms_mm, max_mm=fig.max_mm, point_rms_mm=fig.point_rms_mm,
        rms_interval_mm=fig.rms_interval_mm, max_interval_mm=fig.max_interval_mm,
        level=level, dof=None if dof is None or not np.isfinite(dof) else float(dof),
        method=("the real machine's error drawn from the inputs' joint distribution and "
                "propagated through the exact model, linearised (GUM Supplement 1; "
                f"{law}; bounded inputs rectangular; {draws} draws)"))
