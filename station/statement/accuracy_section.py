"""result.json's ``accuracy`` (docs/design.md, "Accuracy at the tool") and model.json,
filled from the statement's own figures (station.statement.tool_figures and quantities): the
same numbers, computed once, so that the section and the statement never differ."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from orthocal import AXES, GAP_NAMES, TILT_NAMES
from orthocal.accuracy import error_field
from orthocal.joint_compensation import count_at_tool
from orthocal.joint_count import count_words
from orthocal.numbers import finite
from orthocal.tool_interval import assumes
from station.analysis import accuracy_statement as acc_
from station.analysis import run_budget
from station.analysis.compensated import ROUTES_IN_FULL, grouped, nominal_reasons
from station.record import result_accuracy as rec
from station.record.model import MachineModel
from station.record.result_statement import Quantity
from station.statement import decisions as rule
from station.statement.joints_at_tool import route_words
from station.statement.known_machine import DRHO, KnownMachine
from station.statement.quantities import PAIRS
from station.statement.snapshot import Rounds
from station.statement.tool_figures import FieldFigures, ToolFigures


def _after(fig: FieldFigures) -> rec.AfterInterval:
    return rec.AfterInterval(rms_mm=fig.rms.value, max_mm=fig.max.value,
                             rms_interval_95_mm=fig.rms.interval,
                             max_interval_95_mm=fig.max.interval)


def _objectives(rounds: Rounds, machine: KnownMachine
                ) -> tuple[rec.Objectives, rec.Alternative, rec.ErrorStats]:
    """Each objective's offsets written exactly (plug-in fields), and what the best
    offsets can do for the pooled layout."""
    cfg = rounds.config
    geometry, frame, points = cfg.machine.geometry(), cfg.writeback.frame, rounds.points
    lay = rounds.layout.vector() if rounds.layout is not None else np.zeros(6)
    zero = np.zeros(3)
    before = rounds.offsets_before
    figures: dict[str, rec.ObjectiveFigures] = {}
    for name, target in (("joints", dict.fromkeys(DRHO, 0.0)), ("tool", rounds.tool_target)):
        fld = error_field(points, geometry, acc_.params(target, lay), zero, frame)
        registers = None if before is None else {
            a: finite(float(before[a]) - (machine.start.get(f"drho_{a}", 0.0)
                                          - float(target[f"drho_{a}"]))) for a in "xyz"}
        figures[name] = rec.ObjectiveFigures(
            after=rec.ErrorStats(rms_mm=fld.rms_mm, max_mm=fld.max_mm), offsets_mm=registers,
            target_drho_mm={n: finite(float(target[n])) for n in DRHO})
    chosen = cfg.writeback.objective
    other = "tool" if chosen == "joints" else "joints"
    best = error_field(points, geometry, acc_.params(rounds.tool_target, lay), zero, frame)
    return (rec.Objectives(joints=figures["joints"], tool=figures["tool"]),
            rec.Alternative(objective=other, after=figures[other].after,
                            offsets_mm=figures[other].offsets_mm,
                            target_drho_mm=figures[other].target_drho_mm),
            rec.ErrorStats(rms_mm=best.rms_mm, max_mm=best.max_mm))


def _compensated(rounds: Rounds, tool: ToolFigures) -> rec.Compensated:
    told = tool.told
    model = rounds.last.model
    nominal = nominal_reasons(rounds.layout, told, model)
    laid = [n for n in told if n not in DRHO]
    joints = [] if tool.joints is None else tool.joints.basis(tool.route)
    return rec.Compensated(
        rms_mm=tool.compensated.rms.value, max_mm=tool.compensated.max.value,
        rms_interval_95_mm=tool.compensated.rms.interval,
        max_interval_95_mm=tool.compensated.max.interval,
        offsets_only_rms_mm=tool.after.rms.value, offsets_only_max_mm=tool.after.max.value,
        told=told, nominal=nominal, routes=list(ROUTES_IN_FULL), route=tool.route,
        takes_into_account=route_words(tool.route), method=tool.method,
        assumes=["the controller is told Δρ as the rounds joined left it"
                 + (f", and {', '.join(laid)} as the run identified them" if laid else ""),
                 *(f"{', '.join(names)}: {why}" for why, names in grouped(nominal).items()
                   if not names[0].startswith("dL")),
                 "ΔL = 0 (leg lengths nominal; not identified beside the tilts and gaps "
                 "from two stops per leg); a leg 0.1 mm long changes the field",
                 *joints,
                 "a compensated program (orthocal compensate) takes the same into account "
                 "(with the joint tables, each joint's error in the direction the program "
                 "moves it) and adds at most its --tolerance (default 1 µm) along the "
                 "path between its points"],
        field_rms_mm=[round(float(v), 7) for v in tool.point_rms_mm])


def joint_words(tool: ToolFigures) -> str:
    """What the figures take the encoders to be: exact up to their zero where the run
    knows nothing of its joints, else each joint's positioning error as result.json's
    ``joints`` states it."""
    basis = [] if tool.joints is None else tool.joints.basis("offsets")
    if not basis:
        return "encoders exact up to their zero"
    return ("encoders exact up to their zero and each joint's positioning error "
            "(result.json's joints): " + "; ".join(basis))


def drive_count(rounds: Rounds) -> rec.DriveCount | None:
    """What the drive's count does at the tool over the stated grid, (J17); None where
    the joints are taken as continuous."""
    c = rounds.target_count_mm
    if not any(v > 0 for v in c):
        return None
    rms, top = count_at_tool(rounds.points, rounds.config.machine.geometry(), c)
    return rec.DriveCount(target_mm=dict(zip(AXES, c, strict=True)), rms_mm=rms,
                          max_mm=top)


def drive_count_words(count: rec.DriveCount) -> str:
    """The assumption the tool's figures make of the drive's count, in words."""
    c = count_words([count.target_mm[a] or 0.0 for a in AXES])
    return (f"each joint at whole counts of the drive's targets ({c}): a point between "
            f"counts is reached with each joint up to half a count off, "
            f"{1000 * count.rms_mm:.1f} µm RMS and up to {1000 * count.max_mm:.1f} µm at "
            "the tool over the workspace, which these figures leave out (model.md, \"The "
            "drive's count\")")


def accuracy_section(rounds: Rounds, machine: KnownMachine, tool: ToolFigures,
                     q: Mapping[str, Quantity]) -> rec.Accuracy:
    """``accuracy`` from the statement: the tool's figures, the squareness, the tilts
    and gaps as the statement has them (the advice lists are filled from the advice
    once it is made: station.statement.conclude)."""
    cfg = rounds.config
    lay = rounds.layout
    objectives, alternative, best = _objectives(rounds, machine)
    in_model = rounds.last.names
    fitted = "+".join(["rho", *(["tilt"] if lay is not None else []),
                       *(["gap"] if lay is not None and lay.gaps() else [])])
    words = [w.replace("encoders exact up to their zero", joint_words(tool))
             for w in assumes(fitted, cfg.writeback.frame)]
    counted = drive_count(rounds)
    if counted is not None:  # before the last: the intervals hold under all above
        words.insert(max(len(words) - 1, 0), drive_count_words(counted))
    fit = rounds.layout_fit
    form = None if lay is None or fit is None else \
        run_budget.form_of_layout(cfg, fit, lay.names)
    if form is not None:
        words.insert(0, form[1])
    said = acc_.layout_words(lay, rounds.last.model, in_model)
    if said:
        words.insert(0, said)
    square = {pair: q.get(f"squareness_{pair}") for pair, _ in PAIRS}
    k_act = [rule.act_k(x.dof) for x in square.values() if x is not None]
    tilts_in_model = any(n in in_model for n in TILT_NAMES)
    return rec.Accuracy(
        workspace_mm=[(lo, hi) for lo, hi in cfg.machine.workspace_box()],
        grid=rec.Grid(points_per_axis=acc_.GRID_POINTS, points=len(rounds.points),
                      excluded=int(acc_.grid(cfg, rounds.limits).excluded)),
        frame=cfg.writeback.frame, objective=cfg.writeback.objective,
        before=rec.ErrorStats(rms_mm=tool.before.rms.value, max_mm=tool.before.max.value),
        after=_after(tool.after), after_method=tool.method,
        objectives=objectives, alternative=alternative, best_offsets_can_do=best,
        squareness_mm_per_m={p: None if x is None else x.value for p, x in square.items()},
        squareness_std_errors={p: None if x is None or x.k is None or x.expanded is None
                               else x.expanded / x.k for p, x in square.items()},
        squareness_decision=None if lay is None else rec.SquarenessDecision(
            k=max(k_act) if k_act else None, rule=rule.ACT_RULE),
        squareness_advice=[], gap_advice=[],
        tilts=None if lay is None else {n: finite(v) for n, v in lay.as_dict().items()},
        tilt_std_errors=None if lay is None else
        {n: finite(v) for n, v in lay.std_errors().items()},
        tilt_interval_95=None if lay is None or tilts_in_model else
        {n: x.interval_95 for n in TILT_NAMES if (x := q.get(n)) is not None
         and x.interval_95 is not None},
        gaps=None if lay is None or not lay.gaps() else
        {n: finite(v) for n, v in (lay.gaps() or {}).items()},
        gap_std_errors=None if lay is None or not lay.gaps() else
        {n: finite(v) for n, v in (lay.gap_std_errors() or {}).items()},
        gap_interval_95=None if lay is None or not lay.gaps() else
        {n: x.interval_95 for n in GAP_NAMES if (x := q.get(n)) is not None
         and x.interval_95 is not None},
        field=rec.ErrorField(points_mm=np.round(rounds.points, 4).tolist(),
                             before_mm=np.round(tool.before.field.field, 6).tolist(),
                             after_mm=np.round(tool.after.field.field, 6).tolist()),
        compensated=_compensated(rounds, tool), drive_count=counted, assumes=words)


def machine_model(rounds: Rounds, machine: KnownMachine) -> MachineModel:
    """model.json: the identified machine (accuracy_statement.model_export), Δρ now the
    statement's as left."""
    first = rounds.idents[0]
    names = list(first.names)
    idx = [names.index(n) for n in DRHO if n in names]
    written = rounds.written[-1].written if rounds.written else None
    return MachineModel.model_validate(acc_.model_export(
        rounds.config, drho_start=machine.start,
        drho_start_cov=np.asarray(first.covariance)[np.ix_(idx, idx)] if len(idx) == 3
        else None, drho_now=machine.now, tilts=rounds.layout, model=rounds.last.model,
        offsets_before=None if rounds.offsets_before is None else dict(rounds.offsets_before),
        offsets_written=None if written is None else dict(written),
        dof=finite(first.std_error_dof)))
