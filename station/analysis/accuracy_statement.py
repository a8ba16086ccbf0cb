"""Accuracy at the tool, as the run states it (docs/design.md and docs/model.md, "Accuracy
at the tool"): where the tool goes before and after the offsets written, with
95 % intervals, over the workspace, for both objectives; the squareness and the
gaps between the axes, which the offsets cannot fix, and what to do about them;
the identified machine for export (model.json).

The machine the run states is the one all its rounds measured: Δρ at the start
of the run is the run's statement (``remaining.total``), Δρ now is what the last
verification found left (``remaining.estimate``; the offsets written moved the
rest), and the axes' layout (tilts and gaps), which no offset changes, is pooled
over every round's rho+tilt+gap fit (each round's misplaced stands are
modelled; a round whose layout disagrees with the others' beyond its
uncertainty is left out and named). The layout is stated even when ``auto``
kept a smaller model: the figure then carries what the run could not rule out
in its intervals. ΔL is taken as 0 (not identifiable beside the tilts from two
postures per leg) and ``assumes`` says so.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

import orthocal
from orthocal import AXES, BOW_NAMES, GAP_NAMES, PARAM_NAMES, TILT_NAMES
from orthocal.accuracy import (
    ErrorField,
    Grid,
    error_field,
    optimal_offsets,
    squareness,
    workspace_grid,
)
from orthocal.loop import FALSE_ALARM
from orthocal.numbers import finite
from orthocal.tool_interval import after_interval, assumes
from station.analysis.rail_advice import gap_advice, squareness_advice, undecided_advice
from station.config import StationConfig
from station.record import result_accuracy as rec
from station.record.result_accuracy import SquarenessDecision
from station.record.result_base import Interval, Params

#: Grid nodes per axis of the workspace box (docs/model.md's check values use 7³).
GRID_POINTS = 7
#: Consistency of one round's layout with the others' (χ², one dof per name): below
#: this p-value the round is left out of the pool (the first round's stands).
POOL_LEVEL = 0.001
DRHO = tuple(f"drho_{a}" for a in AXES)
#: How the axes lie: what no offset changes (docs/model.md, "Extended model" and "Axes
#: that do not meet"). Pooled over the rounds, in this order.
LAYOUT_NAMES: tuple[str, ...] = (*TILT_NAMES, *GAP_NAMES)
#: The layout's fits, largest first: a round whose own model lacks part of the
#: layout is fitted again with the first of these its deviations identify.
LAYOUT_MODELS = ("rho+tilt+gap", "rho+tilt")
#: The soft limits a statement's grid leaves out: (lower, upper) joint mm.
Limits = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class RoundLayout:
    """One round's fit of the axes' layout: its phase, the names it holds (tilts
    in mrad, gaps in mm), their values, covariance, and the dof of that covariance."""

    phase: str
    names: tuple[str, ...]
    values: np.ndarray
    covariance: np.ndarray
    dof: float | None


@dataclass(frozen=True)
class Layout:
    """The axes' layout the run states: pooled over ``rounds`` (inverse-covariance
    weights), ``dropped`` the rounds left out and why. ``names``: the tilts, and
    the gaps where the rounds' fits had them."""

    names: tuple[str, ...]
    values: np.ndarray
    covariance: np.ndarray
    dof: float | None
    rounds: tuple[str, ...]
    dropped: tuple[str, ...] = ()

    def _pick(self, which: Sequence[str], what: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, what, strict=True) if n in which}

    def as_dict(self) -> dict[str, float]:
        """The tilts (mrad)."""
        return self._pick(TILT_NAMES, self.values)

    def std_errors(self) -> dict[str, float]:
        return self._pick(TILT_NAMES, np.sqrt(np.maximum(np.diag(self.covariance), 0.0)))

    def gaps(self) -> dict[str, float] | None:
        """The gaps (mm), None where the rounds' fits had none."""
        return self._pick(GAP_NAMES, self.values) or None

    def gap_std_errors(self) -> dict[str, float] | None:
        return self._pick(GAP_NAMES, np.sqrt(np.maximum(np.diag(self.covariance), 0.0))) \
            or None

    def vector(self, keep: Sequence[str] | None = None) -> np.ndarray:
        """The layout over LAYOUT_NAMES (six: tilts, then gaps); names not held, or
        not in ``keep`` (None: all), at 0."""
        out = np.zeros(len(LAYOUT_NAMES))
        for n, v in zip(self.names, self.values, strict=True):
            if keep is None or n in keep:
                out[LAYOUT_NAMES.index(n)] = v
        return out

    def covariance_full(self) -> np.ndarray:
        """The covariance over LAYOUT_NAMES (zero where not held)."""
        idx = [LAYOUT_NAMES.index(n) for n in self.names]
        out = np.zeros((len(LAYOUT_NAMES), len(LAYOUT_NAMES)))
        out[np.ix_(idx, idx)] = self.covariance
        return out


def round_layout(phase: str, ident: orthocal.Identification) -> RoundLayout | None:
    """The tilts (and gaps, where it has them) of an identification; None when it
    has no tilts."""
    if not all(n in ident.names for n in TILT_NAMES):
        return None
    return _round(phase, ident, tuple(n for n in LAYOUT_NAMES if n in ident.names))


def round_form(phase: str, ident: orthocal.Identification) -> RoundLayout | None:
    """The legs' bows (orthocal.BOW_NAMES, mm) of an identification that fitted them
    (a second gauge plane), as a round to pool like the layout; None without them."""
    if not all(n in ident.names for n in BOW_NAMES):
        return None
    return _round(phase, ident, BOW_NAMES)


def _round(phase: str, ident: orthocal.Identification, held: tuple[str, ...]
           ) -> RoundLayout | None:
    """The parameters ``held`` of an identification with their covariance block; None
    where that block is not finite."""
    names = list(ident.names)
    idx = [names.index(n) for n in held]
    cov = np.asarray(ident.covariance, dtype=float)[np.ix_(idx, idx)]
    if not np.all(np.isfinite(cov)):
        return None
    return RoundLayout(phase, held, np.array([ident.parameters[n] for n in held]), cov,
                       finite(ident.std_error_dof))


def pool_layout(rounds: Sequence[RoundLayout]) -> Layout | None:
    """Inverse-covariance pooling of the rounds' layouts (they do not change with
    the offsets), over the names the most rounds hold. A round inconsistent with the
    pool of the others (χ² test at POOL_LEVEL) is left out: the first round's
    misplaced stands bias it most."""
    from scipy.special import chdtrc  # the χ² upper tail (scipy.stats' chi2.sf)

    if not rounds:
        return None
    names = max({r.names for r in rounds}, key=lambda n: (sum(r.names == n for r in rounds),
                                                          len(n)))
    kept = [r for r in rounds if r.names == names]
    dropped: list[str] = [f"{r.phase} (its fit held other parameters)" for r in rounds
                          if r.names != names]
    while len(kept) >= 2:
        worst, worst_p = None, 1.0
        for r in kept:
            others = pool_layout([o for o in kept if o is not r])
            assert others is not None
            d = r.values - others.values
            p = float(chdtrc(len(names),
                             float(d @ np.linalg.solve(r.covariance + others.covariance, d))))
            if p < worst_p:
                worst, worst_p = r, p
        if worst is None or worst_p >= POOL_LEVEL:
            break
        kept.remove(worst)
        dropped.append(f"{worst.phase} (its layout disagrees with the other rounds', "
                       f"p = {worst_p:.1e})")
    info = sum(np.linalg.inv(r.covariance) for r in kept)
    cov = np.linalg.inv(info)
    values = cov @ sum(np.linalg.solve(r.covariance, r.values) for r in kept)
    dofs = [r.dof for r in kept if r.dof is not None]
    return Layout(names, values, cov, float(sum(dofs)) if len(dofs) == len(kept) else None,
                  tuple(r.phase for r in kept), tuple(dropped))


def params(drho: Mapping[str, float] | Sequence[float], layout: np.ndarray) -> np.ndarray:
    """The 12-vector of PARAM_NAMES: Δρ, ΔL = 0, the tilts and the gaps (``layout``
    over LAYOUT_NAMES, or the three tilts alone)."""
    d = [float(drho[n]) for n in DRHO] if isinstance(drho, Mapping) else list(drho)
    v = np.zeros(len(LAYOUT_NAMES))
    v[:len(layout)] = layout
    return np.array([*d, 0.0, 0.0, 0.0, *v], dtype=float)


def grid(config: StationConfig, limits: Limits | None) -> Grid:
    """The workspace grid (soft limits excluded)."""
    return workspace_grid(config.machine.workspace_box(), GRID_POINTS,
                          config.machine.geometry(), limits)


def tool_target(config: StationConfig, layout: Layout | None, points: np.ndarray,
                keep: Sequence[str] | None = None) -> dict[str, float]:
    """The joint errors Δρ that leave the least RMS tool error over ``points`` in
    the configured frame for a machine whose axes lie as ``layout`` says (only the
    names in ``keep``, None: all; ΔL = 0): the target of objective "tool"
    (orthocal.accuracy.optimal_offsets with Δρ = 0: its offsets are the joint
    errors to aim at). Zero without a layout."""
    if layout is None or (keep is not None and not any(n in keep for n in layout.names)):
        return dict.fromkeys(DRHO, 0.0)
    best = optimal_offsets(points, config.machine.geometry(),
                           params((0, 0, 0), layout.vector(keep)), config.writeback.frame,
                           max_abs_offset_mm=config.writeback.max_abs_offset_mm)
    return {n: float(v) for n, v in zip(DRHO, best.offsets, strict=True)}


def _stats(field: ErrorField) -> rec.ErrorStats:
    return rec.ErrorStats(rms_mm=float(field.rms_mm), max_mm=float(field.max_mm))


def _known(values: Mapping[str, float]) -> Params:
    """A per-name map as the record holds it: NaN and infinities as null."""
    return {n: finite(v) for n, v in values.items()}


def covariance(now_cov: np.ndarray | None, layout: Layout | None,
                form_cov: np.ndarray | None = None) -> np.ndarray:
    """12×12: Δρ now (the last round's) and the pooled layout; the two come from
    different fits and are taken as independent. ``form_cov``: what the legs' form
    leaves in the layout (over ``layout.names``; every round alike, so added after
    the pooling, not averaged by it)."""
    cov = np.zeros((len(PARAM_NAMES), len(PARAM_NAMES)))
    if now_cov is not None:
        cov[:3, :3] = now_cov
    if layout is not None:
        cov[6:, 6:] = layout.covariance_full()
        if form_cov is not None:
            idx = [6 + LAYOUT_NAMES.index(n) for n in layout.names]
            cov[np.ix_(idx, idx)] += form_cov
    return cov


def _interval(layout: Layout, names: Sequence[str]) -> dict[str, Interval] | None:
    """The 95 % intervals of the layout's ``names`` it holds."""
    k = orthocal.coverage_factor(layout.dof)
    se = np.sqrt(np.maximum(np.diag(layout.covariance), 0.0))
    out = {n: (float(v - k * e), float(v + k * e))
           for n, v, e in zip(layout.names, layout.values, se, strict=True) if n in names}
    return out or None


def layout_words(layout: Layout | None, model: str, in_model: Sequence[str]) -> str | None:
    """What the figure takes of the axes' layout, in words (None: nothing held)."""
    if layout is None:
        return None
    held = "tilts and gaps" if any(n in GAP_NAMES for n in layout.names) else "tilts"
    left = [n for n in layout.names if n not in in_model]
    return (f"the axes' {held} as the fits of round(s) {', '.join(layout.rounds)} put them, "
            "pooled (they do not change with the offsets)"
            + (f"; the model test kept {model!r}, so {', '.join(left)} are not significant, "
               "and the intervals include them" if left else "")
            + (f"; left out: {'; '.join(layout.dropped)}" if layout.dropped else ""))


def statement(config: StationConfig, limits: Limits | None, *,
              drho_start: Mapping[str, float], drho_now: Mapping[str, float],
              drho_now_cov: np.ndarray | None, dof: float | None, layout: Layout | None,
              model: str, in_model: Sequence[str], offsets_before: Mapping[str, float] | None,
              target_tool: Mapping[str, float], form: tuple[np.ndarray, str] | None = None,
              undecided: str | None = None) -> rec.Accuracy:
    """The run JSON's ``accuracy`` (docs/design.md): before and after over the workspace
    with 95 % intervals for the after-figures, both objectives' predicted after-
    figures side by side, squareness and the gaps with what to do, what it all
    assumes. ``in_model``: the parameter names of the model the run kept.
    ``form``: what the legs' form may leave in the layout (covariance over
    ``layout.names``, orthocal.budget.form_covariance) and its words: the after-
    figures' intervals carry it. ``undecided``: the model that explains the data as
    well as the layout's (the legs' bows, model_choice.measured_form): then no rail is
    to be shimmed or moved on these figures (:func:`undecided_advice`)."""
    geometry = config.machine.geometry()
    g = grid(config, limits)
    points = g.points
    frame = config.writeback.frame
    lay_v = layout.vector() if layout is not None else np.zeros(len(LAYOUT_NAMES))
    zero = np.zeros(3)
    before = error_field(points, geometry, params(drho_start, lay_v), zero, frame)
    cov = covariance(drho_now_cov, layout)
    with_form = cov if form is None else covariance(drho_now_cov, layout, form[0])
    after = after_interval(params(drho_now, lay_v), with_form, dof, zero, points, geometry,
                           frame)
    # Each objective's offsets written exactly: the machine's Δρ at its target.
    objectives: dict[str, rec.ObjectiveFigures] = {}
    for name, target in (("joints", dict.fromkeys(DRHO, 0.0)), ("tool", target_tool)):
        fld = error_field(points, geometry, params(target, lay_v), zero, frame)
        registers = None if offsets_before is None else _known({
            a: float(offsets_before[a]) - (float(drho_start[f"drho_{a}"])
                                           - float(target[f"drho_{a}"])) for a in AXES})
        objectives[name] = rec.ObjectiveFigures(
            after=_stats(fld), offsets_mm=registers,
            target_drho_mm=_known({n: float(target[n]) for n in DRHO}))
    # what no offsets can reach: the best offsets for the layout, Δρ then nothing
    best = error_field(points, geometry, params(tool_target(config, layout, points), lay_v),
                       zero, frame)
    chosen = config.writeback.objective
    other = "tool" if chosen == "joints" else "joints"
    sq = squareness(params(drho_now, lay_v), geometry, offsets=zero, covariance=cov)
    sq_values, sq_se = sq.as_dict(), sq.std_errors_dict() or {}
    tilts_in_model = any(n in in_model for n in TILT_NAMES)
    gaps_in_model = any(n in in_model for n in GAP_NAMES)
    tilt_interval = None if layout is None or tilts_in_model else \
        _interval(layout, TILT_NAMES)
    fitted = "+".join(["rho", *(["tilt"] if layout is not None else []),
                       *(["gap"] if layout is not None and layout.gaps() else [])])
    words = assumes(fitted, frame)
    said = layout_words(layout, model, in_model)
    if form is not None and layout is not None:
        words.insert(0, form[1])
    if said:
        words.insert(0, said)
    rail = config.machine.rho_max - config.machine.rho_min
    decision = squareness_decision(layout, tilts_in_model)
    gap_decision = squareness_decision(layout, gaps_in_model)
    return rec.Accuracy(
        workspace_mm=[(lo, hi) for lo, hi in config.machine.workspace_box()],
        grid=rec.Grid(points_per_axis=GRID_POINTS, points=len(points), excluded=int(g.excluded)),
        frame=frame, objective=chosen,
        before=_stats(before),
        after=rec.AfterInterval(rms_mm=float(after.rms_mm), max_mm=float(after.max_mm),
                                rms_interval_95_mm=_pair(after.rms_interval_mm),
                                max_interval_95_mm=_pair(after.max_interval_mm)),
        after_method=after.method,
        objectives=rec.Objectives(joints=objectives["joints"], tool=objectives["tool"]),
        alternative=rec.Alternative(objective=other, after=objectives[other].after,
                                    offsets_mm=objectives[other].offsets_mm,
                                    target_drho_mm=objectives[other].target_drho_mm),
        best_offsets_can_do=_stats(best),
        squareness_mm_per_m=_known(sq_values),
        squareness_std_errors=_known(sq_se),
        squareness_decision=decision,
        squareness_advice=undecided_advice(undecided) if undecided else
        squareness_advice(layout, rail, decision),
        tilts=None if layout is None else _known(layout.as_dict()),
        tilt_std_errors=None if layout is None else _known(layout.std_errors()),
        tilt_interval_95=tilt_interval,
        gaps=None if layout is None else _maybe_known(layout.gaps()),
        gap_std_errors=None if layout is None else _maybe_known(layout.gap_std_errors()),
        gap_interval_95=None if layout is None else _interval(layout, GAP_NAMES),
        gap_advice=undecided_advice(undecided) if undecided else
        gap_advice(layout, gap_decision),
        field=rec.ErrorField(points_mm=np.round(points, 4).tolist(),
                             before_mm=np.round(before.field, 6).tolist(),
                             after_mm=np.round(after.field.field, 6).tolist()),
        # put into the controller: stated by station.analysis.compensated once this is
        compensated=None,
        assumes=words,
    )


def _pair(values: Sequence[float]) -> Interval:
    lo, hi = values
    return float(lo), float(hi)


def _maybe_known(values: Mapping[str, float] | None) -> Params | None:
    return None if values is None else _known(values)


def squareness_decision(tilts: Layout | None, tilts_in_model: bool
                        ) -> SquarenessDecision | None:
    """When an axis counts as leaning (what the advice and the report judge by):
    beyond k standard errors, k from Student's t on the tilts' dof for one false
    alarm in a thousand square machines over the three axes (the closed loop's
    rule, orthocal.loop.FALSE_ALARM), and only when the model test kept the tilts:
    a 95 % interval would send one square machine in seven to shim a rail."""
    if tilts is None:
        return None
    if not tilts_in_model:
        return SquarenessDecision(k=None, rule="the model test kept no tilt (none beyond "
                                               "the noise): no axis counts as leaning")
    k = orthocal.coverage_factor(tilts.dof, 1.0 - FALSE_ALARM)
    return SquarenessDecision(k=k, rule=f"an axis counts as leaning beyond {k:.2f} standard "
                                        f"errors (Student's t on {tilts.dof:g} dof: one false "
                                        "alarm in a thousand square machines)")


def model_export(config: StationConfig, *, drho_start: Mapping[str, float],
                 drho_start_cov: np.ndarray | None, drho_now: Mapping[str, float],
                 tilts: Layout | None, model: str, offsets_before: Mapping[str, float] | None,
                 offsets_written: Mapping[str, float] | None, dof: float | None
                 ) -> dict[str, object]:
    """model.json: the identified machine, for a controller or a tool that
    compensates kinematics (parameters, standard errors, covariance, conventions
    and units)."""
    m = config.machine
    cov = covariance(drho_start_cov, tilts)
    values = params(drho_start, tilts.vector() if tilts is not None else np.zeros(6))
    estimated = [n for n, c in zip(PARAM_NAMES, np.diag(cov), strict=True) if c > 0]
    idx = [PARAM_NAMES.index(n) for n in estimated]
    return {
        "format": "orthocal machine model 1",
        "geometry": {"leg_length_mm": m.leg_length, "rho_min_mm": m.rho_min,
                     "rho_max_mm": m.rho_max},
        "conventions": {
            "model": "docs/model.md (1'): leg i is a bar of length L + dL_i from the "
                     "carriage A_i = c_i + (rho_i + drho_i)·u_i to the end point P",
            "axes": "u_x = e_x; u_y = normalise(e_y + tilt_yx·e_x); u_z = normalise(e_z + "
                    "tilt_zx·e_x + tilt_zy·e_y) (tilts ×1e-3); the frame is fixed by u_x and "
                    "the x–y plane of u_x, u_y",
            "gaps": "c_x = (0, gap_xz/2, gap_xy/2), c_y = (gap_yz/2, 0, -gap_xy/2), c_z = "
                    "(-gap_yz/2, -gap_xz/2, 0): gap_xy is how far axis x passes axis y "
                    "along +z, gap_xz axis x past axis z along +y, gap_yz axis y past axis z "
                    "along +x; the origin midway between each pair of axes, drho in that "
                    "frame",
            "drho": "the joint zero error: commanded rho_i puts the carriage at rho_i + "
                    "drho_i; write-back sets o_i <- o_i - drho_i",
            "parameters": "drho at the start of the run (offsets_before); drho_now once "
                          "offsets_written were written",
        },
        "units": {"drho": "mm", "dL": "mm", "tilt": "mrad", "gap": "mm"},
        "model": model,
        "parameters": {n: float(v) for n, v in zip(PARAM_NAMES, values, strict=True)},
        "estimated": estimated,
        "not_estimated": {n: "taken as 0: not identifiable beside the tilts and gaps from "
                             "two postures per leg" if n.startswith("dL") else "taken as 0"
                          for n in PARAM_NAMES if n not in estimated},
        "std_errors": {n: float(math.sqrt(cov[PARAM_NAMES.index(n), PARAM_NAMES.index(n)]))
                       for n in estimated},
        "covariance": {"names": estimated,
                       "matrix": cov[np.ix_(idx, idx)].tolist()},
        "std_errors_dof": dof,
        "drho_now": {n: float(drho_now[n]) for n in DRHO},
        "offsets_before": None if offsets_before is None else dict(offsets_before),
        "offsets_written": None if offsets_written is None else dict(offsets_written),
    }
