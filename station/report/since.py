"""The report's "Since the last calibration" (the result's ``since_last``, written
by station.commands.run from the machine's history: docs/design.md, "Machine
history"): per parameter, the last run's as left against this run's as found, the
change with its 95 % half-width and whether it is significant. The numbers are
station.history.compare's; this only shows them. Absent (no machine id, no earlier
run): nothing said."""

from __future__ import annotations

import html

from station.history.compare import change_lines
from station.record.result import RunResult
from station.record.result_sections import Change, NotCompared, SinceLast
from station.report.format import format_when, param_html

_INTRO = ("The joints are compared as e = Δρ − o, their error in the controller's zero "
          "frame: the machine's own, whatever offsets were written in between. A change "
          "is significant when it lies beyond its 95 % interval (for the joints, Student's "
          "t on the smaller dof of the two runs; the normal's k for the tilts and gaps).")
_SIGNIFICANT = {True: "<b>yes</b>", False: "no", None: "—"}


def _head(since: SinceLast) -> str:
    return (f"the last run of this machine, {since.previous_run} (started "
            f"{format_when(since.previous_started)}), {since.previous_state}, against this "
            "run as found")


def summary_lines(result: RunResult) -> list[str]:
    since = result.since_last
    if since is None:
        return []
    if isinstance(since, NotCompared):
        return [f"  since last    not compared with {since.previous_run}: "
                f"{since.not_compared}"]
    rows = change_lines(since.model_dump())  # station.history's words, from its JSON
    return [f"  since last    {_head(since)}:"] + [f"    {line}" for line in rows]


def _cells(c: Change, scale: float, digits: int) -> str:
    def num(v: float | None, signed: bool = True) -> str:
        return "—" if v is None else f"{scale * v:{'+' if signed else ''}.{digits}f}"

    return "".join(f'<td class="num">{x}</td>' for x in (
        num(c.before), num(c.after), num(c.change),
        num(c.interval_95, signed=False))) + f"<td>{_SIGNIFICANT[c.significant]}</td>"


def section_html(result: RunResult) -> str:
    since = result.since_last
    if since is None:
        return ""
    title = "\n<h2>Since the last calibration</h2>"  # its own line, where there is one
    if isinstance(since, NotCompared):
        return (f"{title}<p>Not compared with the last run of this machine, "
                f"{html.escape(since.previous_run)}: "
                f"{html.escape(since.not_compared)}.</p>")
    rows = []
    for axis, c in since.joint_error_mm.items():
        rows.append(f'<tr><td class="l">joint {html.escape(axis)}: e (µm)</td>'
                    f"{_cells(c, 1000.0, 1)}</tr>")
    for name, c in since.layout.items():
        scale, unit = (1000.0, "µm") if name.startswith("gap") else (1.0, "mrad")
        rows.append(f'<tr><td class="l">{param_html(name)} ({unit})</td>'
                    f"{_cells(c, scale, 1 if scale > 1 else 3)}</tr>")
    if not rows:
        return ""
    head = _head(since)
    return (f"{title}<p>{html.escape(head[0].upper() + head[1:])}.</p>"
            '<table><thead><tr><th class="l">parameter</th><th>last run</th>'
            "<th>this run</th><th>change</th><th>± 95 %</th><th>significant</th></tr>"
            "</thead><tbody>" + "".join(rows) + "</tbody></table>"
            f'<p class="small">{html.escape(_INTRO)}</p>')
