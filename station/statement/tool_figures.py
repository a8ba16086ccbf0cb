"""The tool's error over the workspace as the run states it (docs/model.md, "Accuracy at
the tool", "The statement's uncertainty" and "The tool with the joints' errors"):
before the calibration, after it with the offsets written, and with the identified
geometry in the controller (with the joint tables where the run has them), each
figure's RMS and max of |E| with one 95 % interval, propagated by Monte Carlo over the
machine's joint distribution (GUM Supplement 1, orthocal.field_mc: the fits' scatter
and every stated input within its bound, the joints' errors as each route leaves
them, the plug-in's bias near a zero field inverted). What the geometry in the
controller gains over the offsets alone is judged over the same drawn machines
(orthocal.uncertainty.Uncertainty.draws), draw by draw."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from orthocal import PARAM_NAMES
from orthocal import compensation as comp_
from orthocal import tool_interval as after_
from orthocal.accuracy import ErrorField, error_field
from orthocal.field_mc import Bounded
from orthocal.kinematics import inverse
from orthocal.uncertainty import Uncertainty
from station.analysis.accuracy_statement import LAYOUT_NAMES
from station.analysis.compensated import told_names
from station.statement.joints_at_tool import JointsAtTool
from station.statement.known_machine import DRHO, KnownMachine, offsets_moved
from station.statement.snapshot import Rounds

#: Draws of the machine (seeded: a run's statement is repeatable).
DRAWS = 4000
SEED = 20261207
#: What an interval at the tool gives (orthocal.tool_interval, orthocal.compensation).
_Interval = after_.AfterInterval | comp_.CompensatedInterval
#: The label of a joint's lead among the Type B inputs (orthocal.budget_columns).
LEAD = "joint lead:"


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
    (``compensated``, the controller told ``told``, by ``route``: a key of
    orthocal.joint_compensation.ROUTES, with the joint tables where the run has
    them); ``method`` in words; ``joints``: the joints as the figures take them;
    ``assumed_share``: per figure ("after", "compensated"), the share of its mean
    square the assumed joints' bounds make (their leads through the identification
    and at the tool)."""

    before: FieldFigures
    after: FieldFigures
    compensated: FieldFigures
    told: list[str]
    point_rms_mm: np.ndarray
    method: str
    route: str = "kinematics"
    joints: JointsAtTool | None = None
    assumed_share: dict[str, float] | None = None


def _stats(F0: np.ndarray, G: np.ndarray, deltas: np.ndarray, n: int,
           linked: np.ndarray | None = None, u: np.ndarray | None = None
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per draw, RMS and max of |E| of F0 − G·δ (+ the joints' ``linked`` field (3n × m)
    at each draw's inputs ``u`` (draws × m)); and each point's root mean square."""
    rms = np.empty(len(deltas))
    mx = np.empty(len(deltas))
    point = np.zeros(n)
    for lo in range(0, len(deltas), 500):  # the whole field per draw: in chunks
        f = F0 - deltas[lo:lo + 500] @ G.T
        if linked is not None and u is not None and linked.shape[1]:
            f = f + u[lo:lo + 500] @ linked.T
        d = f.reshape(-1, n, 3)
        norms2 = np.einsum("dnk,dnk->dn", d, d)
        rms[lo:lo + 500] = np.sqrt(norms2.mean(axis=1))
        mx[lo:lo + 500] = np.sqrt(norms2.max(axis=1))
        point += norms2.sum(axis=0)
    return rms, mx, np.sqrt(point / len(deltas))


def _columns(u: Uncertainty) -> list[int]:
    var = np.diag(u.covariance())
    return [c for c in range(len(PARAM_NAMES)) if var[c] > 0.0]


def _split(joint: Uncertainty) -> tuple[Uncertainty, dict[str, np.ndarray]]:
    """The joint distribution without the joints' leads, and each joint's lead column
    over the parameters (by axis): the leads are drawn with the joints' errors at the
    tool, one input each (:func:`_linked`)."""
    keep = [i for i, lab in enumerate(joint.labels) if not lab.startswith(LEAD)]
    rest = Uncertainty(joint.names, joint.blocks, joint.columns[:, keep],
                       tuple(joint.labels[i] for i in keep),
                       tuple(joint.sources[i] for i in keep))
    leads: dict[str, np.ndarray] = {}
    for col, lab in zip(joint.columns.T, joint.labels, strict=True):
        if lab.startswith(LEAD):
            axis = lab[len(LEAD):]
            leads[axis] = leads.get(axis, np.zeros(len(joint.names))) + col
    return rest, leads


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


@dataclass(frozen=True, eq=False)
class _Linear:
    """One field linearised at the estimate: its plug-in ``F0`` (3n), its Jacobian ``G``
    over the parameters an input moves, and each joint's input in the truth,
    ``linked`` (3n × m, in ``axes``' order): what its lead does through the
    identification (−G·c) and its error at the tool, drawn as one input."""

    F0: np.ndarray
    G: np.ndarray
    linked: np.ndarray
    axes: tuple[str, ...]

    def share(self, of: Sequence[str], value_mm: float) -> float:
        """The share of a figure's mean square (``value_mm`` squared) the joints ``of``
        make: their inputs' mean square over the points, each a third of its square."""
        keep = [i for i, a in enumerate(self.axes) if a in of]
        n = len(self.F0) // 3
        ms = float(np.sum(self.linked[:, keep] ** 2) / n / 3.0)
        total = max(value_mm**2, ms)
        return 0.0 if total <= 0.0 else ms / total


def _linear(rounds: Rounds, theta: np.ndarray, theta_c: np.ndarray | None, cols: list[int],
            joints: JointsAtTool, route: str, which: str, leads: dict[str, np.ndarray]
            ) -> _Linear:
    """The field after the offsets (``theta_c`` None) or with the controller told
    ``theta_c``, by ``route``, linearised at the estimate ``theta`` of the machine
    ``which`` ("start", "now"); the joints' ``leads`` (parameter columns by axis)
    linked with their errors at the tool."""
    cfg = rounds.config
    geometry, frame, points = cfg.machine.geometry(), cfg.writeback.frame, rounds.points
    n, zero = len(points), np.zeros(3)
    tables = joints.plug_in(which, route)
    if theta_c is None:
        F0 = error_field(points, geometry, theta, zero, frame, joint_errors=tables).field
        G = after_.field_jacobian(points, geometry, theta, zero, frame, cols, tables) \
            if cols else np.zeros((3 * n, 0))
        J = after_.joint_jacobian(points, geometry, theta, zero, tables)
        rho = inverse(points, geometry)
    else:
        F0 = comp_.compensated_field(points, geometry, theta, theta_c, frame, tables).field
        G = comp_.truth_jacobian(points, geometry, theta, theta_c, frame, cols, tables) \
            if cols else np.zeros((3 * n, 0))
        J = comp_.joint_jacobian(points, geometry, theta, theta_c, tables)
        rho = comp_.controller_joints(points, geometry, theta_c)
    at_tool = joints.framed(rho, which, J, points, frame)
    axes = tuple(a for a in "xyz" if a in leads or a in at_tool)
    linked = np.zeros((3 * n, len(axes)))
    for k, a in enumerate(axes):
        if a in leads and cols:
            linked[:, k] -= G @ leads[a][cols]  # the truth is the plug-in less G·δ
        if a in at_tool:
            linked[:, k] += at_tool[a]
    return _Linear(F0.ravel(), G, linked, axes)


def _draws(linear: _Linear) -> list[Bounded] | None:
    """The joints' linked inputs as the truth's field errors (orthocal.field_mc: each
    uniform in ±1; already in the frame, which leaves them as they are)."""
    m = linear.linked.shape[1]
    return [Bounded(linear.linked, np.ones(m))] if m else None


def _paired_gain(rounds: Rounds, rest: Uncertainty, cols: list[int],
                 fields: tuple[_Linear, _Linear]) -> tuple[np.ndarray, np.ndarray]:
    """The RMS after the offsets and with the geometry in the controller over the same
    drawn machines, the joints' inputs drawn once for both (``fields``: the two
    linearised): what the controller gains, judged draw by draw
    (station.statement.decisions.gain)."""
    n = len(rounds.points)
    deltas = rest.draws(DRAWS, np.random.default_rng(SEED))[:, cols] if cols else \
        np.zeros((DRAWS, 0))
    u = np.random.default_rng(SEED + 1).uniform(-1.0, 1.0, (DRAWS, len(fields[0].axes)))
    assert fields[0].axes == fields[1].axes
    after, _, _ = _stats(fields[0].F0, fields[0].G, deltas, n, fields[0].linked, u)
    controller, _, _ = _stats(fields[1].F0, fields[1].G, deltas, n, fields[1].linked, u)
    return after, controller


def _exact(linear: _Linear, assumed: Sequence[str]) -> _Linear:
    """``linear`` with the joints ``assumed`` exact: their inputs left out."""
    keep = [i for i, a in enumerate(linear.axes) if a not in assumed]
    return _Linear(linear.F0, linear.G, linear.linked[:, keep],
                   tuple(linear.axes[i] for i in keep))


def _envelope(iv: _Interval, again: Callable[[_Linear], _Interval], linear: _Linear,
              assumed: Sequence[str]
              ) -> tuple[tuple[float, float], tuple[float, float]]:
    """The RMS and max intervals of ``iv``, widened to hold the same figure with the
    ``assumed`` joints exact (``again``: the interval of another linearised field). An
    assumed bound is what the joints may be, not how they are spread: screws that
    happen to be right (a square machine, ground screws) lie inside it, and a uniform
    draw of three leads almost never puts all three near zero, so the drawn interval
    alone would leave that machine out (docs/model.md, "The tool with the joints'
    errors")."""
    if not assumed:
        return iv.rms_interval_mm, iv.max_interval_mm
    ex = again(_exact(linear, assumed))
    return ((min(iv.rms_interval_mm[0], ex.rms_interval_mm[0]),
             max(iv.rms_interval_mm[1], ex.rms_interval_mm[1])),
            (min(iv.max_interval_mm[0], ex.max_interval_mm[0]),
             max(iv.max_interval_mm[1], ex.max_interval_mm[1])))


def _fig(value: float, interval: tuple[float, float], draws: np.ndarray) -> Figure:
    return Figure(float(value), (float(interval[0]), float(interval[1])), draws)


def tool_figures(rounds: Rounds, machine: KnownMachine) -> ToolFigures:
    """The three fields with their figures (module docstring): each by
    orthocal.tool_interval.after_interval / orthocal.compensation.compensated_interval
    over the machine's joint distribution (Type A as the fits state it, every Type B
    input uniform within its bound: docs/model.md, "Intervals at the tool"), Δρ now
    the truth's where nothing was measured after the last write (it is then an aim);
    the joints' errors as each route leaves them, each joint's lead one input with
    what it does through the identification (station.statement.joints_at_tool)."""
    cfg = rounds.config
    geometry, frame, points = cfg.machine.geometry(), cfg.writeback.frame, rounds.points
    zero = np.zeros(3)
    joint = machine.joint()
    rest, leads = _split(joint)
    cov, dof = _type_a(rest)
    bounded = _bounded(rest)
    cols = _columns(joint)
    joints = JointsAtTool(rounds.joints, offsets_moved(rounds))
    out: dict[str, FieldFigures] = {}
    fields: dict[str, _Linear] = {}
    for name, which in (("before", "start"), ("after", "now")):
        aim = () if machine.measured_now or name == "before" else DRHO
        fields[name] = _linear(rounds, machine.params(which), None, cols, joints, "offsets",
                               which, leads)
        def after(linear: _Linear, which: str = which, aim: tuple = aim
                  ) -> after_.AfterInterval:
            return after_.after_interval(
                machine.params(which), cov, dof, zero, points, geometry, frame,
                draws=DRAWS, seed=SEED, bounded=bounded, in_truth=aim,
                field_draws=_draws(linear), joint_errors=joints.plug_in(which, "offsets"))
        iv = after(fields[name])
        rms, mx = _envelope(iv, after, fields[name], joints.assumed)
        out[name] = FieldFigures(iv.field, _fig(iv.rms_mm, rms, np.empty(0)),
                                 _fig(iv.max_mm, mx, np.empty(0)))
    told = told_names(rounds.layout, rounds.last.names)
    estimate = machine.params("now")
    theta_c = np.array([v if p in told else 0.0
                        for p, v in zip(PARAM_NAMES, estimate, strict=True)])
    absent = [p not in told and p in LAYOUT_NAMES for p in PARAM_NAMES]
    route = joints.compensated_route()
    fields["compensated"] = _linear(rounds, estimate, theta_c, cols, joints, route, "now",
                                    leads)
    def compensated(linear: _Linear) -> comp_.CompensatedInterval:
        return comp_.compensated_interval(
            theta_c, estimate, cov, dof, points, geometry, frame, draws=DRAWS, seed=SEED,
            absent=absent, bounded=bounded, joint_errors=joints.plug_in("now", route),
            field_draws=_draws(linear))
    comp = compensated(fields["compensated"])
    comp_rms, comp_max = _envelope(comp, compensated, fields["compensated"],
                                   joints.assumed)
    after_draws, comp_draws = _paired_gain(rounds, rest, cols,
                                           (fields["after"], fields["compensated"]))
    out["compensated"] = FieldFigures(
        comp.field, _fig(comp.rms_mm, comp_rms, comp_draws),
        _fig(comp.max_mm, comp_max, np.empty(0)))
    out["after"] = FieldFigures(out["after"].field,
                                _fig(out["after"].rms.value, out["after"].rms.interval,
                                     after_draws), out["after"].max)
    share = {name: fields[name].share(joints.assumed, out[name].rms.value)
             for name in ("after", "compensated")} if joints.assumed else None
    return ToolFigures(before=out["before"], after=out["after"],
                       compensated=out["compensated"], told=told,
                       point_rms_mm=np.asarray(comp.point_rms_mm),
                       method=(f"Monte Carlo over the machine's joint distribution (GUM "
                               f"Supplement 1, {DRAWS} seeded draws: the fits' scatter as "
                               "Student's t, each stated input uniform within its bound, "
                               "each joint's error as the route leaves it, drawn with "
                               "what its lead does through the identification), the field "
                               "linearised at the estimate, the plug-in's bias near a zero "
                               "field inverted (docs/model.md, \"Intervals at the tool\" "
                               "and \"The tool with the joints' errors\")"),
                       route=route, joints=joints, assumed_share=share)
