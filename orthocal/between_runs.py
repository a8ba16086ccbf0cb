"""The change of one quantity between two runs of one machine (docs/model.md, "The
change between two runs"): each run's value with its uncertainty as its statement
gives it (a Type A part on its degrees of freedom, each Type B source's standard
contribution, a bound added whole), combined as the GUM combines a difference of two
correlated estimates (JCGM 100:2008, 5.2): the Type A parts independent (each run's own
scatter), a Type B source of the machine's own common to both runs fully correlated
(r = 1, same sign: the same fit of the same postures sees it the same way, so the change
keeps what differs of it, |u_B − u_A|), any other source independent. Pure."""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field

from orthocal.noise import coverage_factor
from orthocal.uncertainty import welch

#: The name a statement gives its Type A part among its contributions.
TYPE_A = "repeatability"


@dataclass(frozen=True)
class Stated:
    """One run's value of a quantity with the parts of its uncertainty: ``u_a`` the
    Type A standard uncertainty on ``dof_a`` (None: infinite), ``type_b`` each Type B
    source's standard contribution, ``whole`` a bound its expanded uncertainty holds
    added whole (another explanation as good; 0 for none)."""

    value: float
    u_a: float
    dof_a: float | None
    type_b: Mapping[str, float] = field(default_factory=dict)
    whole: float = 0.0

    @property
    def u_c(self) -> float:
        return math.sqrt(self.u_a ** 2 + sum(u * u for u in self.type_b.values()))


def of_statement(value: float, expanded: float, k: float, dof: float | None,
                 contributions: Mapping[str, float]) -> Stated:
    """A statement's quantity (docs/design.md, "The statement of the machine") as its
    parts. Its dof is Welch–Satterthwaite's of the Type A part and the Type B at ∞ dof
    (model.md (14)), so the Type A part's own is ν_A = ν_eff·u_A⁴/u_c⁴; what its U holds
    beyond k·u_c was added whole."""
    u_a = float(contributions.get(TYPE_A, 0.0))
    type_b = {s: float(u) for s, u in contributions.items() if s != TYPE_A}
    u_c = math.sqrt(u_a ** 2 + sum(u * u for u in type_b.values()))
    dof_a = None if dof is None or u_c == 0.0 else dof * u_a ** 4 / u_c ** 4
    return Stated(value, u_a, dof_a, type_b, max(0.0, expanded - k * u_c))


@dataclass(frozen=True)
class Change:
    """B − A with its combined standard uncertainty, Welch–Satterthwaite's dof (None:
    infinite), k at 95 %, the expanded uncertainty U = k·u_c + the bounds added whole,
    and whether the change lies beyond U."""

    value: float
    u_c: float
    dof: float | None
    k: float
    expanded: float

    @property
    def significant(self) -> bool:
        return abs(self.value) > self.expanded


def change(a: Stated, b: Stated, common: Collection[str] = ()) -> Change:
    """The change from run ``a`` to run ``b`` (model.md (C1)): ``common`` the Type B
    sources the two runs share (one physical input), fully correlated; every other part
    independent."""
    ub2 = 0.0
    for source in set(a.type_b) | set(b.type_b):
        ua, ub = a.type_b.get(source, 0.0), b.type_b.get(source, 0.0)
        shared = source in common and source in a.type_b and source in b.type_b
        ub2 += (ub - ua) ** 2 if shared else ua * ua + ub * ub
    parts = [(a.u_a, math.inf if a.dof_a is None else a.dof_a),
             (b.u_a, math.inf if b.dof_a is None else b.dof_a), (math.sqrt(ub2), math.inf)]
    u_c = math.sqrt(a.u_a ** 2 + b.u_a ** 2 + ub2)
    dof = welch(parts)
    k = coverage_factor(dof, 0.95)
    return Change(b.value - a.value, u_c, dof, k, k * u_c + a.whole + b.whole)
