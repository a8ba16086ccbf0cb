"""One run as a history entry, from its result.json alone (docs/design.md, "Machine
history").

Δρ depends on the offsets the controller held when it was measured: writing o' for o
moves it by o' − o (a correction o ← o − Δρ̂ leaves Δρ ≈ 0). What belongs to the
machine, and can be compared between runs whatever was written in between, is the
joint error in the controller's zero frame, e = Δρ − o (mm, per axis): as found, from
the run's statement of Δρ at its start (``remaining.total`` where a verification
measured after the last write, else the first identification) and its offsets
before; as left, from the last verification's estimate and the offsets it measured
with (those the run wrote; a rollback does not change the machine's e). Each state
also says what the machine runs with: ``drho_mm``, Δρ = e + o with the offsets it
held then (``offsets_mm``): as found the offsets before, as left those the run left
(``offsets_final``), so that a run left at +1.2 µm says +1.2 µm as left, and a
rolled-back run, whose offsets are back as found, says its as-found Δρ again.

Where the run states the machine (result.json ``statement``: docs/design.md, "The
statement of the machine"), every value and uncertainty the entry keeps is the
statement's: as found from ``drho_*.as_found``, as left from ``drho_*.as_left``, the
tilts and gaps, each joint's reversal, the tool after; each with its expanded
uncertainty, k, dof and the contributions of its sources, which ``compare`` combines
(station.history.compare). A record from before the statement keeps the legacy reading
(``remaining``, the budget, the accuracy block), below."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from orthocal import AXES
from orthocal.between_runs import TYPE_A
from station.record.result import RunResult
from station.record.result_base import Axis3, NotStated, Params
from station.record.result_statement import Quantity


def _frame(drho: Params, se: Params, offsets: Axis3 | None, dof: float | None,
           certificate: Mapping[str, float | None] | None = None,
           held: Axis3 | None = None) -> dict[str, Any] | None:
    """Per axis e = Δρ − o (``offsets``: those Δρ was measured with) with Δρ's
    standard error, and ``certificate``'s expanded uncertainty of Δρ where it states
    one (o is exact: e's is Δρ's); and Δρ = e + o with the offsets ``held`` (default
    ``offsets``) as ``drho_mm``. None when any value is missing."""
    if offsets is None:
        return None
    held = offsets if held is None else held
    out: dict[str, Any] = {}
    runs_with: dict[str, Any] = {}
    for a in AXES:
        d, s, o, h = drho.get(f"drho_{a}"), se.get(f"drho_{a}"), offsets.get(a), held.get(a)
        if d is None or o is None or h is None:
            return None
        out[a] = {"value_mm": d - o, "std_error_mm": s}
        runs_with[a] = {"value_mm": d - o + h, "std_error_mm": s}
        expanded = (certificate or {}).get(f"drho_{a}")
        if expanded is not None:
            out[a]["expanded_95_mm"] = expanded
    return {"joint_error_mm": out, "drho_mm": runs_with, "offsets_mm": dict(held),
            "dof": dof}


def _certificate(result: RunResult, statement: str) -> Params:
    """The run's certificate figure per parameter: the uncertainty budget's expanded
    uncertainty (Type A and B, docs/design.md "Uncertainty budget"), where the budget
    states the same Δρ as ``statement`` (``remaining.total`` or ``identified``); else
    none, and the history falls back to the statistical interval, saying so."""
    budget = result.uncertainty_budget
    if budget is None or isinstance(budget, NotStated) or budget.statement != statement:
        return {}
    return budget.expanded_95_mm


def _stated_value(q: Quantity, value: float, key: str = "") -> dict[str, Any]:
    """A statement's quantity as the entry keeps it: ``value`` (in the quantity's frame:
    e = Δρ − o for a joint) under ``value{key}``, its Type A part as the standard error
    the drift weighs by, its expanded uncertainty, k, dof, decision and the standard
    contribution of each source (what compare combines)."""
    contributions = dict(q.contributions or {})
    return {f"value{key}": value, f"std_error{key}": contributions.get(TYPE_A),
            f"expanded_95{key}": q.expanded, "k": q.k, "dof": q.dof,
            "decision": q.decision, f"contributions{key}": contributions, "stated": True}


def _stated_frame(result: RunResult, state: str, offsets: Axis3 | None,
                  held: Axis3 | None) -> dict[str, Any] | None:
    """:func:`_frame` from the statement's ``drho_*.<state>`` (None where any is
    missing): e = Δρ − o with the offsets Δρ was stated with, Δρ = e + o with those
    ``held``."""
    q = stated(result)
    if offsets is None or held is None:
        return None
    out: dict[str, Any] = {}
    runs_with: dict[str, Any] = {}
    for a in AXES:
        x, o, h = q.get(f"drho_{a}.{state}"), offsets.get(a), held.get(a)
        if x is None or x.value is None or o is None or h is None:
            return None
        out[a] = _stated_value(x, x.value - o, "_mm")
        runs_with[a] = _stated_value(x, x.value - o + h, "_mm")
    return {"joint_error_mm": out, "drho_mm": runs_with, "offsets_mm": dict(held),
            "dof": None, "stated": True}


def stated(result: RunResult) -> dict[str, Quantity]:
    """The record's statement by name (empty for a record from before it)."""
    return {q.name: q for q in result.statement or []}


def _layout(result: RunResult) -> dict[str, Any]:
    q = stated(result)
    if q:
        return {n: _stated_value(x, x.value) for n, x in q.items()
                if n.startswith(("tilt_", "gap_")) and x.value is not None}
    acc = result.accuracy
    out: dict[str, Any] = {}
    if acc is None or isinstance(acc, NotStated):
        return out
    for got, ses, intervals in ((acc.tilts, acc.tilt_std_errors, acc.tilt_interval_95),
                                (acc.gaps, acc.gap_std_errors, acc.gap_interval_95)):
        for name, value in (got or {}).items():
            if value is None:
                continue
            out[name] = {"value": value, "std_error": (ses or {}).get(name)}
            # the run's own 95 % interval (Student's t on its dof), as a half-width
            pair = (intervals or {}).get(name)
            if pair is not None:
                out[name]["interval_95"] = (pair[1] - pair[0]) / 2.0
    return out


def _reversal(result: RunResult) -> dict[str, Any]:
    """Each joint's lost motion as the run states it (mm, with its standard error, and
    with a statement its expanded uncertainty and decision)."""
    q = stated(result)
    if any(n.startswith("reversal_") for n in q):
        return {a: _stated_value(x, x.value, "_mm") for a in AXES
                if (x := q.get(f"reversal_{a}")) is not None and x.value is not None}
    rev = result.reversal
    if rev is None:
        return {}
    return {a: {"value_mm": value, "std_error_mm": rev.std_errors_mm.get(a)}
            for a in AXES if (value := rev.value_mm.get(a)) is not None}


def _instruments(result: RunResult) -> list[dict[str, Any]]:
    """The gauges by what identifies them (their serials, where the config gives them)."""
    budget = result.uncertainty_budget
    if budget is None or isinstance(budget, NotStated):
        return []
    return [{"name": i.name, "protocol": i.protocol, "serial": i.serial}
            for i in budget.instruments]


def _as_found(result: RunResult) -> dict[str, Any] | None:
    """e at the run's start: the statement's Δρ as found; a record from before it:
    from ``remaining.total`` where a verification measured after the last write, else
    from the first identification."""
    if stated(result):
        return _stated_frame(result, "as_found", result.offsets_before,
                             result.offsets_before)
    rem = result.remaining
    if rem is not None and rem.total:
        return _frame(rem.total, rem.std_errors, result.offsets_before, rem.std_errors_dof,
                      _certificate(result, "remaining.total"))
    return _frame(result.identified, result.std_errors, result.offsets_before,
                  result.std_errors_dof, _certificate(result, "identified"))


def _as_left(result: RunResult) -> dict[str, Any] | None:
    """The machine as the run left it: e from the last verification's estimate under
    the offsets it measured with (those the run wrote, which a rollback since replaced
    are its first ``replaced``), and Δρ with the offsets the run left (offsets_final:
    after a rollback, the restored ones, so Δρ is back as found)."""
    rem = result.remaining
    if rem is None or not rem.estimate:
        return None
    backs = result.rollback_history()
    measured_with = backs[0].replaced if backs else result.offsets_final
    if stated(result):
        return _stated_frame(result, "as_left", measured_with, result.offsets_final)
    return _frame(rem.estimate, rem.std_errors, measured_with, rem.std_errors_dof,
                  held=result.offsets_final)


def entry_of(result: RunResult, profile: str | None = None) -> dict[str, Any]:
    """The history entry of a finished run's ``result`` (its result.json, as the
    record); ``profile``: the register map its controller used (from its config)."""
    machine, acc = result.machine, result.accuracy
    back = result.rolled_back
    # the tool as the run left it: after a rollback, as it was found
    tool = stated(result).get(f"tool.{'before' if back is not None else 'after'}.rms")
    after = tool.value if tool is not None else None if acc is None or \
        isinstance(acc, NotStated) else acc.before.rms_mm if back is not None else \
        acc.after.rms_mm
    return {
        "run_dir": result.run_dir, "machine_id": machine.id,
        "started": result.started, "finished": result.finished,
        "status": result.status, "stopped": None if result.loop is None else result.loop.stopped,
        "model": result.model, "converged": bool(result.converged),
        "geometry": {"leg_length": machine.leg_length, "rho_min": machine.rho_min,
                     "rho_max": machine.rho_max},
        "profile": profile,
        "offsets_before": result.offsets_before,
        "offsets_final": result.offsets_final,
        # orthocal rollback: the last (when, the offsets it replaced and restored), and
        # every one in turn
        "rolled_back": None if back is None else back.model_dump(mode="json"),
        "rollbacks": [b.model_dump(mode="json") for b in result.rollback_history()],
        "as_found": _as_found(result), "as_left": _as_left(result), "layout": _layout(result),
        "tool_after_rms_mm": after,
        "reversal": _reversal(result), "instruments": _instruments(result),
    }


def profile_of(run_dir: Path) -> str | None:
    """The register map the run's controller used, from its config.toml (here, not
    in store.py: `orthocal compare` and `export` read it without SQLAlchemy)."""
    import tomllib

    try:
        data = tomllib.loads((Path(run_dir) / "config.toml").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    profile = (data.get("controller") or {}).get("profile")
    return str(profile) if profile is not None else None
