"""The tool's error over the workspace as the run states it (docs/model.md, "Accuracy at
the tool" and "The statement's uncertainty"): before the calibration, after it with the
offsets written, and with the identified geometry in the controller, each figure's
RMS and max of |E| with one 95 % interval, propagated by Monte Carlo over the
machine's joint distribution (GUM Supplement 1): each draw is a machine the data
allow (orthocal.uncertainty.Uncertainty.draws), carried through the field
linearised at the estimate. The same draws serve the three fields, so a difference
between two of them (what the geometry in the controller gains) is judged draw by
draw."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthocal import PARAM_NAMES
from orthocal.accuracy import ErrorField, error_field
from orthocal.compensation import compensated_field, truth_jacobian
from orthocal.tool_interval import field_jacobian
from orthocal.uncertainty import Uncertainty
from station.analysis.compensated import told_names
from station.statement.known_machine import KnownMachine
from station.statement.snapshot import Rounds

#: Draws of the machine (seeded: a run's statement is repeatable).
DRAWS = 4000
SEED = 20261207
#: The interval's tails (95 %, probabilistically symmetric: JCGM 101 5.3.3).
TAILS = (0.025, 0.975)


@dataclass(frozen=True, eq=False)
class Figure:
    """One bounded figure (mm): its value (the median over the draws), its 95 %
    interval, and the draws themselves (for decisions made draw by draw)."""

    value: float
    interval: tuple[float, float]
    draws: np.ndarray


@dataclass(frozen=True, eq=False)
class FieldFigures:
    """A field's plug-in (at the estimate) and its RMS and max figures."""

    field: ErrorField
    rms: Figure
    max: Figure


@dataclass(frozen=True, eq=False)
class ToolFigures:
    """Before, after (the offsets written) and with the geometry in the controller
    (``compensated``, the controller told ``told``); ``method`` in words."""

    before: FieldFigures
    after: FieldFigures
    compensated: FieldFigures
    told: list[str]
    point_rms_mm: np.ndarray
    method: str


def _figure(values: np.ndarray) -> Figure:
    lo, hi = np.quantile(values, TAILS)
    return Figure(float(np.median(values)), (float(lo), float(hi)), values)


def _stats(F0: np.ndarray, G: np.ndarray, deltas: np.ndarray, n: int
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per draw, RMS and max of |E| of F0 − G·δ; and each point's root mean square."""
    rms = np.empty(len(deltas))
    mx = np.empty(len(deltas))
    point = np.zeros(n)
    for lo in range(0, len(deltas), 500):  # the whole field per draw: in chunks
        d = (F0 - deltas[lo:lo + 500] @ G.T).reshape(-1, n, 3)
        norms2 = np.einsum("dnk,dnk->dn", d, d)
        rms[lo:lo + 500] = np.sqrt(norms2.mean(axis=1))
        mx[lo:lo + 500] = np.sqrt(norms2.max(axis=1))
        point += norms2.sum(axis=0)
    return rms, mx, np.sqrt(point / len(deltas))


def _columns(u: Uncertainty) -> list[int]:
    var = np.diag(u.covariance())
    return [c for c in range(len(PARAM_NAMES)) if var[c] > 0.0]


def tool_figures(rounds: Rounds, machine: KnownMachine) -> ToolFigures:
    """The three fields with their figures (module docstring)."""
    cfg = rounds.config
    geometry, frame, points = cfg.machine.geometry(), cfg.writeback.frame, rounds.points
    n = len(points)
    zero = np.zeros(3)
    joint = machine.joint()
    cols = _columns(joint)
    rng = np.random.default_rng(SEED)
    deltas = joint.draws(DRAWS, rng)[:, cols] if cols else np.zeros((DRAWS, 0))
    out: dict[str, FieldFigures] = {}
    for name, which in (("before", "start"), ("after", "now")):
        theta = machine.params(which)
        fld = error_field(points, geometry, theta, zero, frame)
        G = field_jacobian(points, geometry, theta, zero, frame, cols) if cols else \
            np.zeros((3 * n, 0))
        rms, mx, _ = _stats(fld.field.ravel(), G, deltas, n)
        out[name] = FieldFigures(fld, _figure(rms), _figure(mx))
    told = told_names(rounds.layout, rounds.last.names)
    estimate = machine.params("now")
    theta_c = np.array([v if p in told else 0.0
                        for p, v in zip(PARAM_NAMES, estimate, strict=True)])
    comp = compensated_field(points, geometry, estimate, theta_c, frame)
    G_c = truth_jacobian(points, geometry, estimate, theta_c, frame, cols) if cols else \
        np.zeros((3 * n, 0))
    rms, mx, point = _stats(comp.field.ravel(), G_c, deltas, n)
    out["compensated"] = FieldFigures(comp, _figure(rms), _figure(mx))
    return ToolFigures(before=out["before"], after=out["after"],
                       compensated=out["compensated"], told=told, point_rms_mm=point,
                       method=(f"Monte Carlo over the machine's joint distribution (GUM "
                               f"Supplement 1, {DRAWS} seeded draws: each fit's scatter as "
                               "Student's t, each Type B input uniform within its bound), "
                               "the field linearised at the estimate; value the median, "
                               "95 % interval from the 2.5 % to the 97.5 % quantile"))
