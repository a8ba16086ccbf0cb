"""``orthocal design``: the experiment before anything moves (docs/design.md).

For the configured test postures and a model: rank, condition number, each
parameter's standard error per µm of noise, what cannot be separated (in
words), the predicted run time, and a D-optimal search for better strokes
within the soft limits and the indicators' strokes. No device is contacted:
the soft limits are the config's ``[controller] soft_min`` / ``soft_max``
(without them the search stays within the machine section's rho_min/rho_max),
and every candidate stroke must pass the same plan check ``orthocal run``
applies (soft limits, workspace, plunger travel along every move).

Two noise figures per parameter:

* ``noise_gain``: per unit of noise on one deviation, one measurement of each
  (orthocal's statistical floor, σ·sqrt(diag (JᵀJ)⁻¹) at σ = 1);
* ``std_error_per_um``: for the whole planned run (its cycles, readings per
  stop, and the Π0 stops each deviation shares), per µm of indicator noise
  (orthocal.design.run_std_errors); µrad per µm for the tilts.

The run time is the physical floor of the plan as the station runs it: every
move (and each waypoint's sub-move) a rest-to-rest trapezoid over its longest axis
at the configured speed and acceleration (drivers.profiles.move_time: axes that
move together; a drive that moves one axis after another takes longer),
the settle time at each stop, and each stop's readings at the gauges' line
time (request + reply characters at their baud rate; the gauges of a stop are
read in parallel). Operator mounting time is not included. bench/cycle.py
measures the station at 1.0x-1.1x this floor (BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

import numpy as np

from orthocal import AXES
from orthocal.numbers import finite
from orthocal.postures import MIDDLE, split_plane, stroke
from station.config import StationConfig, load_config, parse_config
from station.errors import BadInput
from station.plan.check import check_plan
from station.plan.checker import MotionChecker
from station.plan.limits import effective_limits
from station.plan.steps import Move, Plan, Read, Settle, build_plan

# No controller is contacted: "controller limits" wide open, narrowed by the config.
_OPEN = ([-1e6] * 3, [1e6] * 3)
OBJECTIVE = ("D-optimal: maximise det of the run's information matrix (the inverse of its "
             "covariance), as many stops per leg as configured")


def _float_list(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise BadInput(f"--strokes: expected numbers a,b,c in mm, got {text!r}") from None
    if not values:
        raise BadInput("--strokes: expected at least one stroke in mm")
    return values


def _config(args: argparse.Namespace) -> StationConfig:
    """The config file, or a station of two indicators per leg on the geometry
    options; ``--strokes`` replaces ``[procedure] strokes`` (validated as in a file)."""
    strokes = None if args.strokes is None else _float_list(args.strokes)
    if args.config:
        config = load_config(args.config)
        if strokes is None:
            return config
        data = config.model_dump(exclude_none=True)
        source = f"{args.config} with --strokes"
    else:
        data = {
            "machine": {"leg_length": args.leg_length, "rho_min": args.rho_min,
                        "rho_max": args.rho_max},
            "indicators": [{"name": "A", "port": "none"}, {"name": "B", "port": "none"}],
            "setups": [{"leg": leg, "indicators": dict(zip("AB", [d for d in AXES if d != leg],
                                                           strict=True))} for leg in AXES],
            "procedure": {},
        }
        source = "design options"
    if strokes is not None:
        data["procedure"]["strokes"] = strokes
    return parse_config(data, source)


def _model(args: argparse.Namespace, config: StationConfig) -> str:
    import orthocal

    model = args.model or config.procedure.model
    if model not in (*orthocal.MODELS, "auto"):
        raise BadInput(f"--model: must be one of {', '.join(orthocal.MODELS)} or auto, "
                       f"got {model!r}")
    return model


def _resolve_auto(plan: Plan, config: StationConfig) -> str:
    """``auto`` chooses among nested candidates after the run; before it, the one
    that matters is the largest these postures can identify (the smaller ones are
    determined at least as well)."""
    from orthocal import design
    from orthocal.selection import CANDIDATES

    keys, _ = plan_keys(plan)
    geometry = config.machine.geometry()
    able = [m for m in CANDIDATES if design.quality(keys, geometry, m).identifiable]
    return able[-1] if able else CANDIDATES[0]


def _separation(plan: Plan, config: StationConfig) -> dict[str, Any]:
    """What these stops can tell apart: each model ``auto`` may keep (the lattice,
    orthocal.selection.CANDIDATES) with its condition number and largest noise
    gain per kind of parameter, or what it cannot separate; and the legs' form
    against the tilts (orthocal.design.form_separation), with what does separate
    them."""
    from orthocal import design
    from orthocal.selection import CANDIDATES

    keys, _ = plan_keys(plan)
    geometry = config.machine.geometry()
    lattice = []
    for name in CANDIDATES:
        q = design.quality(keys, geometry, name)
        kinds = {kind: max((g for n, g in q.noise_gain.items() if n.startswith(kind)),
                           default=None) for kind in ("drho", "dL", "tilt", "gap")}
        lattice.append({
            "model": name, "identifiable": q.identifiable,
            "condition_number": q.condition_number if q.identifiable else None,
            "noise_gain_max": {k: v for k, v in kinds.items()
                               if v is not None and q.identifiable},
            **({} if q.identifiable else {"cannot_separate": design.describe(q)})})
    middles = [k for k in keys if split_plane(k[0])[1] == MIDDLE]
    form = design.form_separation(middles, geometry)
    finite_form = {k: (v if math.isfinite(v) else None) for k, v in form.items()}
    tells = "cannot tell" if form["middle"] == math.inf else "hardly tells"
    strokes = [stroke(k[0], geometry) for k in middles]
    planes = "; ".join(
        f"at {f:g} of its length from the carriage's joint (condition {form[f'{f:g}']:.0f}"
        + ("" if f + min(strokes) / geometry.leg_length > 0
           and f + max(strokes) / geometry.leg_length < 1
           else ", but the leg leaves that plane at a planned posture") + ")"
        for f in design.SECOND_PLANES)
    words = (f"one gauge plane per leg (the middles) {tells} "
             "a uniform bow of the legs from the tilts, whatever the strokes; what does: a "
             f"second gauge plane on each leg ([[setups]] at), {planes}; or "
             "the legs' straightness measured and stated ([uncertainty] leg_straightness_mm)")
    return {"lattice": lattice, "leg_form": {"model": "rho+tilt and one bow per leg",
                                             "condition_number": finite_form, "note": words}}


# --- what the plan measures ------------------------------------------------------------


def plan_keys(plan: Plan) -> tuple[list[tuple[str, str, str]], list[list[int]]]:
    """The deviation keys the plan measures, with each indicator's rows
    (station.plan.steps.Plan.deviation_keys)."""
    return plan.deviation_keys()


def _line_time_s(config: StationConfig, name: str) -> float:
    """Seconds one reading occupies the line: request + reply at the gauge's baud."""
    from drivers.indicator_protocols import make_protocol

    ind = config.indicator(name)
    overrides = {target: getattr(ind, key) for key, target in (
        ("baudrate", "baudrate"), ("bytesize", "bytesize"), ("parity", "parity"),
        ("stopbits", "stopbits"), ("request", "request"), ("terminator", "terminator"),
        ("pattern", "reply_pattern"), ("unit", "unit"), ("scale", "scale"))
        if getattr(ind, key) is not None}
    try:
        proto = make_protocol(ind.protocol, overrides or None)
    except ValueError as exc:
        raise BadInput(f"indicators.{name}: {exc}") from None
    # A generic gauge states no reply format: count a 12-character value.
    reply = (proto.reply_format.format(value=0.0).encode() if proto.reply_format
             else b"+0000.000 mm")
    return (len(proto.request) + len(reply) + len(proto.terminator)) * proto.bits_per_char \
        / proto.baudrate


def run_time(plan: Plan, config: StationConfig) -> dict[str, Any]:
    """Predicted seconds of the plan's measurement (and verification) phases, from
    Π0 on, at the configured cycles (no repeats, no adaptive early stop)."""
    from drivers.profiles import move_time

    c = config.controller
    position: np.ndarray | None = None
    moves = settle = reading = 0.0
    n_moves = n_stops = 0
    line = {name: _line_time_s(config, name) for sp in plan.setups for name in sp.indicators}
    for step, via in plan.waypoints_of():
        if isinstance(step, Move):
            # the waypoints the plan check put on the move and its approach point: each
            # a move of its own
            approach = [step.approach] if step.approach is not None else []
            for leg in [*via, *approach, step.targets]:
                target = np.asarray(leg)
                if position is not None:
                    distance = float(np.max(np.abs(target - position)))
                    if distance > 1e-3:  # the sequencer skips moves within a µm
                        moves += move_time(distance, c.speed_mm_s, c.accel_mm_s2)
                        n_moves += 1
                position = target
        elif isinstance(step, Settle):
            settle += step.seconds
        elif isinstance(step, Read):
            n_stops += 1
            reading += step.n * max(line[name] for name in step.indicators)
    phase = moves + settle + reading
    phases = 2 if config.procedure.verify else 1
    return {"total_s": phases * phase, "measurement_s": phase,
            "verification_s": phase if phases == 2 else 0.0,
            "moves_s": moves, "settle_s": settle, "readings_s": reading,
            "moves": n_moves, "stops": n_stops}


# --- the design ------------------------------------------------------------------------


def _figures(plan: Plan, config: StationConfig, model: str) -> dict[str, Any]:
    from orthocal import design

    geometry = config.machine.geometry()
    keys, indicators = plan_keys(plan)
    q = design.quality(keys, geometry, model)
    out: dict[str, Any] = {
        "test_postures": list(plan.setups[0].order),
        "strokes_mm": [float(stroke(p, geometry)) for p in plan.setups[0].order],
        "n_deviations": q.n_deviations, "parameters": list(q.names), "rank": q.rank,
        "identifiable": q.identifiable,
        "condition_number": finite(q.condition_number),
        "noise_gain": {n: finite(v) for n, v in q.noise_gain.items()},
        "std_error_per_um": {n: None for n in q.names},
        # D and A of the whole run (per µm of indicator noise), filled in below
        "d_criterion_log_det": None, "a_criterion_trace_cov": None,
        "cannot_separate": [dict(c) for c in q.invisible],
        "in_words": design.describe(q),
        "run_time": run_time(plan, config),
        "tool_rms_per_um": None,
    }
    if q.identifiable:
        J = design.design_matrix(keys, geometry, model)
        cov = design.run_covariance(J, indicators, plan.cycles, plan.readings)
        se = np.sqrt(np.diag(cov))
        out["std_error_per_um"] = {n: float(v) for n, v in zip(q.names, se, strict=True)}
        out["d_criterion_log_det"] = float(-np.linalg.slogdet(cov)[1])
        out["a_criterion_trace_cov"] = float(np.trace(cov))
        out["tool_rms_per_um"] = tool_rms_per_um(config, q.names, cov)
    return out


def tool_rms_per_um(config: StationConfig, names: Any, cov: np.ndarray) -> float | None:
    """What the identification's noise alone leaves at the tool: the expected RMS
    over the workspace grid of the tool-point error (µm per µm of indicator noise)
    on a square machine whose offsets were written (objective joints): the field's
    linear response to the parameters' errors, with this plan's covariance.
    None where the model has no joint offsets."""
    from orthocal import PARAM_NAMES
    from orthocal.accuracy import workspace_grid
    from orthocal.tool_interval import field_jacobian

    if not any(n.startswith("drho_") for n in names):
        return None
    geometry = config.machine.geometry()
    points = workspace_grid(config.machine.workspace_box(), 7, geometry).points
    columns = [PARAM_NAMES.index(n) for n in names]
    G = field_jacobian(points, geometry, np.zeros(len(PARAM_NAMES)), np.zeros(3),
                       config.writeback.frame, columns)
    # E|δF|² summed over the grid's 3n components, per point: the mean squared error
    return float(np.sqrt(np.trace(G @ cov @ G.T) / len(points)))


def _feasible(config: StationConfig, limits: tuple[Any, Any]):
    """The plan check of ``orthocal run`` for a set of strokes: soft limits,
    workspace and plunger travel along every move of their plan."""
    # One checker for every candidate (their plans share most sub-moves); whether a
    # plan holds does not depend on where its waypoints are spread.
    checker = MotionChecker(config, limits, spread=False)

    def check(strokes: Any) -> bool:
        try:
            check_plan(build_plan(config, list(np.atleast_1d(strokes))), config, limits,
                       checker=checker, travel=False)
        except (BadInput, ValueError):
            return False
        return True
    return check


def _search_bounds(config: StationConfig, limits: tuple[Any, Any]
                   ) -> tuple[tuple[float, float], str]:
    m, c = config.machine, config.controller
    known = limits is not _OPEN
    if not known and c.soft_min is None and c.soft_max is None:
        return (m.rho_min, m.rho_max), "[machine] rho_min..rho_max (no soft limits known)"
    lo_j, hi_j = effective_limits(config, limits)
    # The stop's joint i at L + s must respect the soft limits of every measured leg's
    # axis; the plan check (run per candidate) covers the other joints and the plungers.
    legs = [AXES.index(sp.leg) for sp in config.setups]
    lo = max(float(lo_j[i]) - m.leg_length for i in legs)
    hi = min(float(hi_j[i]) - m.leg_length for i in legs)
    if getattr(limits, "source", "registers") in ("absent", "nonsense"):
        known = False  # the controller could not tell: the config's limits alone
    source = "the controller's soft limits" if known else "[controller] soft_min/soft_max"
    if known and (c.soft_min is not None or c.soft_max is not None):
        source += " narrowed by the config"
    return (max(lo, -m.leg_length + 1.0), min(hi, m.leg_length - 1.0)), source


def design_summary(config: StationConfig, model: str, search: bool = True,
                   controller_limits: tuple[Any, Any] | None = None) -> dict[str, Any]:
    """Everything ``orthocal design`` reports, as JSON-ready data. BadInput when
    the configured plan fails the plan check (the run would refuse it too).
    ``controller_limits``: the controller's soft limits when it has been asked
    (``orthocal run --plan``); otherwise only the config's limit the search."""
    from orthocal import design

    limits = _OPEN if controller_limits is None else controller_limits
    plan = check_plan(build_plan(config), config, limits)
    m = config.machine
    auto = model == "auto"
    if auto:
        model = _resolve_auto(plan, config)
    doc: dict[str, Any] = {
        "model": model,
        **({"auto": f"auto picks among nested models after the run; shown for {model}, "
                    "the largest these postures identify"} if auto else {}),
        "machine": {"leg_length": m.leg_length, "rho_min": m.rho_min, "rho_max": m.rho_max},
        "cycles": plan.cycles, "readings": plan.readings,
        **_figures(plan, config, model),
        **_separation(plan, config),
    }
    if not search:
        return doc
    bounds, source = _search_bounds(config, limits)
    legs = {sp.leg: [d.lstrip("-") for d in sp.indicators.values()] for sp in plan.setups}
    try:
        check = _feasible(config, limits)
        found = design.search_strokes(doc["strokes_mm"], legs, m.geometry(), model, bounds,
                                      feasible=check, feasible_set=check, cycles=plan.cycles)
        better = check_plan(build_plan(config, list(found.strokes)), config, limits)
    except (ValueError, BadInput) as exc:
        doc["search"] = {"objective": OBJECTIVE, "bounds_mm": list(bounds),
                         "bounds_from": source, "error": f"no better strokes: {exc}"}
        return doc
    proposal = _figures(better, config, model)
    d_now, d_new = doc["d_criterion_log_det"], proposal["d_criterion_log_det"]
    p = len(proposal["parameters"])
    doc["search"] = {
        "objective": OBJECTIVE, "bounds_mm": list(bounds), "bounds_from": source,
        "candidates": found.candidates,
        # det ratio as a per-parameter factor: how much smaller each axis of the
        # confidence ellipsoid is on (geometric) average.
        "d_gain": None if d_now is None or d_new is None else
        float(math.exp((d_new - d_now) / (2 * p))),
        "config": _config_lines(m, found.strokes),
        **proposal,
    }
    return doc


def _config_lines(m: Any, strokes: tuple[float, ...]) -> str:
    lines = []
    lo, hi = min(min(strokes), m.rho_min), max(max(strokes), m.rho_max)
    if (lo, hi) != (m.rho_min, m.rho_max):
        lines.append(f"[machine] rho_min = {lo:g}, rho_max = {hi:g}")
    lines.append("[procedure] strokes = [" + ", ".join(f"{s:g}" for s in strokes) + "]")
    return "; ".join(lines)


# --- output ------------------------------------------------------------------------------


def _table(doc: dict[str, Any]) -> list[str]:
    lines = [f"  {'parameter':<9} {'noise gain':>10} {'SE/µm run':>10}"]
    for n in doc["parameters"]:
        g, se = doc["noise_gain"][n], doc["std_error_per_um"][n]
        lines.append(f"  {n:<9} {'∞' if g is None else f'{g:.3f}':>10} "
                     f"{'∞' if se is None else f'{se:.3f}':>10}")
    return lines


def _lattice_lines(doc: dict[str, Any]) -> list[str]:
    """The models auto may keep, what each costs or why it cannot be had; the form."""
    if "lattice" not in doc:
        return []
    lines = ["  what these stops separate (the models auto may keep; largest noise gain per "
             "kind, tilts in mrad per mm):"]
    for row in doc["lattice"]:
        if row["identifiable"]:
            gains = ", ".join(f"{k} {v:.2f}" for k, v in row["noise_gain_max"].items())
            lines.append(f"    {row['model']:<14} condition {row['condition_number']:8.1f}; "
                         f"{gains}")
        else:
            lines.append(f"    {row['model']:<14} not identifiable: "
                         + " ".join(row["cannot_separate"]))
    lines.append(f"  legs' form: {doc['leg_form']['note']}")
    return lines


def _time(t: dict[str, Any]) -> str:
    return (f"{t['total_s']:.1f} s ({t['measurement_s']:.1f} s per phase: moves "
            f"{t['moves_s']:.1f} + settle {t['settle_s']:.1f} + readings "
            f"{t['readings_s']:.1f}; {t['moves']} moves, {t['stops']} stops per phase)")


def format_summary(doc: dict[str, Any]) -> str:
    cond = doc["condition_number"]
    lines = [
        *([f"design: {doc['auto']}"] if "auto" in doc else []),
        f"design: model {doc['model']}, stops per leg "
        + ", ".join(f"{s:+g}" for s in doc["strokes_mm"]) + " mm "
        f"({doc['n_deviations']} deviations, {doc['cycles']} cycle(s) × "
        f"{doc['readings']} reading(s))",
        f"  rank {doc['rank']} of {len(doc['parameters'])}, condition number "
        + ("∞" if cond is None else f"{cond:.2f}"),
        *_table(doc),
        "  noise gain: SE per unit of deviation noise (orthocal's statistical floor); "
        "SE/µm run: µm (µrad for tilts) per µm of indicator noise for this plan",
        *_lattice_lines(doc),
        *(f"  {w}" for w in doc["in_words"]),
        *([f"  at the tool: the identification's noise leaves {doc['tool_rms_per_um']:.2f} µm "
           "RMS of tool-point error over the workspace per µm of indicator noise (a square "
           "machine, objective joints)"] if doc.get("tool_rms_per_um") is not None else []),
        f"  predicted run time: {_time(doc['run_time'])}; operator mounting not included",
    ]
    s = doc.get("search")
    if s is not None:
        lines.append(f"search: {s['objective']}, strokes within [{s['bounds_mm'][0]:g}, "
                     f"{s['bounds_mm'][1]:g}] mm ({s['bounds_from']}) that pass the plan check")
        if "error" in s:
            lines.append(f"  {s['error']}")
        else:
            same = s["strokes_mm"] == doc["strokes_mm"]
            gain = s["d_gain"]
            lines += [
                "  best: " + ", ".join(f"{v:+g}" for v in s["strokes_mm"]) + " mm"
                + (" (the configured strokes)" if same else ""),
                f"  D: ln det information {_fmt(doc['d_criterion_log_det'])} → "
                f"{_fmt(s['d_criterion_log_det'])}"
                + ("" if gain is None else f" (confidence ellipsoid {gain:.3f}× smaller per "
                   "axis)") + f"; A: trace covariance {_fmt(doc['a_criterion_trace_cov'])} → "
                f"{_fmt(s['a_criterion_trace_cov'])}",
                *_table(s),
                *(f"  {w}" for w in s["in_words"]),
                f"  run time {_time(s['run_time'])}",
                f"  config: {s['config']}",
            ]
    return "\n".join(lines)


def _fmt(v: float | None) -> str:
    return "n/a (rank-deficient)" if v is None else f"{v:.4g}"


def main(args: argparse.Namespace) -> int:
    config = _config(args)
    model = _model(args, config)
    doc = design_summary(config, model)
    print(json.dumps(doc, indent=1, allow_nan=False) if args.json else format_summary(doc))
    return 0
