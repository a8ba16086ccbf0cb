"""What changed between two runs of one machine (docs/design.md, "Machine history"):
A's machine as left against B's as found, per axis in the controller's zero frame
(station.history.entry), and the tilts and gaps; each change with its 95 % expanded
uncertainty and whether it stands out of it.

Where both runs state the machine (their entries keep each quantity's parts), the
change's uncertainty combines the two as the GUM combines a difference of correlated
estimates (orthocal.between_runs, docs/model.md "The change between two runs"): each
run's scatter (Type A) independent; the legs' straightness, the one stated input that
is the machine's own and the same in both runs, fully correlated, so that what it puts
on both values cancels in the change but for the difference of its two parts; every
other Type B input (each round's temperature, each mounting's gauge error and plunger
angle) independent; a bound a run added whole (tilts or bows) added whole again. An
entry from before the statement keeps its standard error alone (legacy)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from orthocal import coverage_factor
from orthocal.between_runs import Stated, of_statement
from orthocal.between_runs import change as combined
from station.errors import say
from station.history.trend import started_at
from station.record.io import section, validated
from station.record.quantity_text import plus_minus
from station.record.result import RunResult
from station.record.result_sections import NotCompared, SinceLast
from station.record.result_statement import Quantity, Unit

#: The Type B sources two runs of one machine share, fully correlated: the same legs
#: read at the same gauge planes (the stands set at the legs' middles). A gauge's MPE,
#: the plunger angle (per mounting) and a temperature change (per round) are each
#: run's own.
COMMON = ("leg straightness",)


class Incomparable(ValueError):
    """The two runs are not of one machine set up alike (said in one line)."""


def check_comparable(a: Mapping[str, Any], b: Mapping[str, Any]) -> None:
    if a.get("run_dir") == b.get("run_dir"):
        # One run against itself: every change exactly zero, every one "not
        # significant", which says nothing about the machine.
        raise Incomparable(f"A and B are the same run ({a.get('run_dir')}): give two runs "
                           "of one machine")
    for label, entry in (("A", a), ("B", b)):
        if not entry.get("machine_id"):
            raise Incomparable(f"run {label} ({entry.get('run_dir')}) names no machine: set "
                               "[machine] id so that runs of one machine can be compared")
    if a["machine_id"] != b["machine_id"]:
        raise Incomparable(f"different machines: A is {a['machine_id']!r}, "
                           f"B is {b['machine_id']!r}")
    if a.get("geometry") != b.get("geometry"):
        raise Incomparable(f"different geometry: A {a.get('geometry')}, B {b.get('geometry')}")
    if a.get("profile") != b.get("profile"):
        raise Incomparable(f"different register maps: A {a.get('profile')!r}, "
                           f"B {b.get('profile')!r}")


def _parts(v: Mapping[str, Any], key: str, dof: float | None) -> Stated | None:
    """An entry's value as its uncertainty's parts: the statement's where the entry
    keeps them, else (legacy) its standard error alone on ``dof``; None where it has
    no uncertainty."""
    value = v[f"value{key}"]
    contributions = v.get(f"contributions{key}")
    expanded, k = v.get(f"expanded_95{key}"), v.get("k")
    if contributions and expanded is not None and k is not None:
        return of_statement(value, expanded, k, v.get("dof"), contributions)
    se = v.get(f"std_error{key}")
    return None if se is None else Stated(value, se, dof)


def _half(v: Mapping[str, Any], key: str) -> float | None:
    """The 95 % half-width an entry's value was stated with (None: not stated)."""
    return v.get(f"expanded_95{key}") if v.get("stated") else None


def _change(va: Mapping[str, Any], vb: Mapping[str, Any], key: str,
            dof: float | None = None) -> dict[str, Any]:
    """One parameter's change from ``va`` (run A) to ``vb`` (run B), ``key`` the unit
    suffix of their values ("_mm" for the joints, "" for the layout); ``dof`` a legacy
    entry's (the smaller of the two runs'; None: the normal's k)."""
    before, after = va[f"value{key}"], vb[f"value{key}"]
    out: dict[str, Any] = {"before": before, "after": after, "change": after - before,
                           "before_expanded": _half(va, key), "after_expanded": _half(vb, key)}
    a, b = _parts(va, key, dof), _parts(vb, key, dof)
    if a is None or b is None:
        return {**out, "std_error": None, "interval_95": None, "k": None, "dof": None,
                "significant": None}
    if not a.type_b and not b.type_b and a.whole == 0.0 == b.whole:
        # legacy: two standard errors, independent, k from Student's t on ``dof``
        se = math.hypot(a.u_a, b.u_a)
        k = coverage_factor(dof, 0.95)
        return {**out, "std_error": se, "interval_95": k * se, "k": k, "dof": dof,
                "significant": abs(after - before) > k * se}
    c = combined(a, b, COMMON)
    return {**out, "std_error": c.u_c, "interval_95": c.expanded, "k": c.k, "dof": c.dof,
            "significant": c.significant}


def compare(a: Mapping[str, Any], b: Mapping[str, Any]) -> dict[str, Any]:
    """Changes from history entry ``a`` (earlier) to ``b``: joint errors (A as left, or
    as found where it left nothing measured, against B as found) and the layout."""
    check_comparable(a, b)
    left = a.get("as_left") or a.get("as_found")
    found = b.get("as_found")
    joints: dict[str, Any] = {}
    if left and found:
        dofs = [d for d in (left.get("dof"), found.get("dof")) if d]
        dof = min(dofs) if dofs else None
        for axis, va in left["joint_error_mm"].items():
            joints[axis] = _change(va, found["joint_error_mm"][axis], "_mm", dof)
    layout = {name: _change(va, b["layout"][name], "")
              for name, va in (a.get("layout") or {}).items()
              if name in (b.get("layout") or {})}
    return {"machine_id": a["machine_id"], "a": a["run_dir"], "b": b["run_dir"],
            "a_state": "as left" if a.get("as_left") else "as found",
            "changes": changes(joints, layout), "joint_error_mm": joints, "layout": layout}


def changes(joints: dict[str, Any], layout: dict[str, Any]) -> dict[str, Any]:
    """Per parameter (docs/model.md's names) the change with its unit in the key:
    ``change_mm``/``change_mrad``, ``expanded_95_…`` and ``significant``. A joint's
    change is that of Δρ in the controller's zero frame (Δρ − o): the machine's own."""
    out: dict[str, Any] = {}
    for axis, c in joints.items():
        out[f"drho_{axis}"] = {"change_mm": c["change"], "expanded_95_mm": c["interval_95"],
                               "std_error_mm": c["std_error"], "significant": c["significant"]}
    for name, c in layout.items():
        unit = "mm" if name.startswith("gap") else "mrad"
        out[name] = {f"change_{unit}": c["change"], f"expanded_95_{unit}": c["interval_95"],
                     f"std_error_{unit}": c["std_error"], "significant": c["significant"]}
    return out


def microns(value: float | None, signed: bool = True) -> str:
    """A length in mm shown in µm to 0.1 µm, whatever its size (``orthocal history``'s
    columns: a joint's e, about −o on a calibrated machine, is thousands: −1818.6); —
    where not stated."""
    return "—" if value is None else f"{1000 * value:{'+' if signed else ''}.1f}"


#: What ``significant`` means, said once under a comparison's lines.
CRITERION = ("significant: the change lies beyond its 95 % expanded uncertainty U, the two "
             "runs' combined as the GUM combines a difference (each run's scatter "
             "independent, the legs' straightness common to both and fully correlated, "
             "every other stated input independent; a run from before the statement: its "
             "standard error alone, k from Student's t on the smaller dof). Joints as "
             "e = Δρ − o, each joint's zero error without the controller's offsets "
             "(history's legend); each value printed as every view prints a quantity.")


def _significance(flag: bool | None) -> str:
    if flag is None:
        return "significance unknown (no uncertainty)"
    return "significant" if flag else "not significant"


def quantity(name: str, unit: Unit, value: float, expanded: float | None) -> Quantity:
    """A value with its 95 % expanded uncertainty as a quantity, for quantity_text to
    print the one way every view prints it."""
    return Quantity(name=name, value=value, unit=unit, expanded=expanded, interval_95=None,
                    k=None, dof=None, decision=None, basis=[])


def said(c: Mapping[str, Any], name: str, unit: Unit) -> tuple[str, str, str]:
    """(before, after, change) of a comparison's ``c``, each printed by quantity_text:
    each run's value with the ± it was stated with, the change with its U."""
    return (plus_minus(quantity(name, unit, c["before"], c.get("before_expanded"))),
            plus_minus(quantity(name, unit, c["after"], c.get("after_expanded"))),
            plus_minus(quantity(name, unit, c["change"], c.get("interval_95"))))


def change_lines(doc: Mapping[str, Any]) -> list[str]:
    """One line per parameter of a comparison (``compare``'s ``joint_error_mm`` and
    ``layout``): before → after (each with its stated ±), the change ± its 95 %
    expanded uncertainty, and whether it is significant (CRITERION), each printed by
    station.record.quantity_text (a length below 0.1 mm in µm, above in mm with its ±
    in µm; a tilt in mrad to 0.001)."""
    rows: list[list[str]] = []
    for axis, c in (doc.get("joint_error_mm") or {}).items():
        rows.append([f"joint {axis} e", *said(c, f"e_{axis}", "mm"),
                     _significance(c["significant"])])
    for name, c in (doc.get("layout") or {}).items():
        unit: Unit = "mm" if name.startswith("gap") else "mrad"
        rows.append([name, *said(c, name, unit), _significance(c["significant"])])
    for r in rows:
        r[3] += " (95 %)"
    widths = [max((len(r[i]) for r in rows), default=0) for i in range(4)]
    return [f"{r[0]:<{widths[0]}}  {r[1]:>{widths[1]}} → {r[2]:>{widths[2]}}  change "
            f"{r[3]:<{widths[3]}}  {r[4]}" for r in rows]


def since_last_run(config: Any, result: RunResult, runs_dir: Path
                   ) -> SinceLast | NotCompared | None:
    """:func:`since_last` of a finishing run (its record) against the machine's
    history as it stands before the run is recorded there ([history], or
    ``<runs_dir>``'s store), as the record's ``since_last``. None without history,
    machine id or earlier run; a store that cannot be read, or an entry this code
    cannot read, is said in one line and compares nothing: the run stands."""
    if not config.history.enabled:
        return None
    from station.history.entry import entry_of
    from station.history.store import HistoryStore, default_url

    # the entry of the run as result.json will hold it, as the history files it
    entry = entry_of(validated(result), config.controller.profile)
    if not entry.get("machine_id"):
        return None
    url = config.history.url or default_url(runs_dir)
    try:
        with HistoryStore(url) as store:
            earlier = store.entries(entry["machine_id"])
        doc = since_last(earlier, entry)
    except Exception as exc:  # a database or an old entry's error: said, not raised
        say(f"orthocal: not compared with the machine's last run ({type(exc).__name__}: "
            f"{exc})")
        return None
    # validated outside the try: a comparison the record does not declare is a bug
    if doc is None:
        return None
    return section(NotCompared, doc) if "not_compared" in doc else section(SinceLast, doc)


def since_last(earlier: Sequence[Mapping[str, Any]],
               entry: Mapping[str, Any]) -> dict[str, Any] | None:
    """A run's "Since the last calibration" (result ``since_last``): its ``entry``
    against the last of ``earlier`` (history entries) of its machine that started
    before it, through ``compare``. None without a machine id, without an earlier
    run, or where nothing could be compared; ``not_compared`` says why two runs of
    one id are not comparable (another geometry or register map)."""
    machine, start = entry.get("machine_id"), started_at(entry)
    if not machine or start is None:
        return None
    prior = [(when, e) for e in earlier if e.get("machine_id") == machine
             and e.get("run_dir") != entry.get("run_dir")  # a resumed run's own row
             and (when := started_at(e)) is not None and when < start]
    if not prior:
        return None
    _, last = max(prior, key=lambda p: p[0])
    head = {"previous_run": last["run_dir"], "previous_started": last.get("started")}
    try:
        doc = compare(last, entry)
    except Incomparable as exc:
        return {**head, "not_compared": str(exc)}
    if not doc["joint_error_mm"] and not doc["layout"]:
        return None
    return {**head, "previous_state": doc["a_state"],
            "joint_error_mm": doc["joint_error_mm"], "layout": doc["layout"]}
