"""One run as a history entry, from its result.json alone (docs/design.md, "Machine
history").

Δρ depends on the offsets the controller held when it was measured: writing o' for o
moves it by o' − o (a correction o ← o − Δρ̂ leaves Δρ ≈ 0). What belongs to the
machine, and can be compared between runs whatever was written in between, is the
joint error in the controller's zero frame, e = Δρ − o (mm, per axis): as found, from
the run's statement of Δρ at its start (``remaining.total`` where a verification
measured after the last write, else the first identification) and its offsets
before; as left, from the last verification's estimate and the offsets the run left
(``offsets_final``; after ``orthocal rollback``, those it replaced, under which the
verification measured: the entry's ``rolled_back`` says so). Tilts and gaps need no
frame: offsets do not move them."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from orthocal import AXES


def _num(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) \
        else None


def _mapping(value: Any) -> Mapping[str, Any]:
    """``value`` where it is a mapping, else an empty one (a key missing or malformed)."""
    return value if isinstance(value, Mapping) else {}


def _frame(drho: Mapping[str, Any], se: Mapping[str, Any], offsets: Mapping[str, Any] | None,
           dof: Any, certificate: Mapping[str, Any] | None = None) -> dict[str, Any] | None:
    """Per axis e = Δρ − o with Δρ's standard error, and ``certificate``'s expanded
    uncertainty of Δρ where it states one (o is exact: e's is Δρ's); None when any
    value is missing."""
    if not isinstance(offsets, Mapping):
        return None
    out: dict[str, Any] = {}
    for a in AXES:
        d, s, o = _num(drho.get(f"drho_{a}")), _num(se.get(f"drho_{a}")), _num(offsets.get(a))
        if d is None or o is None:
            return None
        out[a] = {"value_mm": d - o, "std_error_mm": s}
        expanded = _num((certificate or {}).get(f"drho_{a}"))
        if expanded is not None:
            out[a]["expanded_95_mm"] = expanded
    return {"joint_error_mm": out, "dof": _num(dof)}


def _certificate(result: Mapping[str, Any], statement: str) -> Mapping[str, Any]:
    """The run's certificate figure per parameter: the uncertainty budget's expanded
    uncertainty (Type A and B, docs/design.md "Uncertainty budget"), where the budget
    states the same Δρ as ``statement`` (``remaining.total`` or ``identified``); else
    none, and the history falls back to the statistical interval, saying so."""
    budget = _mapping(result.get("uncertainty_budget"))
    if budget.get("statement") != statement:
        return {}
    return _mapping(budget.get("expanded_95_mm"))


def _layout(result: Mapping[str, Any]) -> dict[str, Any]:
    acc = _mapping(result.get("accuracy"))
    out: dict[str, Any] = {}
    for kind in ("tilt", "gap"):
        got = _mapping(acc.get(f"{kind}s"))
        ses = _mapping(acc.get(f"{kind}_std_errors"))
        intervals = _mapping(acc.get(f"{kind}_interval_95"))
        for name, value in got.items():
            if _num(value) is not None:
                out[name] = {"value": float(value), "std_error": _num(ses.get(name))}
                # the run's own 95 % interval (Student's t on its dof), as a half-width
                pair = intervals.get(name)
                if isinstance(pair, list) and len(pair) == 2 and \
                        all(_num(x) is not None for x in pair):
                    out[name]["interval_95"] = (float(pair[1]) - float(pair[0])) / 2.0
    return out


def _reversal(result: Mapping[str, Any]) -> dict[str, Any]:
    """Each joint's lost motion as the run measured it (mm, with its standard error)."""
    rev = _mapping(result.get("reversal"))
    values = _mapping(rev.get("value_mm"))
    ses = _mapping(rev.get("std_errors_mm"))
    return {a: {"value_mm": _num(values.get(a)), "std_error_mm": _num(ses.get(a))}
            for a in AXES if _num(values.get(a)) is not None}


def _instruments(result: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The gauges by what identifies them (their serials, where the config gives them)."""
    budget = result.get("uncertainty_budget")
    found = budget.get("instruments") if isinstance(budget, Mapping) else None
    return [{"name": i.get("name"), "protocol": i.get("protocol"), "serial": i.get("serial")}
            for i in (found if isinstance(found, list) else []) if isinstance(i, Mapping)]


def entry_of(result: Mapping[str, Any], profile: str | None = None) -> dict[str, Any]:
    """The history entry of a finished run's ``result`` (its result.json);
    ``profile``: the register map its controller used (from its config)."""
    machine = _mapping(result.get("machine"))
    rem = _mapping(result.get("remaining"))
    found_drho = rem.get("total") or result.get("identified") or {}
    found_se = rem.get("std_errors") if rem.get("total") else result.get("std_errors") or {}
    found_dof = rem.get("std_errors_dof") if rem.get("total") else result.get("std_errors_dof")
    statement = "remaining.total" if rem.get("total") else "identified"
    as_found = _frame(found_drho, found_se or {}, result.get("offsets_before"), found_dof,
                      _certificate(result, statement))
    # the offsets the last verification measured with: offsets_final, unless a
    # rollback has since replaced them (e is the machine's own, whatever is held now)
    back = _mapping(result.get("rolled_back"))
    as_left = None if not rem.get("estimate") else _frame(
        rem["estimate"], rem.get("std_errors") or {},
        back.get("replaced") if back else result.get("offsets_final"),
        rem.get("std_errors_dof"))
    acc = _mapping(result.get("accuracy"))
    after = _mapping(acc.get("after"))
    loop = _mapping(result.get("loop"))
    return {
        "run_dir": str(result.get("run_dir")), "machine_id": machine.get("id"),
        "started": result.get("started"), "finished": result.get("finished"),
        "status": result.get("status"), "stopped": loop.get("stopped"),
        "model": result.get("model"), "converged": bool(result.get("converged")),
        "geometry": {k: machine.get(k) for k in ("leg_length", "rho_min", "rho_max")},
        "profile": profile,
        "offsets_before": result.get("offsets_before"),
        "offsets_final": result.get("offsets_final"),
        # orthocal rollback: when, and the offsets it replaced and restored
        "rolled_back": back or None,
        "as_found": as_found, "as_left": as_left, "layout": _layout(result),
        "tool_after_rms_mm": _num(after.get("rms_mm")),
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
