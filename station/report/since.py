"""The report's "Since the last calibration" (the result's ``since_last``, written
by station.commands.run from the machine's history: docs/design.md, "Machine
history"): per parameter, the last run's as left against this run's as found, the
change with its 95 % half-width and whether it is significant. The numbers are
station.history.compare's; this only shows them. Absent (no machine id, no earlier
run) or malformed: nothing said, never raised."""

from __future__ import annotations

import html
from collections.abc import Mapping
from typing import Any

from station.history.compare import change_lines
from station.report.format import as_dict, format_when, param_html

_INTRO = ("The joints are compared as e = Δρ − o, their error in the controller's zero "
          "frame: the machine's own, whatever offsets were written in between. A change "
          "is significant when it lies beyond its 95 % interval (for the joints, Student's "
          "t on the smaller dof of the two runs; the normal's k for the tilts and gaps).")


def _head(since: Mapping[str, Any]) -> str:
    state = since.get("previous_state") or "as left"
    return (f"the last run of this machine, {since.get('previous_run')} (started "
            f"{format_when(since.get('previous_started'))}), {state}, against this run "
            "as found")


def summary_lines(result: Mapping[str, Any]) -> list[str]:
    since = result.get("since_last")
    if not isinstance(since, Mapping):
        return []
    if since.get("not_compared"):
        return [f"  since last    not compared with {since.get('previous_run')}: "
                f"{since['not_compared']}"]
    try:
        rows = change_lines(since)
    except (KeyError, TypeError, ValueError):
        return []  # a record this version cannot read: the report stands without it
    return [f"  since last    {_head(since)}:"] + [f"    {line}" for line in rows]


def _cells(c: Mapping[str, Any], scale: float, digits: int) -> str:
    def num(v: Any, signed: bool = True) -> str:
        return "—" if not isinstance(v, int | float) else \
            f"{scale * v:{'+' if signed else ''}.{digits}f}"

    significant = {True: "<b>yes</b>", False: "no"}.get(c.get("significant"), "—")
    return "".join(f'<td class="num">{x}</td>' for x in (
        num(c.get("before")), num(c.get("after")), num(c.get("change")),
        num(c.get("interval_95"), signed=False))) + f"<td>{significant}</td>"


def section_html(result: Mapping[str, Any]) -> str:
    since = result.get("since_last")
    if not isinstance(since, Mapping):
        return ""
    title = "\n<h2>Since the last calibration</h2>"  # its own line, where there is one
    if since.get("not_compared"):
        return (f"{title}<p>Not compared with the last run of this machine, "
                f"{html.escape(str(since.get('previous_run')))}: "
                f"{html.escape(str(since['not_compared']))}.</p>")
    rows = []
    for axis, c in as_dict(since.get("joint_error_mm")).items():
        rows.append(f'<tr><td class="l">joint {html.escape(axis)}: e (µm)</td>'
                    f"{_cells(as_dict(c), 1000.0, 1)}</tr>")
    for name, c in as_dict(since.get("layout")).items():
        scale, unit = (1000.0, "µm") if name.startswith("gap") else (1.0, "mrad")
        rows.append(f'<tr><td class="l">{param_html(name)} ({unit})</td>'
                    f"{_cells(as_dict(c), scale, 1 if scale > 1 else 3)}</tr>")
    if not rows:
        return ""
    head = _head(since)
    return (f"{title}<p>{html.escape(head[0].upper() + head[1:])}.</p>"
            '<table><thead><tr><th class="l">parameter</th><th>last run</th>'
            "<th>this run</th><th>change</th><th>± 95 %</th><th>significant</th></tr>"
            "</thead><tbody>" + "".join(rows) + "</tbody></table>"
            f'<p class="small">{html.escape(_INTRO)}</p>')
