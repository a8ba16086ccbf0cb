"""The uncertainty of what a run states (docs/model.md, "The statement's uncertainty";
GUM, JCGM 100:2008, and its Supplement 1, JCGM 101:2008).

Every quantity the station states is a function of the machine's parameters θ
(PARAM_NAMES), and what the run knows of θ is one joint distribution of its error
δ = θ̂ − θ, in two kinds of parts:

- Type A (the scatter): blocks of parameters, each with a covariance resting on ν
  degrees of freedom (Student's t; ∞: normal). Blocks come from different fits and
  their Type A errors are independent (a block per fit).
- Type B (bounded systematic inputs: the legs' form, a gauge's MPE, a temperature
  step …): each input uniform in ±1, acting on θ through its column, δ_B = C·u,
  u ~ U(−1, 1)^m. Two columns of one *label* are one physical input (the legs' bow
  seen through two fits), so the statement keeps their correlation.

A scalar quantity's standard uncertainty is the GUM's quadrature (5.1.2, 5.2.2): u_c² =
u_A² + Σ_cols (c²/3), its dof Welch–Satterthwaite's (G.4.1, Type B at ∞) and its
expanded uncertainty U = k·u_c, k from Student's t at 95 % (G.3). A vector quantity
(the tool's field) takes :meth:`Uncertainty.draws` (Supplement 1: the parameters' joint
distribution drawn, each draw carried through the exact function).

Pure, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from orthocal.noise import coverage_factor

#: The coverage probability of every stated interval.
COVERAGE = 0.95
#: A uniform input on [−1, 1] has variance 1/3.
UNIFORM_VAR = 1.0 / 3.0


@dataclass(frozen=True)
class Block:
    """A Type A block: the parameters at ``index`` (into the names), their
    ``covariance`` and its ``dof`` (None: infinite)."""

    index: tuple[int, ...]
    covariance: np.ndarray
    dof: float | None


@dataclass(frozen=True)
class Marginal:
    """One scalar's uncertainty: ``u_a`` (Type A, on ``dof_a``), ``u_b`` (Type B),
    ``u_c`` combined, ``dof`` Welch–Satterthwaite's (None: ∞), ``k`` and
    ``expanded`` = k·u_c at 95 %, and each source's standard contribution
    (``contributions``; the Type A part as ``type_a_name``)."""

    u_a: float
    dof_a: float | None
    u_b: float
    u_c: float
    dof: float | None
    k: float
    expanded: float
    contributions: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Uncertainty:
    """The joint distribution of the error of the estimates of ``names`` (module
    docstring): Type A ``blocks``, Type B ``columns`` (n × m) with each column's
    ``labels`` (the physical input) and ``sources`` (the budget's name of it)."""

    names: tuple[str, ...]
    blocks: tuple[Block, ...]
    columns: np.ndarray
    labels: tuple[str, ...]
    sources: tuple[str, ...]

    @staticmethod
    def empty(names: Sequence[str]) -> Uncertainty:
        """No error at all (every value known exactly)."""
        return Uncertainty(tuple(names), (), np.zeros((len(names), 0)), (), ())

    # --- parts -------------------------------------------------------------------------

    def type_a_covariance(self) -> np.ndarray:
        n = len(self.names)
        out = np.zeros((n, n))
        for b in self.blocks:
            out[np.ix_(b.index, b.index)] += b.covariance
        return out

    def merged(self) -> tuple[np.ndarray, tuple[str, ...]]:
        """The Type B columns one per physical input (columns of one label summed: one
        input), with each input's source."""
        distinct = list(dict.fromkeys(self.labels))
        out = np.zeros((len(self.names), len(distinct)))
        sources = [""] * len(distinct)
        for col, lab, src in zip(self.columns.T, self.labels, self.sources, strict=True):
            j = distinct.index(lab)
            out[:, j] += col
            sources[j] = src
        return out, tuple(sources)

    def type_b_covariance(self) -> np.ndarray:
        cols, _ = self.merged()
        return UNIFORM_VAR * cols @ cols.T

    def covariance(self) -> np.ndarray:
        """Type A and Type B together (the GUM's covariance of the estimates)."""
        return self.type_a_covariance() + self.type_b_covariance()

    def source_names(self) -> list[str]:
        """What the distribution holds, in words: the Type A part (where any) and each
        Type B source once."""
        typed = ["repeatability (Type A)"] if self.blocks else []
        return typed + list(dict.fromkeys(self.sources))

    # --- one quantity --------------------------------------------------------------------

    def marginal(self, name: str, type_a_name: str = "repeatability") -> Marginal:
        """The GUM combination for parameter ``name`` (:func:`combine_linear` of its
        unit row)."""
        row = np.zeros(len(self.names))
        row[self.names.index(name)] = 1.0
        return self.linear_marginal(row, type_a_name)

    def linear_marginal(self, row: Sequence[float] | np.ndarray,
                        type_a_name: str = "repeatability") -> Marginal:
        """The uncertainty of the linear function ``row``·θ: Type A through each
        block (their dof joined by Welch–Satterthwaite), Type B through the columns,
        each source's part reported by its name."""
        r = np.asarray(row, dtype=float)
        parts: list[tuple[float, float]] = []
        ua2 = 0.0
        for b in self.blocks:
            rb = r[list(b.index)]
            var = float(rb @ b.covariance @ rb)
            if var > 0.0:
                ua2 += var
                parts.append((math.sqrt(var), math.inf if b.dof is None else float(b.dof)))
        contrib: dict[str, float] = {}
        if self.columns.size:
            cols, sources = self.merged()
            for src, e in zip(sources, r @ cols, strict=True):
                contrib[src] = contrib.get(src, 0.0) + UNIFORM_VAR * float(e) ** 2
        ub2 = sum(contrib.values())
        u_a, u_b = math.sqrt(ua2), math.sqrt(ub2)
        u_c = math.sqrt(ua2 + ub2)
        dof_a = welch(parts)
        dof = welch([*parts, (u_b, math.inf)])
        k = coverage_factor(dof, COVERAGE)
        out = {type_a_name: u_a} if ua2 > 0.0 else {}
        out.update({s: math.sqrt(v) for s, v in contrib.items() if v > 0.0})
        return Marginal(u_a=u_a, dof_a=dof_a, u_b=u_b, u_c=u_c, dof=dof, k=k,
                        expanded=k * u_c, contributions=out)

    # --- transforms ----------------------------------------------------------------------

    def pick(self, names: Sequence[str]) -> Uncertainty:
        """The same errors, of ``names`` only (each must be held)."""
        idx = [self.names.index(n) for n in names]
        where = {old: new for new, old in enumerate(idx)}
        blocks = []
        for b in self.blocks:
            keep = [i for i, old in enumerate(b.index) if old in where]
            if keep:
                blocks.append(Block(tuple(where[b.index[i]] for i in keep),
                                    b.covariance[np.ix_(keep, keep)], b.dof))
        return Uncertainty(tuple(names), tuple(blocks), self.columns[idx],
                           self.labels, self.sources)

    def embedded(self, names: Sequence[str]) -> Uncertainty:
        """The same errors over ``names`` (a superset in any order): names not held
        are known exactly (no error)."""
        where = [list(names).index(n) for n in self.names]
        cols = np.zeros((len(names), self.columns.shape[1]))
        cols[where] = self.columns
        blocks = tuple(Block(tuple(where[i] for i in b.index), b.covariance, b.dof)
                       for b in self.blocks)
        return Uncertainty(tuple(names), blocks, cols, self.labels, self.sources)

    def draws(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` draws of the error δ (n × len(names)), GUM Supplement 1: each Type A
        block multivariate Student t (a normal scaled by √(ν/χ²_ν) drawn once per
        block and draw), each Type B input uniform in ±1 (columns sharing a label
        draw one input)."""
        out = np.zeros((n, len(self.names)))
        for b in self.blocks:
            root = _root(b.covariance)
            z = rng.standard_normal((n, root.shape[1])) @ root.T
            if b.dof is not None and math.isfinite(b.dof):
                z /= np.sqrt(rng.chisquare(b.dof, size=(n, 1)) / b.dof)
            out[:, list(b.index)] += z
        if self.columns.size:
            cols, _ = self.merged()
            out += rng.uniform(-1.0, 1.0, size=(n, cols.shape[1])) @ cols.T
        return out


def welch(parts: Sequence[tuple[float, float]]) -> float | None:
    """Welch–Satterthwaite's ν_eff of (u_i, ν_i) (GUM G.4.1), None for infinite."""
    uc2 = sum(u * u for u, _ in parts)
    denom = sum(u**4 / nu for u, nu in parts if math.isfinite(nu) and u > 0.0)
    if denom == 0.0 or uc2 == 0.0:
        return None
    return uc2**2 / denom


def _root(cov: np.ndarray) -> np.ndarray:
    """R with R·Rᵀ = cov for a symmetric positive semi-definite cov."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    return v * np.sqrt(np.clip(w, 0.0, None))


def combined(parts: Sequence[Uncertainty], names: Sequence[str]) -> Uncertainty:
    """The joint distribution of ``parts`` over ``names``: every part's blocks, and
    their columns side by side (a column keeps its label, so one physical input
    seen by two parts stays one input)."""
    out_blocks: list[Block] = []
    cols: list[np.ndarray] = []
    labels: list[str] = []
    sources: list[str] = []
    for p in parts:
        e = p.embedded(names)
        out_blocks += e.blocks
        cols.append(e.columns)
        labels += e.labels
        sources += e.sources
    columns = np.hstack(cols) if cols else np.zeros((len(names), 0))
    return Uncertainty(tuple(names), tuple(out_blocks), columns, tuple(labels),
                       tuple(sources))


def type_a(names: Sequence[str], covariance: np.ndarray, dof: float | None) -> Uncertainty:
    """A Type A part alone: one block of ``names``."""
    cov = np.asarray(covariance, dtype=float)
    block = Block(tuple(range(len(names))), cov, None if dof is None or
                  not math.isfinite(dof) else float(dof))
    return Uncertainty(tuple(names), (block,), np.zeros((len(names), 0)), (), ())


def type_b(names: Sequence[str], columns: np.ndarray, labels: Sequence[str],
           sources: Sequence[str]) -> Uncertainty:
    """A Type B part alone: ``columns`` (len(names) × m) of inputs uniform in ±1."""
    cols = np.asarray(columns, dtype=float).reshape(len(names), -1)
    if cols.shape[1] != len(labels) or len(labels) != len(sources):
        raise ValueError("one label and one source per column")
    return Uncertainty(tuple(names), (), cols, tuple(labels), tuple(sources))


def interval(value: float, marginal: Marginal) -> tuple[float, float]:
    """The symmetric 95 % interval value ± U of a linear quantity."""
    return value - marginal.expanded, value + marginal.expanded


def values_of(values: Mapping[str, float], names: Sequence[str]) -> np.ndarray:
    """The values of ``names`` as a vector (a name not given: 0)."""
    return np.array([float(values.get(n, 0.0)) for n in names])
