"""Accuracy at the tool (docs/model.md, "Accuracy at the tool"; docs/design.md, "Accuracy at
the tool").

The controller believes the machine nominal: for a commanded tool point p it
commands ρ = IK_nominal(p). The real machine's joint input is ρ + o (o: the change
of the offset registers relative to delivery) and its kinematic parameters are
θ = (Δρ, ΔL, tilts) of PARAM_NAMES, so the carriages sit at ρ_i + o_i + Δρ_i along
the real (tilted) axes, the legs are L + ΔL_i long, and the tool lands at

    P(p) = FK_real(ρ + o) = forward(IK_nominal(p) + o, geometry, Δρ, ΔL, tilt)

E(p) = P(p) − p is the tool-point error field, sampled on a grid over the
workspace box and stated after fitting away what the user sets up anyway:

- frame ``"translation"``: the mean of E (the tool offset is set by touching off;
  the mean is the least-squares translation);
- frame ``"rigid"``: the least-squares rigid motion P ≈ R·p + t (Kabsch, exact
  rotation; parts aligned by probing). The field left is P − (R·p + t).

Statistics of a field: RMS over the points of |E| and max |E| (mm).

Units: mm for lengths and offsets, mrad for tilts, mm/m (= mrad) for squareness.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from orthocal.geometry import (
    PARAM_NAMES,
    Geometry,
    full_params,
    params_vector,
    split_params,
)
from orthocal.joint_error import Direction, JointErrors
from orthocal.kinematics import axis_directions, axis_origins, carriages, forward, inverse

FRAMES: tuple[str, str] = ("translation", "rigid")
SQUARENESS_NAMES: tuple[str, str, str] = ("xy", "xz", "yz")
# Central-difference step (mm for Δρ, ΔL; mrad for tilts) of the sensitivities:
# truncation O(h²·curvature) ≈ 1e-10 of the value, rounding ≈ 1e-12 mm / h ≈ 1e-8.
DIFF_STEP = 1e-4


# --- parameters and covariance -------------------------------------------------------


def parameter_vector(params) -> np.ndarray:
    """12-vector of PARAM_NAMES from a 12-, 9- or 6-vector, a dict by name, or None
    (zero)."""
    if isinstance(params, Mapping):
        return params_vector(dict(params))
    return full_params(params).astype(float)


def offset_vector(offsets) -> np.ndarray:
    if offsets is None:
        return np.zeros(3)
    if isinstance(offsets, Mapping):
        offsets = [offsets.get(a, offsets.get(f"drho_{a}", 0.0)) for a in "xyz"]
    o = np.asarray(offsets, dtype=float)
    if o.shape != (3,):
        raise ValueError(f"expected 3 offsets (x, y, z) in mm, got shape {o.shape}")
    return o


def covariance_matrix(covariance, names: Sequence[str] | None = None) -> np.ndarray:
    """The 12×12 covariance over PARAM_NAMES (zero rows/columns for parameters not
    estimated) from any of:

    - a 12×12 array (returned as is), or a 9×9 one over the first nine names
      (axes that meet: the gaps' rows and columns zero);
    - a k×k array together with ``names``, the k parameter names of its rows
      (an ``Identification``'s ``covariance`` and ``names``);
    - a nested dict ``{name: {name: covariance}}``;
    - a flat dict ``{name: standard error}`` (the run JSON's ``std_errors``),
      taken as uncorrelated: this drops the fit's correlations, say so where it
      is used.
    """
    n = len(PARAM_NAMES)
    index = {nm: i for i, nm in enumerate(PARAM_NAMES)}
    out = np.zeros((n, n))
    if isinstance(covariance, Mapping):
        unknown = set(covariance) - set(PARAM_NAMES)
        if unknown:
            raise ValueError(f"unknown parameter name(s): {sorted(unknown)}")
        for a, row in covariance.items():
            if isinstance(row, Mapping):
                for b, v in row.items():
                    if b not in index:
                        raise ValueError(f"unknown parameter name: {b!r}")
                    out[index[a], index[b]] = float(v)
            else:
                out[index[a], index[a]] = float(row) ** 2
        if not np.allclose(out, out.T, rtol=1e-9, atol=0):
            raise ValueError("covariance is not symmetric")
        return out
    c = np.asarray(covariance, dtype=float)
    if names is None:
        if c.shape == (9, 9):
            names = PARAM_NAMES[:9]
        elif c.shape != (n, n):
            raise ValueError(f"expected a {n}×{n} covariance (or names), got shape {c.shape}")
        else:
            return c.copy()
    cols = [index[nm] for nm in names]
    if c.shape != (len(cols), len(cols)):
        raise ValueError(f"covariance of shape {c.shape} does not match {len(cols)} names")
    out[np.ix_(cols, cols)] = c
    return out


# --- the grid ------------------------------------------------------------------------


class Grid(NamedTuple):
    """Points of a workspace grid (n, 3) mm and how many grid nodes were left out."""

    points: np.ndarray
    excluded: int


def default_box(geometry: Geometry) -> np.ndarray:
    """[rho_min, rho_max]³: the cube the test postures span (docs/design.md, workspace)."""
    return np.array([[geometry.rho_min, geometry.rho_max]] * 3, dtype=float)


def workspace_grid(box=None, n: int = 7, geometry: Geometry | None = None,
                   soft_limits=None) -> Grid:
    """The n³ grid over ``box`` [[xmin, xmax], [ymin, ymax], [zmin, zmax]] (mm),
    n nodes per axis including both ends (``linspace``); default box
    [rho_min, rho_max]³ of ``geometry``. Nodes whose nominal IK fails (beyond a
    leg's reach) or whose joints ρ = IK_nominal(p) fall outside ``soft_limits``
    = (lower, upper), two 3-vectors of joint coordinates (mm, the controller's ρ
    as the soft-limit registers count it), are excluded; ``Grid.excluded`` says
    how many. Order: x slowest, z fastest."""
    geometry = geometry or Geometry()
    if n < 2:
        raise ValueError(f"n must be at least 2, got {n}")
    box = default_box(geometry) if box is None else np.asarray(box, dtype=float)
    if box.shape != (3, 2) or not np.all(np.isfinite(box)) or np.any(box[:, 1] < box[:, 0]):
        raise ValueError(f"box must be [[xmin, xmax], [ymin, ymax], [zmin, zmax]], got {box}")
    axes = [np.linspace(lo, hi, n) for lo, hi in box]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    # nominal IK per node: ρ_i = p_i + sqrt(L² − p_j² − p_k²) where the radicand is ≥ 0
    sq = nodes**2
    radicand = geometry.leg_length**2 - (sq.sum(axis=1, keepdims=True) - sq)
    keep = np.all(radicand >= 0, axis=1)
    rho = np.full_like(nodes, np.nan)
    rho[keep] = inverse(nodes[keep], geometry)
    if soft_limits is not None:
        lower, upper = (np.asarray(v, dtype=float) for v in soft_limits)
        if lower.shape != (3,) or upper.shape != (3,):
            raise ValueError("soft_limits must be (lower, upper), two 3-vectors of joints")
        with np.errstate(invalid="ignore"):
            keep &= np.all((rho >= lower) & (rho <= upper), axis=1)
    return Grid(nodes[keep], int(np.count_nonzero(~keep)))


# --- the field -----------------------------------------------------------------------


def tool_error(points, geometry: Geometry, params, offsets,
               joint_errors: JointErrors | None = None,
               direction: Direction = "mean") -> np.ndarray:
    """E = P − p (n, 3) mm at commanded tool points ``points`` (n, 3) mm, for the
    machine of parameters ``params`` (12-, 9- or 6-vector of PARAM_NAMES, or a dict
    by name) with the offset registers changed by ``offsets`` o (3, mm; None: 0)
    since delivery: P = forward(IK_nominal(p) + o, geometry, Δρ, ΔL, tilt, gap)
    (docs/model.md, "Accuracy at the tool"; the axes may pass each other: "Axes that do
    not meet").

    ``joint_errors``: each joint's positioning error ε (docs/model.md, "Joint
    positioning errors", (J1)), taken at the joint input x = IK_nominal(p) + o and
    ``direction`` (default the bidirectional mean, to which Δρ refers; or each point
    reached from a stated side): P = forward(x + ε(x, direction), …). None: exact
    joints, bit for bit the field without the argument."""
    p = np.asarray(points, dtype=float)
    drho, dL, tilt, gap = split_params(parameter_vector(params))
    rho = inverse(p, geometry) + offset_vector(offsets)
    if joint_errors is not None:
        rho = joint_errors.joints(rho, direction)
    return forward(rho, geometry, drho, dL, tilt, gap) - p


def rigid_fit(points, landed) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) of the least-squares rigid motion landed ≈ R·points + t (Kabsch:
    SVD of the centred cross-covariance, det R = +1)."""
    a = np.asarray(points, dtype=float)
    b = np.asarray(landed, dtype=float)
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    R = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return R, cb - R @ ca


def fit_frame(points, errors, frame: str = "translation") -> np.ndarray:
    """The error field left after fitting away the frame (docs/model.md, "Accuracy at
    the tool"): ``"translation"`` subtracts the mean of E (least-squares
    translation); ``"rigid"`` returns P − (R·p + t) for the least-squares rigid
    motion (Kabsch) of the commanded points p onto the landed points P = p + E."""
    e = np.asarray(errors, dtype=float)
    if frame == "translation":
        return e - e.mean(axis=0)
    if frame == "rigid":
        p = np.asarray(points, dtype=float)
        R, t = rigid_fit(p, p + e)
        return (p + e) - (p @ R.T + t)
    raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")


def field_stats(fitted) -> tuple[float, float]:
    """(RMS over the points of |E|, max |E|) of a field (n, 3), mm."""
    norms = np.linalg.norm(np.asarray(fitted, dtype=float), axis=-1)
    return float(np.sqrt(np.mean(norms**2))), float(np.max(norms))


@dataclass(frozen=True, eq=False)
class ErrorField:
    """A tool-point error field after its frame: ``field`` (n, 3) mm at the
    commanded ``points`` (n, 3) mm, its RMS and max of |E| (mm), the ``frame``
    and the ``offsets`` o (mm) it was computed with."""

    frame: str
    rms_mm: float
    max_mm: float
    field: np.ndarray
    points: np.ndarray
    offsets: np.ndarray

    def stats(self) -> dict[str, float]:
        """{"rms_mm": .., "max_mm": ..} (docs/design.md's "before"/"after")."""
        return {"rms_mm": self.rms_mm, "max_mm": self.max_mm}


def fitted_field(points, geometry, theta, offsets, frame,
                 joint_errors: JointErrors | None = None,
                 direction: Direction = "mean") -> np.ndarray:
    return fit_frame(points, tool_error(points, geometry, theta, offsets, joint_errors,
                                        direction), frame)


def error_field(points, geometry: Geometry, params, offsets,
                frame: str = "translation", joint_errors: JointErrors | None = None,
                direction: Direction = "mean") -> ErrorField:
    """:func:`tool_error` over ``points`` after ``frame`` (:func:`fit_frame`), with
    its :func:`field_stats`; ``joint_errors`` and ``direction`` as for
    :func:`tool_error` (None: exact joints)."""
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    p = np.asarray(points, dtype=float)
    o = offset_vector(offsets)
    fitted = fitted_field(p, geometry, parameter_vector(params), o, frame, joint_errors,
                          direction)
    rms, mx = field_stats(fitted)
    return ErrorField(frame, rms, mx, fitted, p, o)


# --- optimal offsets -----------------------------------------------------------------


class OptimalOffsets(NamedTuple):
    """The offsets o (3, mm) that minimise the RMS tool error, and its field."""

    offsets: np.ndarray
    field: ErrorField


def optimal_offsets(points, geometry: Geometry, params, frame: str = "translation",
                    max_abs_offset_mm: float | None = None, start=None,
                    joint_errors: JointErrors | None = None,
                    direction: Direction = "mean") -> OptimalOffsets:
    """The offset-register changes o minimising the RMS of the tool error after
    ``frame`` (the frame is fitted inside the objective: the residual vector is
    fit_frame(E(o)), whose sum of squares is n·RMS²), by nonlinear least squares
    over ``points`` (scipy ``least_squares``), each |o_i| ≤ ``max_abs_offset_mm``
    when given. Start: ``start``, default −Δρ (the paper's correction), clipped to
    the bounds. docs/model.md: the offsets can cancel part of the field the tilts leave,
    so this beats −Δρ whenever the tilts are not zero. ``joint_errors``,
    ``direction``: as for :func:`tool_error` (None: exact joints)."""
    from scipy.optimize import least_squares  # ~0.3 s to import; only here

    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    p = np.asarray(points, dtype=float)
    theta = parameter_vector(params)
    x0 = -theta[:3] if start is None else offset_vector(start)

    def residual(o: np.ndarray) -> np.ndarray:
        return fitted_field(p, geometry, theta, o, frame, joint_errors, direction).ravel()

    opts = dict(xtol=1e-12, ftol=1e-12, gtol=1e-12, diff_step=1e-7)
    if max_abs_offset_mm is None:
        sol = least_squares(residual, x0, method="lm", **opts)
    else:
        m = float(max_abs_offset_mm)
        if not m > 0:
            raise ValueError(f"max_abs_offset_mm must be > 0, got {max_abs_offset_mm}")
        sol = least_squares(residual, np.clip(x0, -m, m), bounds=(-m, m), method="trf", **opts)
    o = np.asarray(sol.x, dtype=float)
    return OptimalOffsets(o, error_field(p, geometry, theta, o, frame, joint_errors, direction))


# --- squareness ----------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Squareness:
    """Squareness errors XY, XZ, YZ (mm/m, ISO 230-1) of the tool's motions along
    commanded x, y, z: the angle between the two motions minus 90°. ``sensitivity``
    (3×9): ∂(xy, xz, yz)/∂θ over PARAM_NAMES (mm/m per mm or per mrad), at the
    offsets held fixed; ``std_errors`` from a covariance when given."""

    values: np.ndarray
    sensitivity: np.ndarray
    std_errors: np.ndarray | None
    method: str

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in zip(SQUARENESS_NAMES, self.values, strict=True)}

    def std_errors_dict(self) -> dict[str, float] | None:
        if self.std_errors is None:
            return None
        return {k: float(v) for k, v in zip(SQUARENESS_NAMES, self.std_errors, strict=True)}

    def propagate(self, covariance, names: Sequence[str] | None = None) -> np.ndarray:
        """Standard errors (mm/m) of the three squareness errors for a parameter
        covariance (any form :func:`covariance_matrix` takes): sqrt diag(S Σ Sᵀ)."""
        c = covariance_matrix(covariance, names)
        return np.sqrt(np.maximum(np.diag(self.sensitivity @ c @ self.sensitivity.T), 0.0))


def _motion_jacobian_at_zero(geometry: Geometry, theta: np.ndarray, o: np.ndarray) -> np.ndarray:
    """dP/dp at the commanded Π0 (p = 0): dIK_nominal/dp = I there (every leg along
    its axis), and implicit differentiation of |P − c_i − q_i·u_i|² = L_i² gives
    D·dP = diag(d_i·u_i)·dq with rows d_i = P − c_i − q_i·u_i."""
    drho, dL, tilt, gap = split_params(theta)
    rho0 = np.full(3, geometry.leg_length) + o
    P = forward(rho0, geometry, drho, dL, tilt, gap)
    u = axis_directions(tilt)
    if u is None:  # no tilt: the axes are e_x, e_y, e_z (axis_directions' None)
        u = np.eye(3)
    d = P[None, :] - carriages(rho0 + drho, u, axis_origins(gap))
    return np.linalg.solve(d, np.diag(np.einsum("ij,ij->i", d, u)))


def _motion_affine(points, geometry: Geometry, theta: np.ndarray, o: np.ndarray) -> np.ndarray:
    """A of the least-squares affine fit P ≈ A·p + b over ``points``."""
    p = np.asarray(points, dtype=float)
    P = p + tool_error(p, geometry, theta, o)
    X = np.hstack([p, np.ones((len(p), 1))])
    coef, *_ = np.linalg.lstsq(X, P, rcond=None)
    return coef[:3].T


def _squareness_values(A: np.ndarray) -> np.ndarray:
    """(angle between columns j, k of A) − 90°, mrad, for (x,y), (x,z), (y,z)."""
    out = np.empty(3)
    for n, (j, k) in enumerate(((0, 1), (0, 2), (1, 2))):
        a, b = A[:, j], A[:, k]
        angle = np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)
        out[n] = (angle - np.pi / 2) * 1e3
    return out


def squareness(params, geometry: Geometry | None = None, offsets=None, points=None,
               covariance=None, names: Sequence[str] | None = None) -> Squareness:
    """Squareness errors XY, XZ, YZ (mm/m) of the tool's motions along commanded
    x, y, z (ISO 230-1: the angle between the motions minus 90°), from the exact
    model (docs/model.md, "Accuracy at the tool"):

    - ``points`` None (default): the Jacobian dP/dp at the commanded Π0 (p = 0),
      analytic (implicit differentiation of the sphere equations); its columns are
      the tool's motions. To first order it is U⁻¹ (rows of U the axis
      directions), so xy ≈ tilt_yx, xz ≈ tilt_zx, yz ≈ tilt_zy (1 mrad = 1 mm/m):
      the sign is such that a positive tilt opens the angle beyond 90°.
    - ``points`` given (e.g. the workspace grid): the linear part A of the
      least-squares affine fit P ≈ A·p + b over them (the workspace analogue of
      ISO 230-1's reference straight lines over the travel).

    ``offsets`` o (mm): default None means o = −Δρ (the joint zeros corrected,
    the carriages at their nominal Π0): docs/model.md's statement, which depends on the
    tilts and ΔL only. Uncorrected joint zeros shear the tool's motions by about
    Δρ_j/L each (0.5 mm → 1.6 mm/m), so pass the offsets actually written to state
    a "before".

    ``sensitivity`` is ∂(xy, xz, yz)/∂θ (central differences, h = 1e-4 mm or
    mrad) with o held at its value; with ``covariance`` (any form
    :func:`covariance_matrix` takes, ``names`` for a k×k matrix) the standard
    errors sqrt diag(S Σ Sᵀ) follow."""
    geometry = geometry or Geometry()
    theta = parameter_vector(params)
    o = -theta[:3] if offsets is None else offset_vector(offsets)

    if points is None:
        def value(t: np.ndarray) -> np.ndarray:
            return _squareness_values(_motion_jacobian_at_zero(geometry, t, o))
        method = "jacobian at commanded Π0"
    else:
        p = np.asarray(points, dtype=float)

        def value(t: np.ndarray) -> np.ndarray:
            return _squareness_values(_motion_affine(p, geometry, t, o))
        method = f"affine fit over {len(p)} points"

    values = value(theta)
    S = np.empty((3, len(PARAM_NAMES)))
    for c in range(len(PARAM_NAMES)):
        step = np.zeros(len(PARAM_NAMES))
        step[c] = DIFF_STEP
        S[:, c] = (value(theta + step) - value(theta - step)) / (2 * DIFF_STEP)
    result = Squareness(values, S, None, method)
    if covariance is not None:
        result = Squareness(values, S, result.propagate(covariance, names), method)
    return result
