"""The misfit that stated form and gauge errors can make, and no more (docs/model.md,
"Leg form against tilts and gaps").

A model test that compares a lack of fit with the noise alone takes every bowed
leg for a tilt. One that adds the stated errors to the noise as a variance lets
any misfit of that size pass whatever its shape, and, an assumed bound being
treated as a scatter measured on infinitely many degrees of freedom, it loses
its power for good. Here the stated errors are what they are: bounded
systematic errors, each with the shape it makes across the deviations.

- The legs' form: a bow of sagitta h in the plane of gauge (i, j) changes
  deviation (s, i, j) by h·g_s, g_s = w(t_s) − w(t_0), w(t) = 4t(1 − t) at the
  exact contact fractions (orthocal.budget.form_vector): one unknown per gauge
  plane, |h| ≤ the stated straightness (read as the sagitta over the leg).
- A gauge's own error: a smooth function of its plunger's position, over the
  tenths of a millimetre a deviation spans a slope: one unknown per gauge, its
  deviations off by c·ȳ_k, |c| ≤ MPE/max(span, max |ȳ_k|) + (1 − cos θ) (the
  MPE over ``mpe_span`` of travel, in proportion below, as the uncertainty
  budget reads it; θ the plunger's angle to the leg's normal, a cosine scale).
- A temperature change during the run: the legs' lengths, one unknown per leg,
  |δL_i| ≤ α·ΔT·L.
- A joint's lead (an assumed joint's bound, or what its table's uncertainty leaves of
  its lead): one unknown per joint, |k_i| ≤ b_i µm/m, the deviations off by what a
  lead does to them, (J4) (orthocal.lead_deviation_change).

The lack of fit of a model is the smallest generalised residual any such errors
leave (the model's own parameters free, linearised at the fit):

    RSS_B = min over δθ, |b| ≤ bound of (r̄ − J·δθ − B·b)ᵀ V⁻¹ (r̄ − J·δθ − B·b)

(r̄ the deviation means' residual, V their covariance in units of σ² of one
per-cycle deviation, with the stands' prior where they are modelled). Where the
machine's errors lie within the bounds, RSS_B is at most the residual the noise
alone leaves, so F = RSS_B / (K − p) / σ̂² against F(K − p, ν) keeps its level
(conservatively); a misfit of another shape, or larger than the stated errors
can make, is not excused, and the test's degrees of freedom stay the noise's.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

# The budget's own inputs: the model test and the statement read the stated errors alike.
from orthocal.budget import MPE_SPAN_MM, STEEL_ALPHA, form_vector
from orthocal.geometry import AXES, Geometry
from orthocal.identification import exact_jacobian
from orthocal.joint_error import lead_deviation_change
from orthocal.measurement import Key


@dataclass(frozen=True)
class Allowance:
    """The stated errors a lack of fit may be excused by (module docstring).

    ``straightness``: the sagitta bound (mm) of each gauge plane (leg, direction);
    planes not named are taken straight. ``mpe``: each gauge plane's maximum
    permissible error (mm) over ``mpe_span`` mm of travel. ``plunger_angle_deg``:
    the plungers' angle to the legs' normals. ``temperature_change``: K during
    the run (the legs of steel). ``joint_lead_um_per_m``: each joint's lead bound
    (µm/m, by axis; joints not named: exact)."""

    straightness: Mapping[tuple[str, str], float] = field(default_factory=dict)
    mpe: Mapping[tuple[str, str], float] = field(default_factory=dict)
    mpe_span: float = MPE_SPAN_MM
    plunger_angle_deg: float = 0.0
    temperature_change: float = 0.0
    joint_lead_um_per_m: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for axis, v in self.joint_lead_um_per_m.items():
            if axis not in AXES or not (np.isfinite(v) and v >= 0):
                raise ValueError(f"joint_lead_um_per_m of joint {axis!r} must be >= 0, "
                                 f"got {v!r}")
        for what, table in (("straightness", self.straightness), ("mpe", self.mpe)):
            for plane, v in table.items():
                if not (np.isfinite(v) and v >= 0):
                    raise ValueError(f"{what} of gauge plane {plane!r} must be >= 0, got {v!r}")
        for what, v in (("mpe_span", self.mpe_span),):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{what} must be > 0, got {v!r}")
        for what, v in (("plunger_angle_deg", self.plunger_angle_deg),
                        ("temperature_change", self.temperature_change)):
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{what} must be >= 0, got {v!r}")

    def to_dict(self) -> dict[str, Any]:
        return {"straightness_mm": {"".join(p): v for p, v in self.straightness.items()},
                "mpe_mm": {"".join(p): v for p, v in self.mpe.items()},
                "mpe_span_mm": self.mpe_span, "plunger_angle_deg": self.plunger_angle_deg,
                "temperature_change_c": self.temperature_change,
                "joint_lead_um_per_m": dict(self.joint_lead_um_per_m)}


@dataclass(frozen=True)
class Columns:
    """The allowance's columns over the distinct deviations: B (K × m), each
    column's bound, and what each column is (``names``)."""

    B: np.ndarray
    bound: np.ndarray
    names: tuple[str, ...]


def columns(allowance: Allowance, distinct: Sequence[Key], means: np.ndarray,
            geometry: Geometry, params: np.ndarray, mount_offsets=None) -> Columns:
    """The bounded error columns of ``allowance`` for the deviations ``distinct``
    whose measured means are ``means`` (mm), the bows' signatures at the fit's
    ``params`` (12-vector) in the planes L/2 + ``mount_offsets`` (one per key;
    None: L/2). Columns of zero bound are left out."""
    K = len(distinct)
    cols: list[np.ndarray] = []
    bounds: list[float] = []
    names: list[str] = []
    g = form_vector(distinct, geometry, params, mount_offsets)
    for plane, h in allowance.straightness.items():
        rows = np.array([(k[1], k[2]) == tuple(plane) for k in distinct])
        if h > 0 and rows.any():
            cols.append(np.where(rows, g, 0.0))
            bounds.append(float(h))
            names.append(f"bow {''.join(plane)}")
    cosine = 1.0 - np.cos(np.radians(allowance.plunger_angle_deg))
    for plane in dict.fromkeys((k[1], k[2]) for k in distinct):
        rows = np.array([(k[1], k[2]) == plane for k in distinct])
        span = max(allowance.mpe_span, float(np.max(np.abs(means[rows]))))
        slope = float(allowance.mpe.get(plane, 0.0)) / span + cosine
        if slope > 0 and np.any(means[rows] != 0):
            cols.append(np.where(rows, means, 0.0))
            bounds.append(slope)
            names.append(f"gauge scale {''.join(plane)}")
    if allowance.temperature_change > 0:
        dL = STEEL_ALPHA * allowance.temperature_change * geometry.leg_length
        J_L = exact_jacobian(distinct, geometry, params, "L", mount_offsets)
        for leg in range(3):
            cols.append(J_L[:, leg])
            bounds.append(dL)
            names.append(f"temperature dL_{'xyz'[leg]}")
    for i, axis in enumerate(AXES):
        b = float(allowance.joint_lead_um_per_m.get(axis, 0.0))
        if b > 0:
            unit = np.zeros(3)
            unit[i] = 1.0
            cols.append(lead_deviation_change(distinct, geometry, unit))
            bounds.append(b)
            names.append(f"lead {axis}")
    B = np.column_stack(cols) if cols else np.zeros((K, 0))
    return Columns(B, np.asarray(bounds, dtype=float), tuple(names))


@dataclass(frozen=True)
class BoundedFit:
    """The smallest weighted residual the bounded errors leave (:func:`bounded_rss`):
    ``rss`` (mm², weighted by V⁻¹ as the lack of fit is), the errors that reach it
    (``used``, mm, by column name) and how many sit at their bound."""

    rss: float
    free_rss: float
    used: dict[str, float]
    at_bound: int

    def to_dict(self) -> dict[str, Any]:
        # largest first; ties (to a picometre: another CPU's last bits) by name, so that
        # the six named are the same on every machine
        big = sorted(self.used.items(), key=lambda kv: (-round(abs(kv[1]), 9), kv[0]))[:6]
        return {"rss_without_allowance_mm2": self.free_rss, "rss_with_allowance_mm2": self.rss,
                "largest_used_mm": {n: v for n, v in big if v != 0.0},
                "at_bound": self.at_bound}


def bounded_rss(r: np.ndarray, V: np.ndarray, J: np.ndarray, cols: Columns) -> BoundedFit:
    """min over δθ (free) and b (|b| ≤ ``cols.bound``) of (r − J·δθ − B·b)ᵀ V⁻¹ (…):
    bounded-variable least squares (scipy's BVLS, exact) on the problem whitened
    by the Cholesky factor of V⁻¹."""
    from scipy.optimize import lsq_linear

    W = np.linalg.inv(V)
    Lw = np.linalg.cholesky((W + W.T) / 2.0).T  # W = Lwᵀ·Lw
    rw, Jw = Lw @ r, Lw @ J
    g = Jw.T @ rw
    free = float(rw @ rw - g @ np.linalg.lstsq(Jw.T @ Jw, g, rcond=None)[0])
    m = cols.B.shape[1]
    if m == 0:
        return BoundedFit(max(free, 0.0), max(free, 0.0), {}, 0)
    A = np.hstack([Jw, Lw @ cols.B])
    p = J.shape[1]
    lb = np.r_[np.full(p, -np.inf), -cols.bound]
    ub = np.r_[np.full(p, np.inf), cols.bound]
    # scale the columns to unit norm: BVLS's tolerances are absolute
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    sol = lsq_linear(A / scale, rw, bounds=(lb * scale, ub * scale), method="bvls",
                     tol=1e-14, lsmr_tol=None)
    resid = rw - (A / scale) @ sol.x
    b = sol.x[p:] / scale[p:]
    rss = float(min(resid @ resid, free))
    at = int(np.sum(np.isclose(np.abs(b), cols.bound, rtol=1e-6, atol=0)))
    return BoundedFit(max(rss, 0.0), max(free, 0.0),
                      {n: float(v) for n, v in zip(cols.names, b, strict=True)}, at)
