"""Accuracy at the tool, as the run states it (design.md and model.md, "Accuracy
at the tool"): where the tool goes before and after the offsets written, with
95 % intervals, over the workspace, for both objectives; the squareness the
offsets cannot fix and what to do about it; the identified machine for export
(model.json).

The machine the run states is the one all its rounds measured: Δρ at the start
of the run is the run's statement (``remaining.total``), Δρ now is what the last
verification found left (``remaining.estimate``; the offsets written moved the
rest), and the tilts, which no offset changes, are pooled over every round's
rho+tilt fit (each round's misplaced stands are modelled; a round whose tilts
disagree with the others' beyond their uncertainty is left out and named). The
tilts are stated even when ``auto`` kept ``rho``: the figure then carries the
tilts the run could not rule out. ΔL is taken as 0 (not identifiable beside the
tilts from two postures per leg) and ``assumes`` says so.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import orthocal
from orthocal import AXES, PARAM_NAMES, TILT_NAMES
from orthocal.accuracy import error_field, optimal_offsets, squareness, workspace_grid
from orthocal.loop import FALSE_ALARM
from orthocal.numbers import finite
from orthocal.tool_interval import after_interval, assumes
from station.config import StationConfig

#: Grid nodes per axis of the workspace box (model.md's check values use 7³).
GRID_POINTS = 7
#: Consistency of one round's tilts with the others' (χ², 3 dof): below this
#: p-value the round is left out of the pool (the first round's stands).
POOL_LEVEL = 0.001
DRHO = tuple(f"drho_{a}" for a in AXES)


@dataclass(frozen=True)
class RoundTilts:
    """One round's rho+tilt fit: its phase, the tilts (mrad), their covariance,
    the dof of that covariance."""

    phase: str
    values: np.ndarray
    covariance: np.ndarray
    dof: float | None


@dataclass(frozen=True)
class Tilts:
    """The tilts the run states: pooled over ``rounds`` (inverse-covariance
    weights), ``dropped`` the rounds left out and why."""

    values: np.ndarray
    covariance: np.ndarray
    dof: float | None
    rounds: tuple[str, ...]
    dropped: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(TILT_NAMES, self.values, strict=True)}

    def std_errors(self) -> dict[str, float]:
        return {n: float(math.sqrt(max(v, 0.0))) for n, v
                in zip(TILT_NAMES, np.diag(self.covariance), strict=True)}


def round_tilts(phase: str, ident: Any) -> RoundTilts | None:
    """The tilts of a rho+tilt identification (None: it has none)."""
    names = list(ident.names)
    if not all(n in names for n in TILT_NAMES):
        return None
    idx = [names.index(n) for n in TILT_NAMES]
    cov = np.asarray(ident.covariance, dtype=float)[np.ix_(idx, idx)]
    if not np.all(np.isfinite(cov)):
        return None
    return RoundTilts(phase, np.array([ident.parameters[n] for n in TILT_NAMES]), cov,
                      finite(ident.std_error_dof))


def pool_tilts(rounds: Sequence[RoundTilts]) -> Tilts | None:
    """Inverse-covariance pooling of the rounds' tilts (they do not change with the
    offsets). A round inconsistent with the pool of the others (χ² test at
    POOL_LEVEL) is left out: the first round's misplaced stands bias it most."""
    from scipy.stats import chi2

    kept = list(rounds)
    dropped: list[str] = []
    while len(kept) >= 2:
        worst, worst_p = None, 1.0
        for r in kept:
            others = pool_tilts([o for o in kept if o is not r])
            assert others is not None
            d = r.values - others.values
            p = float(chi2.sf(float(d @ np.linalg.solve(r.covariance + others.covariance, d)),
                              3))
            if p < worst_p:
                worst, worst_p = r, p
        if worst is None or worst_p >= POOL_LEVEL:
            break
        kept.remove(worst)
        dropped.append(f"{worst.phase} (its tilts disagree with the other rounds', "
                       f"p = {worst_p:.1e})")
    if not kept:
        return None
    info = sum(np.linalg.inv(r.covariance) for r in kept)
    cov = np.linalg.inv(info)
    values = cov @ sum(np.linalg.solve(r.covariance, r.values) for r in kept)
    dofs = [r.dof for r in kept if r.dof is not None]
    return Tilts(values, cov, float(sum(dofs)) if len(dofs) == len(kept) else None,
                 tuple(r.phase for r in kept), tuple(dropped))


def params(drho: Mapping[str, float] | Sequence[float], tilts: np.ndarray) -> np.ndarray:
    """The 9-vector of PARAM_NAMES: Δρ, ΔL = 0, the tilts."""
    d = [float(drho[n]) for n in DRHO] if isinstance(drho, Mapping) else list(drho)
    return np.array([*d, 0.0, 0.0, 0.0, *tilts], dtype=float)


def grid(config: StationConfig, limits: tuple[Any, Any] | None) -> Any:
    """The workspace grid (soft limits excluded)."""
    return workspace_grid(config.machine.workspace_box(), GRID_POINTS,
                          config.machine.geometry(), limits)


def tool_target(config: StationConfig, tilts: Tilts | None, points: np.ndarray
                ) -> dict[str, float]:
    """The joint errors Δρ that leave the least RMS tool error over ``points`` in
    the configured frame for a machine with these tilts (ΔL = 0): the target of
    objective "tool" (orthocal.accuracy.optimal_offsets with Δρ = 0: its offsets
    are the joint errors to aim at). Zero without tilts."""
    if tilts is None:
        return dict.fromkeys(DRHO, 0.0)
    best = optimal_offsets(points, config.machine.geometry(), params((0, 0, 0), tilts.values),
                           config.writeback.frame,
                           max_abs_offset_mm=config.writeback.max_abs_offset_mm)
    return {n: float(v) for n, v in zip(DRHO, best.offsets, strict=True)}


def _stats(field: Any) -> dict[str, float]:
    return {"rms_mm": float(field.rms_mm), "max_mm": float(field.max_mm)}


def _covariance(now_cov: np.ndarray | None, tilts: Tilts | None) -> np.ndarray:
    """9×9: Δρ now (the last round's) and the pooled tilts; the two come from
    different fits and are taken as independent."""
    cov = np.zeros((len(PARAM_NAMES), len(PARAM_NAMES)))
    if now_cov is not None:
        cov[:3, :3] = now_cov
    if tilts is not None:
        cov[6:, 6:] = tilts.covariance
    return cov


def statement(config: StationConfig, limits: tuple[Any, Any] | None, *,
              drho_start: Mapping[str, float], drho_now: Mapping[str, float],
              drho_now_cov: np.ndarray | None, dof: float | None, tilts: Tilts | None,
              model: str, tilts_in_model: bool, offsets_before: Mapping[str, float] | None,
              target_tool: Mapping[str, float]) -> dict[str, Any]:
    """The run JSON's ``accuracy`` (design.md): before and after over the workspace
    with 95 % intervals for the after-figures, both objectives' predicted after-
    figures side by side, squareness with what to do, what it all assumes."""
    geometry = config.machine.geometry()
    g = grid(config, limits)
    points = g.points
    frame = config.writeback.frame
    tilt_v = tilts.values if tilts is not None else np.zeros(3)
    zero = np.zeros(3)
    before = error_field(points, geometry, params(drho_start, tilt_v), zero, frame)
    cov = _covariance(drho_now_cov, tilts)
    after = after_interval(params(drho_now, tilt_v), cov, dof, zero, points, geometry, frame)
    # Each objective's offsets written exactly: the machine's Δρ at its target.
    objectives = {}
    for name, target in (("joints", dict.fromkeys(DRHO, 0.0)), ("tool", target_tool)):
        fld = error_field(points, geometry, params(target, tilt_v), zero, frame)
        registers = None if offsets_before is None else {
            a: float(offsets_before[a]) - (float(drho_start[f"drho_{a}"])
                                           - float(target[f"drho_{a}"])) for a in AXES}
        objectives[name] = {"after": _stats(fld), "offsets_mm": registers,
                            "target_drho_mm": {n: float(target[n]) for n in DRHO}}
    chosen = config.writeback.objective
    other = "tool" if chosen == "joints" else "joints"
    sq = squareness(params(drho_now, tilt_v), geometry, offsets=zero, covariance=cov)
    sq_values, sq_se = sq.as_dict(), sq.std_errors_dict() or {}
    tilt_interval = None
    if tilts is not None and not tilts_in_model:
        k = orthocal.coverage_factor(tilts.dof)
        tilt_interval = {n: (v - k * s, v + k * s) for (n, v), s in
                         zip(tilts.as_dict().items(), tilts.std_errors().values(),
                             strict=True)}
    words = assumes("rho+tilt" if tilts is not None else "rho", frame)
    if tilts is not None:
        source = ", ".join(tilts.rounds)
        words.insert(0, f"tilts as the rho+tilt fits of round(s) {source} put them, pooled "
                        "(they do not change with the offsets)"
                     + ("" if tilts_in_model else
                        f"; the model test kept {model!r}, so they are not significant, and "
                        "the intervals include them")
                     + (f"; left out: {'; '.join(tilts.dropped)}" if tilts.dropped else ""))
    rail = config.machine.rho_max - config.machine.rho_min
    decision = squareness_decision(tilts, tilts_in_model)
    return {
        "workspace_mm": config.machine.workspace_box(),
        "grid": {"points_per_axis": GRID_POINTS, "points": len(points),
                 "excluded": int(g.excluded)},
        "frame": frame, "objective": chosen,
        "before": _stats(before),
        "after": after.to_dict(),
        "after_method": after.method,
        "objectives": objectives,
        "alternative": {"objective": other, **objectives[other]},
        "squareness_mm_per_m": sq_values,
        "squareness_std_errors": sq_se,
        "squareness_decision": decision,
        "squareness_advice": squareness_advice(tilts, rail, decision),
        "tilts": None if tilts is None else tilts.as_dict(),
        "tilt_std_errors": None if tilts is None else tilts.std_errors(),
        "tilt_interval_95": None if tilt_interval is None else
        {n: [float(lo), float(hi)] for n, (lo, hi) in tilt_interval.items()},
        "field": {"points_mm": np.round(points, 4).tolist(),
                  "before_mm": np.round(before.field, 6).tolist(),
                  "after_mm": np.round(after.field.field, 6).tolist()},
        "assumes": words,
    }


_LEANS = {"tilt_yx": ("y", "x"), "tilt_zx": ("z", "x"), "tilt_zy": ("z", "y")}


def squareness_decision(tilts: Tilts | None, tilts_in_model: bool) -> dict[str, Any] | None:
    """When an axis counts as leaning (what the advice and the report judge by):
    beyond k standard errors, k from Student's t on the tilts' dof for one false
    alarm in a thousand square machines over the three axes (the closed loop's
    rule, orthocal.loop.FALSE_ALARM), and only when the model test kept the tilts:
    a 95 % interval would send one square machine in seven to shim a rail."""
    if tilts is None:
        return None
    if not tilts_in_model:
        return {"k": None, "rule": "the model test kept no tilt (none beyond the noise): "
                                   "no axis counts as leaning"}
    k = orthocal.coverage_factor(tilts.dof, 1.0 - FALSE_ALARM)
    return {"k": k, "rule": f"an axis counts as leaning beyond {k:.2f} standard errors "
                            f"(Student's t on "
                            f"{tilts.dof:g} dof: one false alarm in a thousand square "
                            "machines)"}


def squareness_advice(tilts: Tilts | None, rail_mm: float,
                      decision: Mapping[str, Any] | None) -> list[str]:
    """What to do about each axis that leans (``decision``: squareness_decision's; the tilts, the
    axes' own: the squareness of the tool's motions also holds what the offsets
    written shear them by): shim the rail (tilt × its travel) or compensate in the
    controller's kinematics (model.json holds the machine)."""
    if tilts is None:
        return ["the tilts were not identified: squareness not stated"]
    k = orthocal.coverage_factor(tilts.dof)
    k_decide = None if decision is None else decision["k"]
    out = []
    for (name, value), se in zip(tilts.as_dict().items(), tilts.std_errors().values(),
                                 strict=True):
        axis, toward = _LEANS[name]
        if k_decide is None or abs(value) <= k_decide * se:
            why = "the model test kept no tilt" if k_decide is None else \
                f"not beyond {k_decide:.2f} standard errors"
            out.append(f"axis {axis} toward {toward} ({name}): {value:+.3f} ± {k * se:.3f} "
                       f"mm/m (95 %), {why}: nothing to do")
            continue
        shim = abs(value) * rail_mm / 1000.0
        out.append(f"axis {axis} leans {'toward +' if value > 0 else 'away from +'}{toward} "
                   f"by {abs(value):.3f} ± {k * se:.3f} mm/m ({name}): offsets cannot fix "
                   f"it; shim its rail by {1000 * shim:.0f} µm over its {rail_mm:g} mm of "
                   "travel, or compensate in the controller's kinematics (model.json)")
    return out


def model_export(config: StationConfig, *, drho_start: Mapping[str, float],
                 drho_start_cov: np.ndarray | None, drho_now: Mapping[str, float],
                 tilts: Tilts | None, model: str, offsets_before: Mapping[str, float] | None,
                 offsets_written: Mapping[str, float] | None, dof: float | None
                 ) -> dict[str, Any]:
    """model.json: the identified machine, for a controller or a tool that
    compensates kinematics (parameters, standard errors, covariance, conventions
    and units)."""
    m = config.machine
    cov = _covariance(drho_start_cov, tilts)
    values = params(drho_start, tilts.values if tilts is not None else np.zeros(3))
    estimated = [n for n, c in zip(PARAM_NAMES, np.diag(cov), strict=True) if c > 0]
    idx = [PARAM_NAMES.index(n) for n in estimated]
    return {
        "format": "orthocal machine model 1",
        "geometry": {"leg_length_mm": m.leg_length, "rho_min_mm": m.rho_min,
                     "rho_max_mm": m.rho_max},
        "conventions": {
            "model": "model.md (1'): leg i is a bar of length L + dL_i from the carriage "
                     "A_i = (rho_i + drho_i)·u_i to the end point P",
            "axes": "u_x = e_x; u_y = normalise(e_y + tilt_yx·e_x); u_z = normalise(e_z + "
                    "tilt_zx·e_x + tilt_zy·e_y) (tilts ×1e-3); the frame is fixed by u_x and "
                    "the x–y plane of u_x, u_y",
            "drho": "the joint zero error: commanded rho_i puts the carriage at rho_i + "
                    "drho_i; write-back sets o_i <- o_i - drho_i",
            "parameters": "drho at the start of the run (offsets_before); drho_now once "
                          "offsets_written were written",
        },
        "units": {"drho": "mm", "dL": "mm", "tilt": "mrad"},
        "model": model,
        "parameters": {n: float(v) for n, v in zip(PARAM_NAMES, values, strict=True)},
        "estimated": estimated,
        "not_estimated": {n: "taken as 0: not identifiable beside the tilts from two "
                             "postures per leg" if n.startswith("dL") else "taken as 0"
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
