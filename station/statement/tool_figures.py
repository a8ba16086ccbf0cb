"""The tool's error over the workspace as the run states it (docs/model.md, "Accuracy at
the tool" and "The statement's uncertainty"): before the calibration, after it with the
offsets written, and with the identified geometry in the controller, each figure's
RMS and max of |E| with one 95 % interval, propagated by Monte Carlo over the
machine's joint distribution (GUM Supplement 1, orthocal.field_mc: the fits' scatter
and every stated input within its bound, the plug-in's bias near a zero field
inverted). What the geometry in the controller gains over the offsets alone is
judged over the same drawn machines (orthocal.uncertainty.Uncertainty.draws), draw
by draw."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthocal import PARAM_NAMES
from orthocal.accuracy import ErrorField, error_field
from orthocal.compensation import compensated_field, compensated_interval, truth_jacobian
from orthocal.field_mc import Bounded
from orthocal.tool_interval import after_interval, field_jacobian
from orthocal.uncertainty import Uncertainty
from station.analysis.accuracy_statement import LAYOUT_NAMES
from station.analysis.compensated import told_names
from station.statement.known_machine import DRHO, KnownMachine
from station.statement.snapshot import Rounds

#: Draws of the machine (seeded: a run's statement is repeatable).
DRAWS = 4000
SEED = 20261207


@dataclass(frozen=True, eq=False)
class Figure:
    """One bounded figure (mm): its value and its 95 % interval (orthocal.field_mc), and
    where a decision is made draw by draw, the paired draws it is made on."""

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


def _bounded(joint: Uncertainty) -> list[Bounded]:
    """The joint distribution's Type B inputs as the Monte Carlo takes them: one column
    per physical input (orthocal.uncertainty.Uncertainty.merged), each uniform in ±1."""
    cols, _ = joint.merged()
    if not cols.shape[1]:
        return []
    return [Bounded(cols, np.ones(cols.shape[1]), names=tuple(joint.names))]


def _type_a(joint: Uncertainty) -> tuple[np.ndarray, float | None]:
    """The Type A part as one covariance, and the least dof of its blocks (the Monte
    Carlo draws one χ² per draw: the fit with the fewest dof widens all alike, which is
    the cautious side)."""
    dofs = [b.dof for b in joint.blocks if b.dof is not None]
    return joint.type_a_covariance(), (min(dofs) if dofs else None)


def _paired_gain(rounds: Rounds, machine: KnownMachine, joint: Uncertainty,
                 told: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """The RMS after the offsets and with the geometry in the controller over the same
    drawn machines (the field linearised at the estimate): what the controller gains,
    judged draw by draw (station.statement.decisions.gain)."""
    cfg = rounds.config
    geometry, frame, points = cfg.machine.geometry(), cfg.writeback.frame, rounds.points
    n = len(points)
    cols = _columns(joint)
    deltas = joint.draws(DRAWS, np.random.default_rng(SEED))[:, cols] if cols else \
        np.zeros((DRAWS, 0))
    theta = machine.params("now")
    fld = error_field(points, geometry, theta, np.zeros(3), frame)
    G = field_jacobian(points, geometry, theta, np.zeros(3), frame, cols) if cols else \
        np.zeros((3 * n, 0))
    after, _, _ = _stats(fld.field.ravel(), G, deltas, n)
    theta_c = np.array([v if p in told else 0.0
                        for p, v in zip(PARAM_NAMES, theta, strict=True)])
    comp = compensated_field(points, geometry, theta, theta_c, frame)
    G_c = truth_jacobian(points, geometry, theta, theta_c, frame, cols) if cols else \
        np.zeros((3 * n, 0))
    controller, _, _ = _stats(comp.field.ravel(), G_c, deltas, n)
    return after, controller


def _fig(value: float, interval: tuple[float, float], draws: np.ndarray) -> Figure:
    return Figure(float(value), (float(interval[0]), float(interval[1])), draws)


def tool_figures(rounds: Rounds, machine: KnownMachine) -> ToolFigures:
    """The three fields with their figures (module docstring): each by
    orthocal.tool_interval.after_interval / orthocal.compensation.compensated_interval
    over the machine's joint distribution (Type A as the fits state it, every Type B
    input uniform within its bound: docs/model.md, "Intervals at the tool"), Δρ now
    the truth's where nothing was measured after the last write (it is then an aim)."""
    cfg = rounds.config
    geometry, frame, points = cfg.machine.geometry(), cfg.writeback.frame, rounds.points
    zero = np.zeros(3)
    joint = machine.joint()
    cov, dof = _type_a(joint)
    bounded = _bounded(joint)
    out: dict[str, FieldFigures] = {}
    for name, which in (("before", "start"), ("after", "now")):
        aim = () if machine.measured_now or name == "before" else DRHO
        iv = after_interval(machine.params(which), cov, dof, zero, points, geometry, frame,
                            draws=DRAWS, seed=SEED, bounded=bounded, in_truth=aim)
        out[name] = FieldFigures(iv.field, _fig(iv.rms_mm, iv.rms_interval_mm, np.empty(0)),
                                 _fig(iv.max_mm, iv.max_interval_mm, np.empty(0)))
    told = told_names(rounds.layout, rounds.last.names)
    estimate = machine.params("now")
    theta_c = np.array([v if p in told else 0.0
                        for p, v in zip(PARAM_NAMES, estimate, strict=True)])
    absent = [p not in told and p in LAYOUT_NAMES for p in PARAM_NAMES]
    comp = compensated_interval(theta_c, estimate, cov, dof, points, geometry, frame,
                                draws=DRAWS, seed=SEED, absent=absent, bounded=bounded)
    after_draws, comp_draws = _paired_gain(rounds, machine, joint, told)
    out["compensated"] = FieldFigures(
        comp.field, _fig(comp.rms_mm, comp.rms_interval_mm, comp_draws),
        _fig(comp.max_mm, comp.max_interval_mm, np.empty(0)))
    out["after"] = FieldFigures(out["after"].field,
                                _fig(out["after"].rms.value, out["after"].rms.interval,
                                     after_draws), out["after"].max)
    return ToolFigures(before=out["before"], after=out["after"],
                       compensated=out["compensated"], told=told,
                       point_rms_mm=np.asarray(comp.point_rms_mm),
                       method=(f"Monte Carlo over the machine's joint distribution (GUM "
                               f"Supplement 1, {DRAWS} seeded draws: the fits' scatter as "
                               "Student's t, each stated input uniform within its bound), "
                               "the field linearised at the estimate, the plug-in's bias "
                               "near a zero field inverted (docs/model.md, \"Intervals at "
                               "the tool\")"))
