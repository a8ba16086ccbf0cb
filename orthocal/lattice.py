"""The candidates of ``auto`` as a lattice (orthocal.selection): their levels by
size, the test of one candidate (:class:`ModelTest`), which passing candidate
fits best, and what the choice's reason says beyond the test."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from orthocal.geometry import MODELS


@dataclass(frozen=True)
class ModelTest:
    """The lack-of-fit test of one candidate (``F`` None when it was not tested)."""

    model: str
    identifiable: bool
    F: float | None = None
    dof_model: int | None = None
    dof_noise: float | None = None
    p_value: float | None = None
    passed: bool = False
    residual_rms: float | None = None
    note: str = ""
    #: With the stands modelled: the test against the next candidate (``against``),
    #: F of the drop of the residual when its parameters join, on
    #: (``dof_next``, ``dof_noise``) dof, and its p-value (:func:`nested_test`).
    against: str | None = None
    F_next: float | None = None
    dof_next: int | None = None
    p_next: float | None = None
    #: With an allowance (orthocal.misfit): what the stated errors took of the misfit.
    allowance: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        out = {"model": self.model, "identifiable": self.identifiable, "F": self.F,
               "dof": [self.dof_model, self.dof_noise] if self.F is not None else None,
               "p_value": self.p_value, "passed": self.passed,
               "residual_rms_mm": self.residual_rms, "note": self.note or None}
        if self.allowance is not None:
            out["allowance"] = self.allowance
        if self.against is not None:
            out["against_next"] = {"model": self.against, "F": self.F_next,
                                   "dof": [self.dof_next, self.dof_noise],
                                   "p_value": self.p_next}
        return out



def lattice_levels(candidates: Sequence[str]) -> list[list[str]]:
    """The candidates grouped by their number of parameters, smallest first (the
    lattice's levels), each group in the order given."""
    sizes = sorted({len(MODELS[m]) for m in candidates})
    return [[m for m in candidates if len(MODELS[m]) == n] for n in sizes]


def fit_p(test: ModelTest) -> float:
    """How well a passing candidate fits: its smaller p-value (lack of fit, and
    against the next candidate where tested); inf where it could not be tested."""
    ps = [p for p in (test.p_value, test.p_next) if p is not None]
    return min(ps) if ps else math.inf


def best_passing(tests: Sequence[ModelTest]) -> ModelTest | None:
    """The passing candidate the data fit best (the first of equals)."""
    passing = [t for t in tests if t.passed]
    return max(passing, key=fit_p, default=None)


def excused_note(chosen: ModelTest, level: float) -> str:
    """A note when the chosen candidate passes only thanks to the stated form and
    gauge errors (its residual beyond the noise alone): what they may hide, and
    what would tell it apart (docs/model.md, "Leg form against tilts and gaps")."""
    took = chosen.allowance or {}
    p_free = took.get("p_without_allowance")
    if p_free is None or p_free >= level:
        return ""
    return (f"; {chosen.model} leaves more than the noise alone (p = {p_free:.1e}), within "
            "what the stated leg form and gauge errors can make: one gauge plane per leg "
            "cannot tell a uniform bow of the legs from tilts of the axes, so tilts that "
            "size are not claimed; a second gauge plane on each leg ([[setups]] at, e.g. "
            "0.75 of its length from the carriage's joint), or the legs' straightness "
            "measured and stated ([uncertainty] leg_straightness_mm), would tell them apart")


def also_passing(chosen: ModelTest, tests: Sequence[ModelTest]) -> str:
    """A note naming the other candidates of the chosen one's size that pass too."""
    others = [t for t in tests if t.passed and t.model != chosen.model]
    if not others:
        return ""
    return "; " + ", ".join(f"{t.model} passes too (p = {fit_p(t):.3f})" for t in others) + \
        f", {chosen.model} fits best"
