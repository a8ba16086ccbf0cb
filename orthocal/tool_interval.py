"""How well the after-figures of accuracy at the tool are known (docs/model.md,
"Accuracy at the tool"): the RMS and max of the field left once offsets are
written, with a 95 % interval from the parameters' covariance, and the words
that say what such a figure takes as known (``assumes``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from orthocal.accuracy import (
    DIFF_STEP,
    FRAMES,
    ErrorField,
    covariance_matrix,
    error_field,
    fitted_field,
    offset_vector,
    parameter_vector,
)
from orthocal.geometry import MODELS, PARAM_NAMES, TILT_NAMES, Geometry

# --- uncertainty of the after-field --------------------------------------------------


@dataclass(frozen=True, eq=False)
class AfterInterval:
    """The predicted after-field (plug-in at the estimate) and 95 % intervals of
    its RMS and max of |E| (mm) (see :func:`after_interval`)."""

    field: ErrorField
    rms_interval_mm: tuple[float, float]
    max_interval_mm: tuple[float, float]
    level: float
    dof: float | None
    method: str

    @property
    def rms_mm(self) -> float:
        return self.field.rms_mm

    @property
    def max_mm(self) -> float:
        return self.field.max_mm

    def to_dict(self) -> dict[str, object]:
        """docs/design.md's ``"after"`` object."""
        return {"rms_mm": self.rms_mm, "max_mm": self.max_mm,
                "rms_interval_95_mm": list(self.rms_interval_mm),
                "max_interval_95_mm": list(self.max_interval_mm)}


def field_jacobian(points, geometry: Geometry, params, offsets, frame: str,
                   columns: Sequence[int]) -> np.ndarray:
    """∂ fit_frame(E)/∂θ_c (3n × len(columns), mm per mm or mrad), central
    differences (h = 1e-4) of the exact model at ``params``, offsets fixed."""
    p = np.asarray(points, dtype=float)
    theta = parameter_vector(params)
    o = offset_vector(offsets)
    G = np.empty((p.size, len(columns)))
    for k, c in enumerate(columns):
        step = np.zeros(len(PARAM_NAMES))
        step[c] = DIFF_STEP
        plus = fitted_field(p, geometry, theta + step, o, frame)
        minus = fitted_field(p, geometry, theta - step, o, frame)
        G[:, k] = (plus - minus).ravel() / (2 * DIFF_STEP)
    return G


def _coverage_factor(p: float, dof: float | None) -> float:
    """The p-quantile of the standard normal (dof None or infinite) or Student t."""
    from scipy import special  # imported here (scipy.stats would cost seconds)

    if dof is None or not np.isfinite(dof):
        return float(special.ndtri(p))
    if dof <= 0:
        raise ValueError(f"dof must be > 0, got {dof}")
    return float(special.stdtrit(dof, p))


def _bounds(G: np.ndarray, cov: np.ndarray, dof: float | None, level: float, draws: int,
            seed: int) -> dict[str, float]:
    """The constants of :func:`after_interval` for B = G·Σ^½ (3n × k):

    s_rms: the largest standard deviation of a unit linear functional of the field in
    the RMS inner product, sqrt(λ_max(BᵀB)/n); q_b: the (1 − α/4) quantile of
    ‖Bδ‖²_rms; s_pt: the largest standard deviation of the error of one point along
    any direction, max_k sqrt(λ_max(B_k B_kᵀ)); q_max: the (1 − α/2) quantile of
    ‖Bδ‖_max. δ ~ t_ν(0, I) (normal when ν is None), seeded Monte Carlo."""
    w, V = np.linalg.eigh(cov)
    B = G @ (V * np.sqrt(np.clip(w, 0.0, None)))  # Σ = root·rootᵀ (Σ may be singular)
    n = G.shape[0] // 3
    alpha = 1.0 - level
    M = B.T @ B / n
    s_rms = float(np.sqrt(max(np.linalg.eigvalsh(M)[-1], 0.0)))
    Bk = B.reshape(n, 3, -1)
    point_cov = Bk @ Bk.transpose(0, 2, 1)
    s_pt = float(np.sqrt(max(np.linalg.eigvalsh(point_cov)[:, -1].max(), 0.0)))
    rng = np.random.default_rng(seed)
    z = rng.standard_normal((draws, B.shape[1]))
    if dof is not None and np.isfinite(dof):
        if dof <= 0:
            raise ValueError(f"dof must be > 0, got {dof}")
        z /= np.sqrt(rng.chisquare(dof, size=(draws, 1)) / dof)
    b = np.einsum("ij,jk,ik->i", z, M, z)
    mx = np.empty(draws)
    for lo in range(0, draws, 500):  # the max norm needs the whole field; in chunks
        d = (z[lo:lo + 500] @ B.T).reshape(-1, n, 3)
        mx[lo:lo + 500] = np.sqrt(np.einsum("dnk,dnk->dn", d, d).max(axis=1))
    return {"s_rms": s_rms, "q_b": float(np.quantile(b, 1.0 - alpha / 4)), "s_pt": s_pt,
            "q_max": float(np.quantile(mx, 1.0 - alpha / 2))}


def after_interval(params, covariance, dof: float | None, offsets, points,
                   geometry: Geometry | None = None, frame: str = "translation",
                   names: Sequence[str] | None = None, level: float = 0.95,
                   draws: int = 4000, seed: int = 0) -> AfterInterval:
    """RMS and max of |E| of the after-field (the machine of the estimate θ̂ =
    ``params`` with ``offsets`` o written, over ``points``, after ``frame``) and
    their ``level`` (95 %) intervals for the TRUE machine θ, given the covariance
    Σ of θ̂ (9×9 with zeros where not estimated, a dict by name, or k×k with
    ``names``: :func:`covariance_matrix`) with ``dof`` degrees of freedom (Student
    t; None: Σ known, normal).

    Method: a confidence bound that holds for every θ, not plug-in Monte Carlo.
    Let F(θ) be the fitted field (3n-vector), linear over Σ: F(θ̂) = F(θ) + B·δ,
    B = G·Σ^½ with G = ∂F/∂θ over the estimated parameters (:func:`field_jacobian`)
    and δ ~ t_ν(0, I) (normal: ν None). Write r = ‖F(θ)‖ (the truth), T = ‖F(θ̂)‖
    (the plug-in), ⟨·,·⟩ and ‖·‖ the RMS inner product and norm over the points,
    u = F(θ)/r, a = ⟨u, B·δ⟩, whose standard deviation is at most s, the largest
    over unit directions (s² = λ_max(BᵀB)/n). Exactly, T² = r² + 2·r·a + ‖B·δ‖².

    - upper end: T ≥ ⟨u, F(θ̂)⟩ = r + a (Cauchy–Schwarz), so r ≤ T + z_{1−α/2}·s
      fails with probability ≤ α/2;
    - lower end: T² ≤ r² + 2·r·z_{1−α/4}·s + q_b fails with probability ≤ α/2
      (union of a > z·s and ‖B·δ‖² > q_b, q_b its 1 − α/4 quantile, Monte Carlo),
      so r ≥ sqrt(z²s² + T² − q_b) − z·s, and r ≥ 0 only when T² ≤ q_b.

    So the interval covers with probability ≥ level whatever θ is, to the accuracy
    of the linearisation (µm and hundredths of a mrad: negligible). z from Student
    t with ν dof (normal when ν is None). Near a field of zero T is larger than r
    (the bias of a norm: plug-in Monte Carlo around θ̂ then misses a small truth
    almost always); here the lower end is 0 whenever T is within the noise. For a
    large field it is T − z·s … T + z·s up to a term q_b/(2T): as wide as the delta
    method when the field lies along the most uncertain direction, wider by
    s / s_u otherwise.

    Max of |E|, the same way with the max norm: upper r ≤ T + z_{1−α/2}·s_pt (s_pt
    the largest standard deviation of one point's error along any direction;
    T ≥ the landed error at the true worst point along its direction), lower
    r ≥ T − q_max (reverse triangle inequality, q_max the 1 − α/2 quantile of
    max_k |(B·δ)_k|).

    It holds for the parameters Σ describes: anything not estimated (zero rows of
    Σ) is taken as exactly the value in ``params``; :func:`assumes` says so. When
    the model test kept 'rho', the tilts it could not see can be carried by giving
    the rho+tilt fit's tilt block of Σ with the tilts at 0 in ``params``."""
    geometry = geometry or Geometry()
    if not 0 < level < 1:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    theta = parameter_vector(params)
    cov = covariance_matrix(covariance, names)
    if not np.all(np.isfinite(cov)):
        raise ValueError("covariance has non-finite entries")
    columns = [c for c in range(len(PARAM_NAMES)) if cov[c, c] > 0]
    p = np.asarray(points, dtype=float)
    o = offset_vector(offsets)
    fld = error_field(p, geometry, theta, o, frame)
    alpha = 1.0 - level
    T, Tm = fld.rms_mm, fld.max_mm
    if columns:
        G = field_jacobian(p, geometry, theta, o, frame, columns)
        k = _bounds(G, cov[np.ix_(columns, columns)], dof, level, draws, seed)
        z_up = _coverage_factor(1.0 - alpha / 2, dof)
        z_lo = _coverage_factor(1.0 - alpha / 4, dof)
        zs = z_lo * k["s_rms"]
        rms_lo = 0.0 if T**2 <= k["q_b"] else float(np.sqrt(zs**2 + T**2 - k["q_b"]) - zs)
        rms_iv = (max(rms_lo, 0.0), T + z_up * k["s_rms"])
        max_iv = (max(Tm - k["q_max"], 0.0), Tm + z_up * k["s_pt"])
    else:
        rms_iv, max_iv = (T, T), (Tm, Tm)
    law = "normal" if dof is None or not np.isfinite(dof) else f"Student t, {dof:g} dof"
    return AfterInterval(
        field=fld,
        rms_interval_mm=rms_iv,
        max_interval_mm=max_iv,
        level=level,
        dof=None if dof is None or not np.isfinite(dof) else float(dof),
        method=("Cauchy-Schwarz bound over all directions of the parameter error, "
                f"linearised ({law}; Monte Carlo quantiles, {draws} draws)"),
    )


# --- what the figure takes as known ---------------------------------------------------


def assumes(model: str, frame: str = "translation", tilt_interval: Mapping | None = None,
            postures_per_leg: int = 2, dof: float | None = None,
            tilts_in_interval: bool = False) -> list[str]:
    """In words, what an accuracy figure computed from a fit of ``model`` (a key
    of MODELS) takes as known (docs/model.md, "Accuracy at the tool": "what the figure
    cannot know must be said with it"). ``tilt_interval``: {tilt name: (lo, hi)
    mrad}, the 95 % intervals of a rho+tilt fit when the model selection kept a
    model without tilts; ``postures_per_leg``: test stops per leg (ΔL beside the
    tilts needs more than two); ``dof``: of the covariance behind the interval;
    ``tilts_in_interval``: the caller gave :func:`after_interval` the rho+tilt fit's
    tilt covariance (tilts at 0 in the estimate), so the intervals include them."""
    if model not in MODELS:
        raise ValueError(f"model must be one of {sorted(MODELS)}, got {model!r}")
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    cols = set(MODELS[model])
    out: list[str] = []
    if not cols & {0, 1, 2}:
        out.append(f"Δρ = 0 (joint zero errors not in model {model!r})")
    if not cols & {3, 4, 5}:
        if cols & {6, 7, 8} and postures_per_leg <= 2:
            why = "not identifiable beside the tilts from two postures per leg"
        elif cols & {6, 7, 8}:
            why = f"not in model {model!r}"
        else:
            why = f"not in model {model!r}; beside Δρ it is nearly inseparable (model 'full')"
        out.append(f"ΔL = 0 (leg lengths nominal; {why}); a leg 0.1 mm long changes the field")
    if not cols & {6, 7, 8}:
        if tilt_interval:
            spans = ", ".join(f"{nm} [{float(tilt_interval[nm][0]):.3g}, "
                              f"{float(tilt_interval[nm][1]):.3g}]"
                              for nm in TILT_NAMES if nm in tilt_interval)
            tail = ("the intervals include that uncertainty" if tilts_in_interval
                    else "which the figure leaves out")
            out.append(f"tilts = 0 (axes square; model {model!r} was kept): the rho+tilt fit "
                       f"puts them within {spans} mrad (95 %), {tail}")
        else:
            out.append(f"tilts = 0 (actuator axes square; not in model {model!r})")
    out.append("otherwise the machine of model (1'): rigid links, ideal joints and "
               "parallelograms, encoders exact up to their zero")
    if frame == "translation":
        out.append("frame 'translation': the tool offset is set by touching off "
                   "(the mean error is removed)")
    else:
        out.append("frame 'rigid': parts are aligned by probing "
                   "(the least-squares rigid motion is removed)")
    law = f"Student t with {dof:g} dof" if dof is not None and np.isfinite(dof) else "normal"
    out.append(f"the 95 % intervals propagate the fit's covariance ({law}) through the exact "
               "model, linearised, and hold only under the assumptions above")
    return out
