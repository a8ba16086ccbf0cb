"""The report's "Since the last calibration" (the result's ``since_last``, written
by station.commands.run from the machine's history: docs/design.md, "Machine
history"): per parameter, the last run's as left against this run's as found, the
change with its 95 % half-width and whether it is significant. The numbers are
station.history.compare's; this only shows them. Absent (no machine id, no earlier
run): nothing said."""

from __future__ import annotations

import html

from station.history.compare import change_lines, said
from station.record.result import RunResult
from station.record.result_sections import Change, NotCompared, SinceLast
from station.record.result_statement import Unit
from station.report.format import format_when, param_html

_INTRO = ("The joints are compared as e = Δρ − o, their error in the controller's zero "
          "frame: the machine's own, whatever offsets were written in between. Each value "
          "with the ± its run stated it with; a change is significant when it lies beyond "
          "its 95 % expanded uncertainty, the two runs' combined as the GUM combines a "
          "difference (each run's scatter independent, the legs' straightness common to "
          "both and fully correlated, every other stated input independent).")
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


def _cells(c: Change, name: str, unit: Unit) -> str:
    """The change's cells: each run's value with its stated ±, the change with its U,
    as station.history.compare prints them (station.record.quantity_text)."""
    return "".join(f'<td class="num">{html.escape(x)}</td>'
                   for x in said(c.model_dump(), name, unit)) + \
        f"<td>{_SIGNIFICANT[c.significant]}</td>"


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
        rows.append(f'<tr><td class="l">joint {html.escape(axis)}: e</td>'
                    f"{_cells(c, f'e_{axis}', 'mm')}</tr>")
    for name, c in since.layout.items():
        unit: Unit = "mm" if name.startswith("gap") else "mrad"
        rows.append(f'<tr><td class="l">{param_html(name)}</td>{_cells(c, name, unit)}</tr>')
    if not rows:
        return ""
    head = _head(since)
    return (f"{title}<p>{html.escape(head[0].upper() + head[1:])}.</p>"
            '<table class="changes"><thead><tr><th class="l">parameter</th><th>last run '
            "(95 %)</th><th>this run (95 %)</th><th>change (95 %)</th><th>significant</th>"
            "</tr>"
            "</thead><tbody>" + "".join(rows) + "</tbody></table>"
            f'<p class="small">{html.escape(_INTRO)}</p>')
