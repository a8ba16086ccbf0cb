"""The figures of a tool-point error field, RMS and max of |E|, with their 95 %
intervals: Monte Carlo over the joint distribution of the inputs (GUM Supplement 1,
JCGM 101:2008), corrected where the field is near zero (docs/model.md, "Intervals
at the tool").

Over the draws' size the fitted field is linear in the inputs' errors
(docs/model.md states the tolerance against the exact model), so the truth and the
plug-in are

    F = F_s + N_t,      F̂ = F_s + N_o                                       (S1)

F_s the part fixed by the machine and what was written, N_o the errors the plug-in
holds and the truth does not (the estimate's error δ = θ̂ − θ through the field's
Jacobian), N_t those the truth holds and the plug-in does not (what a controller
told the estimate is off by; errors of the machine beyond the model). Each draw
gives both from the inputs' joint distribution (:class:`Inputs`).

Per figure (:func:`figures`), with v = F̂/‖F̂‖ and F_s = λ·v: the same draws give the
distribution of the plug-in's figure at λ (noncentral: the plug-in of a norm is
biased upward by the noise, and plain S1, F̂ − N, misses a truth near zero), hence λ's
confidence distribution C(λ) = P_λ(figure ≥ observed); λ_d = C⁻¹(u_d) paired with the
truth's draws gives the predictive distribution of the truth's figure (a plug-in
below a zero field's median figure read as that median: power-constrained). Its mean
is the value, its 97.5 % point the upper end, and the lesser of its 2.5 % point and the
truth's at C⁻¹(2.5 %) the lower.

With no N_o it is plain S1 (the probabilistically symmetric interval of the draws);
with no N_t the Neyman interval of λ; for a large field both are F̂'s figure ± the
quantiles of the noise along v. Pure: numpy in, numpy out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from orthocal.accuracy import FRAMES
from orthocal.geometry import PARAM_NAMES

#: Draws (draws, n, 3) of a fitted field's error, from a generator and a count.
FieldDraws = Callable[[np.random.Generator, int], np.ndarray]
#: Draws per chunk: a chunk's fields are draws × 3n floats (about 8 MB on the 7³ grid).
CHUNK = 1000
#: The power-constrained limit's threshold: a plug-in is read as no less than a zero
#: field's figure at this quantile (Cowan et al. 2011 propose 0.16, one σ below the median).
POWER = 0.16
#: Nodes of λ at which a statistic's distribution is drawn (C(λ) between them linear).
RMS_NODES, MAX_NODES = 65, 13


@dataclass(frozen=True)
class Bounded:
    """Bounded systematic inputs (JCGM 101, 6.4.2.1: rectangular): input j uniform
    in ±``bounds[j]``, independent of the others; ``columns`` (k × m) the effect of one
    unit of each on k quantities: parameters named ``names`` (None: the 12 of
    PARAM_NAMES, or 9 of them), or a field's 3n values (x, y, z of each point)."""

    columns: np.ndarray
    bounds: np.ndarray
    names: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        c = np.atleast_2d(np.asarray(self.columns, dtype=float))
        b = np.atleast_1d(np.asarray(self.bounds, dtype=float))
        if c.ndim != 2 or b.shape != (c.shape[1],):
            raise ValueError(f"bounded: {c.shape[1] if c.ndim == 2 else '?'} columns need as "
                             f"many bounds, got shape {b.shape}")
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(b)) and np.all(b >= 0)):
            raise ValueError("bounded: columns and bounds must be finite, bounds ≥ 0")
        if self.names is not None and len(self.names) != c.shape[0]:
            raise ValueError(f"bounded: {c.shape[0]} rows, {len(self.names)} names")
        object.__setattr__(self, "columns", c)
        object.__setattr__(self, "bounds", b)

    def draw(self, rng: np.random.Generator, draws: int) -> np.ndarray:
        """(draws, k): Σ_j u_j·columns[:, j], u_j uniform in ±bounds[j]."""
        return (rng.uniform(-1.0, 1.0, (draws, len(self.bounds))) * self.bounds) @ self.columns.T


def frame_projection(points, frame: str) -> Callable[[np.ndarray], np.ndarray]:
    """The frame of a small field error (draws, n, 3), linearised: ``"translation"``
    removes the mean, ``"rigid"`` the least-squares translation and small rotation
    about the centroid (Kabsch to first order; docs/model.md, "Accuracy at the tool")."""
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    p = np.asarray(points, dtype=float)
    if frame == "translation":
        return lambda e: e - e.mean(axis=-2, keepdims=True)
    r = p - p.mean(axis=0)
    basis = np.zeros((len(p), 3, 6))
    basis[:, :, :3] = np.eye(3)
    for k, axis in enumerate(np.eye(3)):  # ω_k × r
        basis[:, :, 3 + k] = np.cross(axis, r)
    U, _ = np.linalg.qr(basis.reshape(-1, 6))

    def project(e: np.ndarray) -> np.ndarray:
        flat = e.reshape(*e.shape[:-2], -1)
        return (flat - (flat @ U) @ U.T).reshape(e.shape)
    return project


def root(cov: np.ndarray) -> np.ndarray:
    """R with R·Rᵀ = cov: Cholesky (+ 1e-12 of the largest variance on the diagonal, so
    that an exact correlation factors), unique and continuous, so a seed draws the
    same machines on every CPU and BLAS; the positive part by eigenvectors where cov
    is not positive semi-definite beyond rounding."""
    scale = float(np.max(np.diag(cov))) if cov.size else 0.0
    if scale <= 0:
        return np.zeros((len(cov), 0))
    try:
        return np.linalg.cholesky(cov + np.eye(len(cov)) * 1e-12 * scale)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(cov)
        return V * np.sqrt(np.clip(w, 0.0, None))


@dataclass(frozen=True)
class Inputs:
    """The joint distribution of a field's errors (n points; :func:`figures`).

    Parameters: δ (k) = R·z/s + R_n·z' + Σ bounded, z and z' standard normal, s² =
    χ²_ν/ν common to the draw's ``stat_root`` part (Student t on ``dof``; None:
    normal), ``normal_root`` a normal part (a systematic input known by its covariance
    alone, JCGM 101 6.4.8), each :class:`Bounded` rectangular; through ``jacobian``
    (3n × k, the fitted field per unit) into the plug-in (N_o) where ``observed``, else
    into the truth (N_t). ``fields``: further draws of the truth's fitted field
    (draws, n, 3), each a :data:`FieldDraws` or a :class:`Bounded` over the 3n values."""

    jacobian: np.ndarray
    observed: np.ndarray
    stat_root: np.ndarray | None = None
    dof: float | None = None
    normal_root: np.ndarray | None = None
    bounded: tuple[Bounded, ...] = ()
    fields: tuple[FieldDraws | Bounded, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.dof is not None and np.isfinite(self.dof) and not self.dof > 0:
            raise ValueError(f"dof must be > 0, got {self.dof}")

    def _parts(self) -> tuple[bool, bool]:
        """(any error in the plug-in, any in the truth)."""
        k = self.jacobian.shape[1]
        acts = np.zeros(k, dtype=bool)
        for r in (self.stat_root, self.normal_root):
            if r is not None and r.size:
                acts |= np.any(r != 0, axis=1)
        for b in self.bounded:
            acts |= np.any(b.columns * b.bounds != 0, axis=1)
        acts &= np.any(self.jacobian != 0, axis=0)
        return bool(np.any(acts & self.observed)), bool(np.any(acts & ~self.observed)
                                                        or self.fields)

    def draw(self, rng: np.random.Generator, draws: int,
             kinds: tuple[bool, bool] = (True, True)) -> tuple[np.ndarray, np.ndarray]:
        """(N_o, N_t), each (draws, n, 3), from one draw of every input; a kind not in
        ``kinds`` is left zero (the draws are the same either way)."""
        k = self.jacobian.shape[1]
        delta = np.zeros((draws, k))
        if self.stat_root is not None and self.stat_root.size:
            z = rng.standard_normal((draws, self.stat_root.shape[1]))
            if self.dof is not None and np.isfinite(self.dof):
                z /= np.sqrt(rng.chisquare(self.dof, size=(draws, 1)) / self.dof)
            delta += z @ self.stat_root.T
        if self.normal_root is not None and self.normal_root.size:
            delta += rng.standard_normal((draws, self.normal_root.shape[1])) @ self.normal_root.T
        for b in self.bounded:
            delta += b.draw(rng, draws)
        shape = (draws, self.jacobian.shape[0] // 3, 3)
        out = []
        for used, mask in zip(kinds, (self.observed, ~self.observed), strict=True):
            out.append((delta[:, mask] @ self.jacobian[:, mask].T).reshape(shape)
                        if used and np.any(mask) else np.zeros(shape))
        for f in self.fields:
            x = f.draw(rng, draws) if isinstance(f, Bounded) else np.asarray(f(rng, draws))
            if kinds[1]:
                out[1] += x.reshape(shape)
        return out[0], out[1]


def parameter_columns(bounded: Bounded) -> np.ndarray:
    """A :class:`Bounded` over parameters as 12 rows of PARAM_NAMES (its ``names``; or
    its 12 rows, or 9: the axes meet)."""
    c = bounded.columns
    out = np.zeros((len(PARAM_NAMES), c.shape[1]))
    if bounded.names is not None:
        unknown = set(bounded.names) - set(PARAM_NAMES)
        if unknown:
            raise ValueError(f"bounded: unknown parameter name(s) {sorted(unknown)}")
        out[[PARAM_NAMES.index(n) for n in bounded.names]] = c
    elif c.shape[0] in (9, len(PARAM_NAMES)):
        out[:c.shape[0]] = c
    else:
        raise ValueError(f"bounded: {c.shape[0]} rows and no names")
    return out


def parameter_inputs(jacobian: np.ndarray, columns: Sequence[int], covariance: np.ndarray,
                     dof: float | None, *, systematic: np.ndarray | None = None,
                     bounded: Sequence[Bounded] = (), observed=None,
                     fields: Sequence[FieldDraws | Bounded] = ()) -> Inputs:
    """:class:`Inputs` of the parameters ``columns`` (indices into PARAM_NAMES) whose
    fitted field per unit is ``jacobian`` (3n × len(columns)): ``covariance`` the
    statistical part (12×12, Student t on ``dof``), ``systematic`` a normal part
    (12×12), ``bounded`` rectangular ones (any :class:`Bounded` over parameters),
    ``observed`` (12 booleans, default all) the parameters whose error is in the
    plug-in, ``fields`` the truth's further field errors."""
    cols = list(columns)
    ix = np.ix_(cols, cols)
    seen = np.ones(len(PARAM_NAMES), dtype=bool) if observed is None else \
        np.asarray(observed, dtype=bool)
    if seen.shape != (len(PARAM_NAMES),):
        raise ValueError(f"observed: one flag per parameter ({len(PARAM_NAMES)})")
    return Inputs(
        jacobian=jacobian, observed=seen[cols],
        stat_root=root(np.asarray(covariance, dtype=float)[ix]),
        dof=None if dof is None or not np.isfinite(dof) else float(dof),
        normal_root=None if systematic is None else root(np.asarray(systematic, dtype=float)[ix]),
        bounded=tuple(Bounded(parameter_columns(b)[cols], b.bounds) for b in bounded),
        fields=tuple(fields))


def active_columns(covariance: np.ndarray, systematic: np.ndarray | None,
                   bounded: Sequence[Bounded]) -> list[int]:
    """The parameters (indices into PARAM_NAMES) any input moves."""
    act = np.diag(covariance) > 0
    if systematic is not None:
        act |= np.diag(systematic) > 0
    for b in bounded:
        act |= np.any(parameter_columns(b) * b.bounds != 0, axis=1)
    return [int(c) for c in np.flatnonzero(act)]


def field_inputs(points, frame: str, field_draws, joint_draws,
                 joint_jacobian: Callable[[], np.ndarray]) -> tuple[FieldDraws | Bounded, ...]:
    """The truth's further field errors as :class:`Inputs` takes them, in ``frame``:
    ``field_draws`` the tool's raw error (before the frame) and ``joint_draws`` the
    joints' positioning error at each point's joints, each a :data:`FieldDraws`
    ((draws, n, 3) mm), a :class:`Bounded` over the 3n values, or a sequence of them;
    ``joint_jacobian()`` (n, 3, 3) ∂E_k/∂q_k, the tool's raw error per joint error at
    each point, asked for only when joint errors are given."""
    project = frame_projection(points, frame)
    n = len(np.asarray(points))

    def listed(x) -> list:
        return [] if x is None else [x] if isinstance(x, Bounded) or callable(x) else list(x)

    joints = listed(joint_draws)
    J = joint_jacobian() if joints else None
    return tuple([_framed(item, "field", None, project, n) for item in listed(field_draws)]
                 + [_framed(item, "joint", J, project, n) for item in joints])


def _framed(item: FieldDraws | Bounded, kind: str, J: np.ndarray | None,
            project: Callable[[np.ndarray], np.ndarray], n: int) -> FieldDraws | Bounded:
    """One field or joint error in the fitted frame."""
    def to_field(x: np.ndarray) -> np.ndarray:  # (..., n, 3) raw → fitted
        x = np.asarray(x, dtype=float)
        if x.shape[-2:] != (n, 3):
            raise ValueError(f"{kind} errors: expected (draws, {n}, 3), got {x.shape}")
        if J is not None:
            x = np.einsum("kij,...kj->...ki", J, x)
        return project(x)
    if isinstance(item, Bounded):
        if item.columns.shape[0] != 3 * n:
            raise ValueError(f"{kind} errors: a bounded input needs {3 * n} rows "
                             f"(x, y, z of each point), got {item.columns.shape[0]}")
        cols = to_field(item.columns.T.reshape(-1, n, 3)).reshape(len(item.bounds), -1).T
        return Bounded(cols, item.bounds)
    if not callable(item):
        raise ValueError(f"{kind} errors: a callable (rng, draws) or a Bounded")
    return lambda rng, draws: to_field(item(rng, draws))


@dataclass(frozen=True)
class Figures:
    """RMS and max of |E| of the truth's field (mm), their ``level`` intervals, and
    ``point_rms_mm`` the root mean square of |E| at each point over the truth's
    draws at the value's λ (:func:`figures`)."""

    rms_mm: float
    max_mm: float
    rms_interval_mm: tuple[float, float]
    max_interval_mm: tuple[float, float]
    point_rms_mm: np.ndarray


@dataclass(frozen=True)
class _Sums:
    """One kind of error N over the draws, against the direction v (unit RMS; w_k =
    |v_k|²): per draw and point c = v_k·N_k and e = |N_k|² (float32: the max's
    inner loop), per draw a = ⟨v, N⟩ and b = ‖N‖² (RMS inner product, float64)."""

    c: np.ndarray
    e: np.ndarray
    a: np.ndarray
    b: np.ndarray
    w: np.ndarray

    def rms(self, lam: np.ndarray) -> np.ndarray:
        """‖λ·v + N‖ (RMS over the points), (len(lam), draws)."""
        lam = np.asarray(lam, dtype=float)[:, None]
        return np.sqrt(np.clip(lam**2 + 2 * lam * self.a + self.b, 0.0, None))

    def max(self, lam: np.ndarray) -> np.ndarray:
        """max_k |λ·v_k + N_k|, (len(lam), draws). At each λ only the points that can
        hold the max of some draw are summed: |λ·v_k + N_k| ≤ λ|v_k| + s_k (s_k the
        largest |N_k| over the draws) and every draw reaches λ·|v_j| − s_j at the point
        j of the largest |v_j| (triangle inequality)."""
        v = np.sqrt(self.w)
        s = np.sqrt(self.e.max(axis=0))
        j = int(np.argmax(v))
        out = np.empty((len(lam), len(self.c)))
        for i, x in enumerate(np.asarray(lam, dtype=float)):
            keep = x * v + s >= x * v[j] - s[j]
            c, e, w = (self.c, self.e, self.w) if keep.all() else \
                (self.c[:, keep], self.e[:, keep], self.w[keep])
            y = np.float32(x)
            f = c * (2 * y)
            f += e
            f += (y * y) * w
            out[i] = np.sqrt(np.clip(f.max(axis=1), 0.0, None))
        return out

    def paired(self, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(‖λ_d·v + N_d‖ RMS, max_k |λ_d·v_k + N_dk|) for each draw d at its own λ_d."""
        lam = np.asarray(lam, dtype=float)
        rms = np.sqrt(np.clip(lam**2 + 2 * lam * self.a + self.b, 0.0, None))
        y = lam.astype(np.float32)[:, None]
        f = self.c * (2 * y)
        f += self.e
        f += (y * y) * self.w
        return rms, np.sqrt(np.clip(f.max(axis=1), 0.0, None)).astype(float)

    @property
    def largest(self) -> float:
        """The largest |N_k| over draws and points (mm)."""
        return float(np.sqrt(self.e.max()))


def _sums(inputs: Inputs, v: np.ndarray, draws: int, seed: int, kinds: tuple[bool, bool]
          ) -> tuple[_Sums, _Sums]:
    """(_Sums of N_o, of N_t) over ``draws`` seeded draws, in chunks; a kind not in
    ``kinds`` (no input of it) stays zero."""
    rng = np.random.default_rng(seed)
    n = len(v)
    w = np.sum(v**2, axis=1)
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = [
        (np.zeros((draws, n), np.float32), np.zeros((draws, n), np.float32),
         np.zeros(draws), np.zeros(draws)) for _ in range(2)]
    for lo in range(0, draws, CHUNK):
        m = min(CHUNK, draws - lo)
        for (c, e, a, b), x, used in zip(parts, inputs.draw(rng, m, kinds), kinds,
                                         strict=True):
            if used:
                cc = x[..., 0] * v[:, 0] + x[..., 1] * v[:, 1] + x[..., 2] * v[:, 2]
                ee = x[..., 0]**2 + x[..., 1]**2 + x[..., 2]**2
                c[lo:lo + m], e[lo:lo + m] = cc, ee
                a[lo:lo + m], b[lo:lo + m] = cc.mean(axis=1), ee.mean(axis=1)
    w32 = w.astype(np.float32)
    (c_o, e_o, a_o, b_o), (c_t, e_t, a_t, b_t) = parts
    return _Sums(c_o, e_o, a_o, b_o, w32), _Sums(c_t, e_t, a_t, b_t, w32)


@dataclass(frozen=True)
class _Confidence:
    """λ's confidence distribution from a statistic of the plug-in, C(λ) = P_λ(stat ≥ t)
    (Xie and Singh 2013), on nodes: C⁻¹(½) is the median-unbiased λ, and C⁻¹(α/2) …
    C⁻¹(1 − α/2) the Neyman interval of λ from the statistic's noncentral
    distribution over the draws."""

    lam: np.ndarray
    c: np.ndarray

    def at(self, p):
        """C⁻¹(p) (p a number or an array); a mass at the lowest node (0 when it is 0)
        below C there."""
        return np.interp(p, self.c, self.lam)


def _confidence(stat: Callable[[np.ndarray], np.ndarray], t: float, scale: float,
                reach: float, nodes: int) -> _Confidence:
    """:class:`_Confidence` of ``stat`` observed at ``t``, read as no less than a zero
    field's statistic at its POWER quantile (a power-constrained limit, Cowan, Cranmer,
    Gross and Vitells 2011: below it C⁻¹ would shrink with the noise's luck, to a
    point at 0 for a plug-in of nothing). stat(λ) lies within scale·λ ± ``reach``
    (triangle inequality), so the nodes span only what that leaves possible."""
    zero = stat(np.zeros(1))[0]
    t = max(t, float(np.quantile(zero, POWER)))
    bottom = max(0.0, (t - reach) / scale)
    lam = np.linspace(bottom, (t + reach) / scale + 1e-12, nodes)
    values = stat(lam)
    if bottom == 0.0:
        values[0] = zero
    c = np.maximum.accumulate(np.mean(values >= t, axis=1))
    c[-1] = 1.0  # every draw is above t there (triangle inequality)
    return _Confidence(lam, c)


def _figure(conf: _Confidence | None, truth: Callable[[np.ndarray], np.ndarray],
            paired: Callable[[np.ndarray], np.ndarray], u: np.ndarray, plug_in: float,
            level: float) -> tuple[float, float, float]:
    """(value, lo, hi) of one figure of the truth, λ from ``conf`` (None: exactly the
    plug-in's scale): ``paired(λ)`` the truth's draws each at its own λ_d,
    ``truth(λs)`` its draws at each of the λs. The predictive distribution: λ_d =
    C⁻¹(u_d) paired at random with the truth's draws (Shen, Liu and Xie 2018); its
    mean (JCGM 101, 5.1.1: the estimate is the expectation) and upper quantile, and as
    lower end the lesser of its lower quantile and the truth's lower quantile at λ's
    lower end. The predictive alone is exact where the figure is linear in both errors
    (a large field: plug-in ± z·s, plain S1's); near zero its λ_d ≥ 0 only lift the
    truth, so the lower end takes the union's there."""
    p = (1.0 - level) / 2.0, (1.0 + level) / 2.0
    if conf is None:
        x = paired(np.full(len(u), plug_in))
        lo, hi = np.quantile(x, p)
    else:
        x = paired(conf.at(u))
        lo, hi = np.quantile(x, p)
        lo = min(lo, float(np.quantile(truth(np.array([float(conf.at(p[0]))]))[0], p[0])))
    # the mean lies inside but where a tail is extreme: then the nearer end
    return float(np.clip(np.mean(x), lo, hi)), float(lo), float(hi)


def _direction(F0: np.ndarray, inputs: Inputs, seed: int) -> np.ndarray:
    """v = F̂/‖F̂‖ (unit RMS); for F̂ = 0 the plug-in's noisiest direction."""
    norm = float(np.sqrt(np.mean(np.sum(F0**2, axis=1))))
    if norm > 0:
        return F0 / norm
    obs, _ = inputs.draw(np.random.default_rng(seed + 1), 64)
    flat = obs.reshape(len(obs), -1)
    if not np.any(flat):
        return np.zeros_like(F0)
    top = np.linalg.svd(flat, full_matrices=False)[2][0].reshape(F0.shape)
    return top / float(np.sqrt(np.mean(np.sum(top**2, axis=1))))


def figures(F0, inputs: Inputs, level: float = 0.95, draws: int = 4000,
            seed: int = 0) -> Figures:
    """RMS and max of |E| of the truth's fitted field and their ``level`` intervals
    (module docstring, (S1)), F̂ = ``F0`` (n, 3) mm the plug-in, the errors from
    ``inputs`` over ``draws`` seeded draws. Each figure's value lies in its interval,
    and the max is never below the RMS (value and both ends: the truth's max of |E| is
    at least its RMS, so each end of the max's is raised to the RMS's)."""
    if not 0 < level < 1:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    if draws < 100:
        raise ValueError(f"draws must be at least 100, got {draws}")
    F0 = np.asarray(F0, dtype=float)
    norms = np.sqrt(np.sum(F0**2, axis=1))
    T, M = float(np.sqrt(np.mean(norms**2))), float(norms.max())
    has_obs, has_truth = inputs._parts()
    if not (has_obs or has_truth):
        return Figures(T, M, (T, T), (M, M), norms)
    v = _direction(F0, inputs, seed)
    w = np.sum(v**2, axis=1)
    m_v = float(np.sqrt(w.max()))
    obs, truth = _sums(inputs, v, draws, seed, (has_obs, has_truth))
    rms_c = _confidence(obs.rms, T, 1.0, float(np.sqrt(obs.b.max())), RMS_NODES) \
        if has_obs else None
    max_c = _confidence(obs.max, M, m_v, obs.largest, MAX_NODES) if has_obs else None
    # λ's confidence draws, stratified, paired with the truth's draws at random
    u = (np.random.default_rng(seed + 2).permutation(draws) + 0.5) / draws
    rms = _figure(rms_c, truth.rms, lambda x: truth.paired(x)[0], u, T, level)
    if has_truth:
        mx = _figure(max_c, truth.max, lambda x: truth.paired(x)[1], u, T, level)
    else:  # the truth is λ·v: its max is λ·max|v|
        lam_v, lam_lo, lam_hi = _figure(max_c, lambda x: x[:, None], lambda x: x, u, T, level)
        mx = (m_v * lam_v, m_v * lam_lo, m_v * lam_hi)
    # each point's root mean square over the predictive draws
    lam = np.full(draws, T) if rms_c is None else rms_c.at(u)
    point = np.sqrt(np.clip(np.mean(lam**2) * w + 2 * (lam @ truth.c) / draws
                            + truth.e.mean(axis=0), 0.0, None))
    return Figures(rms[0], max(mx[0], rms[0]), (rms[1], rms[2]),
                   (max(mx[1], rms[1]), max(mx[2], rms[2])), point)
