"""Design of the experiment before it runs: how well a set of test postures
determines a model, and which strokes would do better.

Everything follows from the Jacobian J of the deviations, system (7) / (7')
at the nominal machine (:func:`orthocal.jacobian`, equal there to the exact
model's derivative). With independent noise σ on each deviation the least
squares estimate has covariance σ²·(JᵀJ)⁻¹; its diagonal's root per unit σ is
each parameter's *noise gain*, the statistical floor
(:func:`orthocal.statistical_floor`).

A stop's deviations are referenced to the mean of the two Π0 stops around it
(station's sequencer), so in a real run the deviations of one indicator in
one cycle share noise; :func:`run_covariance` propagates that exactly to the
covariance C of the station's estimate per unit of indicator noise. Its
inverse is the run's information matrix. A design is scored D-optimal (max
ln det C⁻¹: the confidence ellipsoid's volume shrinks as det C^(1/2); the
score does not depend on the parameters' units beyond a constant, so mm and
mrad need no weighting) or A-optimal (min trace C: the sum of the squared
standard errors). The stroke search here is D-optimal; A is reported beside it.

"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from orthocal.calibration import jacobian
from orthocal.geometry import FIT_NAMES, MODELS, PARAM_NAMES, Geometry
from orthocal.measurement import Key
from orthocal.postures import plane_at, posture_name
from orthocal.stands import Stands, incidence, stand_jacobian

# Relative singular value below which a combination counts as invisible (as in
# identification: the worst well-posed case sits near 1/200).
RANK_TOL = 1e-9
# A weight below this fraction of the largest is left out of the words.
_WORD_TOL = 0.05


@dataclass(frozen=True)
class Quality:
    """How well deviations ``keys`` determine ``model`` (per unit deviation noise)."""

    model: str
    names: tuple[str, ...]
    n_deviations: int
    rank: int
    condition_number: float  # inf when rank-deficient
    noise_gain: dict[str, float]  # σ_param / σ_deviation; inf when not identifiable
    log_det: float  # ln det JᵀJ (D criterion); -inf when rank-deficient
    trace_cov: float  # trace (JᵀJ)⁻¹ (A criterion); inf when rank-deficient
    invisible: tuple[dict[str, float], ...]  # null-space combinations (largest weight 1)
    weakest: dict[str, float]  # best-hidden combination (smallest singular value)

    @property
    def identifiable(self) -> bool:
        return self.rank == len(self.names)


def design_matrix(keys: Sequence[Key], geometry: Geometry, model: str) -> np.ndarray:
    """J of (7)/(7') for ``keys`` and ``model`` at the nominal machine."""
    if model not in MODELS:
        raise ValueError(f"model must be one of {sorted(MODELS)}, got {model!r}")
    return jacobian(list(keys), geometry, model)


def _combination(names: Sequence[str], v: np.ndarray) -> dict[str, float]:
    v = v / v[np.argmax(np.abs(v))]
    return {n: float(w) for n, w in zip(names, v, strict=True) if abs(w) >= _WORD_TOL}


def quality(keys: Sequence[Key], geometry: Geometry, model: str) -> Quality:
    """Rank, condition number, noise gains, D and A criteria and the invisible
    parameter combinations of ``model`` measured by ``keys``."""
    J = design_matrix(keys, geometry, model)
    names = tuple(FIT_NAMES[c] for c in MODELS[model])
    p = len(names)
    # full_matrices: vt is p×p even with fewer deviations than parameters.
    _, s, vt = np.linalg.svd(J.reshape(-1, p), full_matrices=True)
    s = np.concatenate([s, np.zeros(p - s.size)])
    rank = int(np.sum(s > RANK_TOL * max(s[0], 1e-300)))
    invisible = tuple(_combination(names, vt[k]) for k in range(rank, p))
    weakest = _combination(names, vt[-1])
    if rank < p:
        gains = {n: float("inf") for n in names}
        return Quality(model, names, len(keys), rank, float("inf"), gains, float("-inf"),
                       float("inf"), invisible, weakest)
    cov = np.linalg.inv(J.T @ J)
    gains = {n: float(np.sqrt(cov[k, k])) for k, n in enumerate(names)}
    return Quality(model, names, len(keys), rank, float(s[0] / s[-1]), gains,
                   float(2.0 * np.sum(np.log(s))), float(np.trace(cov)), (), weakest)


def describe(q: Quality) -> list[str]:
    """In words: what the deviations cannot separate (null space), or, when all is
    identifiable, which combination is worst determined."""

    def term(name: str, w: float, first: bool) -> str:
        mag = "" if abs(abs(w) - 1.0) < 5e-3 else f"{abs(w):.2f}·"
        sign = ("−" if w < 0 else "") if first else (" − " if w < 0 else " + ")
        return f"{sign}{mag}{name}"

    def combo(c: dict[str, float]) -> str:
        return "".join(term(n, w, k == 0) for k, (n, w) in enumerate(c.items()))

    if not q.identifiable:
        out = [f"rank {q.rank} < {len(q.names)}: these postures cannot separate the "
               f"parameters of model {q.model}."]
        for c in q.invisible:
            if len(c) == 1:
                out.append(f"{next(iter(c))} changes no deviation at all: it is invisible.")
            else:
                out.append(f"moving along {combo(c)} (mm, mrad for tilts) changes no "
                           f"deviation: {', '.join(c)} cannot be told apart; fix one of "
                           "them, identify a smaller model, or add strokes.")
        return out
    gain = max(q.noise_gain.values())
    return [f"all {len(q.names)} parameters identifiable; the worst-determined "
            f"combination is {combo(q.weakest)} (largest noise gain {gain:.3g})."]


def keys_for(strokes: Sequence[float], legs: Mapping[str, Sequence[str]],
             geometry: Geometry) -> list[Key]:
    """Deviation keys of the stops at ``strokes`` for legs → measured directions."""
    names = [posture_name(float(s), geometry) for s in strokes]
    return [(p, leg, d) for p in names for leg, dirs in legs.items() for d in dirs]


def run_covariance(J: np.ndarray, indicators: Sequence[Sequence[int]], cycles: int,
                   readings: int) -> np.ndarray:
    """Covariance of the station's estimate per unit² of indicator (reading) noise
    for a whole run, as the station measures and fits it.

    ``J`` has one row per deviation key; ``indicators`` lists, per mounted
    indicator, its rows (one per stop). Each cycle an indicator reads Π0, its n
    stops and Π0 again (shared with the next cycle), ``readings`` times each; a
    deviation is its stop's mean minus the mean of the two Π0 means around it,
    so within a cycle var = 1.5/r, cov = 0.5/r, and between consecutive cycles
    cov = 0.25/r. The station fits the c cycles' deviations by ordinary least
    squares, X = 1_c ⊗ J_m stacked over indicators m, whose covariance is
    (XᵀX)⁻¹ XᵀΣX (XᵀX)⁻¹ with

        XᵀX = c·Σ_m J_mᵀJ_m,
        XᵀΣX = (1/r)·Σ_m [c·J_mᵀJ_m + (c − 0.5)·b_m b_mᵀ],  b_m = J_mᵀ1.

    The b_m term is the shared Π0: stops read against the same Π0 pair add less
    information than independent deviations would."""
    A, meat = _run_terms(J, indicators, cycles)
    inv = np.linalg.inv(A)
    return inv @ meat @ inv / readings


def _run_terms(J: np.ndarray, indicators: Sequence[Sequence[int]], cycles: int
               ) -> tuple[np.ndarray, np.ndarray]:
    p = J.shape[1]
    A = np.zeros((p, p))
    meat = np.zeros((p, p))
    for rows in indicators:
        Jm = J[list(rows)]
        b = Jm.sum(axis=0)
        A += cycles * Jm.T @ Jm
        meat += cycles * Jm.T @ Jm + (cycles - 0.5) * np.outer(b, b)
    return A, meat


def run_std_errors(J: np.ndarray, indicators: Sequence[Sequence[int]], cycles: int,
                   readings: int) -> np.ndarray:
    """Each parameter's standard error per unit of indicator noise for a whole run
    (:func:`run_covariance`)."""
    return np.sqrt(np.diag(run_covariance(J, indicators, cycles, readings)))


@dataclass(frozen=True)
class Search:
    """Result of :func:`search_strokes`."""

    strokes: tuple[float, ...]
    quality: Quality
    candidates: int  # feasible grid strokes the search looked at


def search_strokes(
    current: Sequence[float],
    legs: Mapping[str, Sequence[str]],
    geometry: Geometry,
    model: str,
    bounds: tuple[float, float],
    feasible: Callable[[float], bool] | None = None,
    feasible_set: Callable[[tuple[float, ...]], bool] | None = None,
    cycles: int = 3,
    step: float = 1.0,
    max_stops: int = 8,
) -> Search:
    """D-optimal strokes: as many stops per leg as ``current`` (more, up to
    ``max_stops``, only when that many cannot identify ``model`` at all), each on
    a ``step`` grid within ``bounds``, nonzero, distinct and ``feasible``; a set
    of strokes replaces the current one only if ``feasible_set`` accepts it (the
    moves between stops matter too, not only each stop).

    The objective is ln det of the information of the run as the station fits
    it, the inverse of :func:`run_covariance` (readings only scale it), not of
    JᵀJ alone: that would ignore the shared Π0 and favour stops bunched at one
    end, whose deviations share most of their noise.

    Coordinate exchange: replace one stroke at a time by the candidate that most
    improves the objective, until no exchange does. Starts from ``current``
    (its infeasible strokes replaced) and from the candidates spread evenly, and
    keeps the better: never worse than a feasible ``current``."""
    lo, hi = bounds
    grid_v = np.round(np.arange(np.ceil(lo / step) * step, hi + 1e-9, step), 9)
    grid_v = np.unique(np.concatenate([grid_v, [s for s in current if lo <= s <= hi]]))
    grid = _Grid([float(s) for s in grid_v if s != 0], feasible)
    if not grid.strokes:
        raise ValueError(f"no stroke within [{lo:g}, {hi:g}] mm")
    per_stop = len(keys_for([1.0], legs, geometry))
    J = design_matrix(keys_for(grid.strokes, legs, geometry), geometry, model)
    rows = J.reshape(len(grid.strokes), per_stop, -1)  # [stroke, indicator, parameter]
    checked: dict[frozenset[int], bool] = {}

    def objective(idx: Sequence[int]) -> float:
        return _log_det_information(rows[list(idx)], cycles)

    def allowed(idx: Sequence[int]) -> bool:
        key = frozenset(idx)
        if key not in checked:
            checked[key] = feasible_set is None or feasible_set(grid.sorted(idx))
        return checked[key]

    n = max(1, min(len(current), len(grid.strokes)))
    while True:
        starts = grid.starts(current, n)
        if not starts:
            raise ValueError(f"fewer than {n} feasible strokes within [{lo:g}, {hi:g}] mm")
        best = max((_exchange(s, grid, objective, allowed) for s in starts),
                   key=lambda idx: objective(idx) if allowed(idx) else float("-inf"))
        if np.isfinite(objective(best)) or n >= min(max_stops, len(grid.strokes)):
            break
        n += 1
    strokes = grid.sorted(best)
    return Search(strokes, quality(keys_for(strokes, legs, geometry), geometry, model),
                  grid.feasible_seen())


def _log_det_information(sub: np.ndarray, cycles: int) -> float:
    """ln det of the information of a run whose stops' rows are ``sub`` [stop,
    indicator, parameter] (the inverse of :func:`run_covariance`; -inf where the
    stops cannot identify the model)."""
    A = cycles * np.einsum("smp,smq->pq", sub, sub)
    lam = np.linalg.eigvalsh(A)
    # λ = s², so RANK_TOL on singular values would sit below rounding; 1e-12 on
    # λ (1e-6 on s) still passes the worst well-posed design (full+tilt, ~1/300).
    if lam[0] <= 1e-12 * lam[-1]:
        return float("-inf")
    b = sub.sum(axis=0)  # [indicator, parameter]
    meat = A + (cycles - 0.5) * b.T @ b
    # ln det of the information (A meat⁻¹ A) = 2 ln det A − ln det meat
    return float(2.0 * np.sum(np.log(lam)) - np.linalg.slogdet(meat)[1])


class _Grid:
    """The search's strokes. A stroke's own check (a plan check of its moves: tens
    of ms) is asked only of a stroke the search would take, once: most of the grid
    never improves the objective, and a set is checked whole before it is taken."""

    def __init__(self, strokes: list[float], feasible: Callable[[float], bool] | None):
        self.strokes = strokes
        self._feasible = feasible
        self._ok: dict[int, bool] = {}

    def ok(self, k: int) -> bool:
        if k not in self._ok:
            self._ok[k] = self._feasible is None or self._feasible(self.strokes[k])
        return self._ok[k]

    def feasible_seen(self) -> int:
        return len(self.strokes) if self._feasible is None else sum(self._ok.values())

    def sorted(self, idx: Sequence[int]) -> tuple[float, ...]:
        return tuple(sorted((self.strokes[k] for k in idx), reverse=True))

    def nearest(self, k: int, taken: Sequence[int]) -> int | None:
        """The feasible stroke nearest to index ``k`` that is not ``taken``."""
        for d in range(len(self.strokes)):
            for j in (k - d, k + d):
                if 0 <= j < len(self.strokes) and j not in taken and self.ok(j):
                    return j
        return None

    def starts(self, current: Sequence[float], n: int) -> list[list[int]]:
        """Starting sets of ``n`` strokes: ``current``'s feasible ones completed from
        the spread, and ``n`` spread evenly (each moved to the nearest feasible)."""
        spread: list[int] = []
        for k in np.linspace(0, len(self.strokes) - 1, n).round():
            j = self.nearest(int(k), spread)
            if j is not None:
                spread.append(j)
        mine = [k for k in (self.strokes.index(s) for s in current if s in self.strokes)
                if self.ok(k)][:n]
        mine += [k for k in spread if k not in mine][: n - len(mine)]
        return [s for s in (mine, spread) if len(set(s)) == n]


def _exchange(idx: list[int], grid: _Grid, objective: Callable[[Sequence[int]], float],
              allowed: Callable[[Sequence[int]], bool]) -> list[int]:
    """Coordinate exchange from ``idx``: replace one stroke at a time by one that
    improves the objective and is allowed, until none does."""
    # An infeasible start counts as worst: its first feasible exchange is taken.
    best = objective(idx) if allowed(idx) else float("-inf")
    improved = True
    while improved:
        improved = False
        for pos in range(len(idx)):
            for cand in range(len(grid.strokes)):
                if cand in idx:
                    continue
                trial = [*idx[:pos], cand, *idx[pos + 1:]]
                value = objective(trial)
                if value > best + 1e-12 and grid.ok(cand) and allowed(trial):
                    idx, best, improved = trial, value, True
    return idx


def drho_error_parts(keys: Sequence[Key], geometry: Geometry, model: str, params,
                     deviation_se: float, stand_sd: float,
                     stands: Stands | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The standard error of Δρ̂ (x, y, z) from the rows ``keys`` (default: one
    mounting of their gauges), split into (the gauges' noise part, the stands'
    part), in mm.

    ``deviation_se``: the standard error of each row (a deviation's mean over
    the mounting's cycles, or one cycle's); ``stand_sd``: each stand's SD about
    L/2; ``stands``: which rows share a stand (orthocal.stands, its ``mounts``).
    The fit is the station's, generalised least squares with the stands as
    random effects, covariance (Jᵀ·V⁻¹·J)⁻¹ with V = se²·I + σ_M²·J_M·J_Mᵀ, linear
    at the machine ``params`` (12-vector: the stands' columns grow with the legs'
    slopes, docs/model.md, "Where the indicator plane is"). The noise part is
    se·(JᵀJ)^(-1/2) (the gains of :func:`quality`); more cycles in the mounting
    shrink it, only another mounting the stands' part."""
    from orthocal.identification import exact_jacobian

    keys = list(keys)
    J = exact_jacobian(keys, geometry, params, model, [0.0] * len(keys))
    _, S = incidence(keys, stands or Stands())
    J_m = stand_jacobian(keys, geometry, params, S)
    drho = [k for k, n in enumerate(FIT_NAMES[c] for c in MODELS[model])
            if n.startswith("drho")]
    noise = deviation_se * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))[drho]
    V = deviation_se**2 * np.eye(len(keys)) + stand_sd**2 * (J_m @ J_m.T)
    total = np.sqrt(np.diag(np.linalg.inv(J.T @ np.linalg.solve(V, J))))[drho]
    return noise, np.sqrt(np.maximum(total**2 - noise**2, 0.0))


#: Where a second gauge plane may stand on each leg, as the fraction of the leg
#: from its joint end at Π0 (the middle is 1/2): docs/model.md, "Leg form against
#: tilts and gaps".
SECOND_PLANES: tuple[float, ...] = (0.25, 0.75)


def form_separation(keys: Sequence[Key], geometry: Geometry, model: str = "rho+tilt",
                    second: Sequence[float] = SECOND_PLANES) -> dict[str, float]:
    """How well ``model`` and one bow per leg (a uniform form of its surface, the
    sagitta h of w = 4h·t(1 − t)) are told apart: the condition number of their
    joint Jacobian at the nominal machine, with the gauges of ``keys`` in the legs'
    middles alone (key "middle"; inf where a uniform bow is exactly a tilt, as it
    is with any strokes), and with the same gauges in a second plane at each
    fraction of ``second`` from the joint end (keys "0.25", …)."""
    from orthocal.budget import form_vector
    from orthocal.identification import exact_jacobian

    params = np.zeros(len(PARAM_NAMES))
    out: dict[str, float] = {}
    for mu in (None, *second):
        rows = list(keys) + ([] if mu is None else list(keys))
        offsets = [0.0] * len(keys) + ([] if mu is None else
                                       [plane_at(mu, geometry)] * len(keys))
        J = exact_jacobian(rows, geometry, params, model, offsets)
        g = form_vector(rows, geometry, params, offsets)
        bows = np.column_stack([np.where([k[1] == leg for k in rows], g, 0.0) for leg in "xyz"])
        s = np.linalg.svd(np.hstack([J, bows]), compute_uv=False)
        # a uniform bow is exactly a tilt with the middles alone: s[-1] is rounding
        cond = float(s[0] / s[-1]) if s[-1] > 1e-6 * s[0] else float("inf")
        out["middle" if mu is None else f"{mu:g}"] = cond
    return out


def bow_tilts(keys: Sequence[Key], geometry: Geometry,
              straightness: Mapping[tuple[str, str], float]) -> np.ndarray:
    """The largest tilts (mrad, TILT_NAMES order) a ``rho+tilt+gap`` fit of the
    deviations ``keys`` takes from the legs bowed within ``straightness`` (sagitta
    bound per gauge plane (leg, direction), mm; a plane not named is straight), at
    the nominal machine: Σ_p |[J⁺·g_p]_tilt|·h_p, g_p the form vector (budget.
    form_vector) on plane p's rows. At the legs' middles a uniform bow is a tilt
    (docs/model.md, "Tilts or bows"): tilts beyond this are the axes', whatever
    the legs within their stated form do."""
    from orthocal.budget import form_vector
    from orthocal.geometry import TILT_NAMES
    from orthocal.identification import exact_jacobian

    distinct = list(dict.fromkeys(keys))
    params = np.zeros(len(PARAM_NAMES))
    model = "rho+tilt+gap"
    J = exact_jacobian(distinct, geometry, params, model)
    g = form_vector(distinct, geometry, params)
    gain = np.linalg.pinv(J)[[list(MODELS[model]).index(FIT_NAMES.index(n))
                              for n in TILT_NAMES]]
    out = np.zeros(len(TILT_NAMES))
    for plane, h in straightness.items():
        rows = np.array([(k[1], k[2]) == tuple(plane) for k in distinct])
        if h > 0 and rows.any():
            out += np.abs(gain @ np.where(rows, g, 0.0)) * float(h)
    return out
