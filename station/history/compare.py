"""What changed between two runs of one machine (docs/design.md, "Machine history"):
A's machine as left against B's as found, per axis in the controller's zero frame
(station.history.entry), and the tilts and gaps; each change with its standard
error and whether it stands out at 95 %."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from orthocal import coverage_factor
from station.errors import say
from station.history.trend import started_at
from station.record.io import section, validated
from station.record.result import RunResult
from station.record.result_sections import NotCompared, SinceLast


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


def _change(before: float, se_a: float | None, after: float, se_b: float | None,
            dof: float | None) -> dict[str, Any]:
    change = after - before
    se = None if se_a is None or se_b is None else math.hypot(se_a, se_b)
    k = coverage_factor(dof, 0.95)
    return {"before": before, "after": after, "change": change, "std_error": se,
            "interval_95": None if se is None else k * se,
            "significant": None if se is None else abs(change) > k * se}


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
            vb = found["joint_error_mm"][axis]
            joints[axis] = _change(va["value_mm"], va["std_error_mm"], vb["value_mm"],
                                   vb["std_error_mm"], dof)
    layout = {name: _change(va["value"], va["std_error"], b["layout"][name]["value"],
                            b["layout"][name]["std_error"], None)
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
    """A length in mm shown in µm to 0.1 µm, whatever its size (a joint's e, about
    −o on a calibrated machine, is thousands: −1818.6); — where not stated."""
    return "—" if value is None else f"{1000 * value:{'+' if signed else ''}.1f}"


def tilt_text(value: float | None, signed: bool = True) -> str:
    """A tilt in mrad (= mm/m) to three significant digits, the number alone (its
    line names the unit): a tilt is stated to a few per cent of itself (its standard
    error), so more digits would be noise and fewer would round a small one to zero;
    — where not stated."""
    if value is None:
        return "—"
    size = abs(value)
    decimals = 3 if size == 0 or not math.isfinite(size) else \
        min(6, max(0, 2 - math.floor(math.log10(size))))
    return f"{value:{'+' if signed else ''}.{decimals}f}"


#: What ``significant`` means, said once under a comparison's lines.
CRITERION = ("significant: the change's 95 % interval (change ± the half-width shown) "
             "excludes zero; for the joints k from Student's t on the smaller dof of the "
             "two runs, for the tilts and gaps the normal's k. Joints as e = Δρ − o, each "
             "joint's zero error without the controller's offsets (history's legend); "
             "tilts in mrad (= mm/m).")


def _significance(flag: bool | None) -> str:
    if flag is None:
        return "significance unknown (no standard error)"
    return "significant" if flag else "not significant"


def change_lines(doc: Mapping[str, Any]) -> list[str]:
    """One line per parameter of a comparison (``compare``'s ``joint_error_mm`` and
    ``layout``): before → after, the change ± its 95 % half-width, and whether it is
    significant (CRITERION). Each line names its one unit and its numbers carry none,
    so that a column never mixes two: the joints' e and the gaps in µm to 0.1 µm
    (microns), the tilts in mrad to three significant digits (tilt_text)."""
    # (name (unit), before, after, change, ± half-width, significance) per parameter
    rows: list[list[str]] = []
    for axis, c in (doc.get("joint_error_mm") or {}).items():
        rows.append([f"joint {axis} e (µm)", *(microns(c[k]) for k in ("before", "after",
                                                                        "change")),
                     microns(c["interval_95"], signed=False), _significance(c["significant"])])
    for name, c in (doc.get("layout") or {}).items():
        text, unit = (microns, "µm") if name.startswith("gap") else (tilt_text, "mrad")
        rows.append([f"{name} ({unit})", *(text(c[k]) for k in ("before", "after", "change")),
                     text(c["interval_95"], signed=False), _significance(c["significant"])])
    widths = [max((len(r[i]) for r in rows), default=0) for i in range(5)]
    return [f"{r[0]:<{widths[0]}}  {r[1]:>{widths[1]}} → {r[2]:>{widths[2]}}  change "
            f"{r[3]:>{widths[3]}} ± {r[4]:<{widths[4]}} at 95 %  {r[5]}" for r in rows]


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
