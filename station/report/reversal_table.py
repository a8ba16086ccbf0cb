"""The joints' lost motion in the report: the summary's lines and the report's
section (a table per joint: reversal with its 95 % interval, half of it, what it
leaves at the tool, what to do), from the result's ``reversal`` and
``accuracy.reversal`` alone."""

from __future__ import annotations

import html

from orthocal import coverage_factor
from orthocal.lost_motion import standing_out
from station.record.quantity_text import plus_minus
from station.record.result import RunResult
from station.record.result_accuracy import Accuracy, ToolReversal
from station.record.result_sections import Reversal
from station.report.format import AXES, at, dof_text, fmt, num, um
from station.report.statement_table import decision_text, stated


def _um(value: float | None, digits: int = 1) -> str:
    v = num(value)
    return "—" if v is None else f"{1000 * v:.{digits}f} µm"


def _pm(value: float | None, se: float | None, k: float, axis: str) -> str:
    """"x 4.2 ± 0.5 µm": the reversal with its 95 % half-width."""
    v = num(value)
    if v is None:
        return f"{axis} —"
    pm = "" if se is None else f" ± {1000 * k * se:.1f}"
    return f"{axis} {1000 * v:.1f}{pm} µm".replace("-", "−")


def _advice(rev: Reversal, tool: ToolReversal) -> str:
    """The record's advice, where some joint's reversal stands out of its noise (a
    result written before the advice was gated may advise on noise: not repeated)."""
    if standing_out(rev.value_mm, rev.std_errors_mm, num(rev.std_errors_dof)):
        return tool.advice
    return "nothing to compensate: no joint's reversal stands out of its noise at 95 %"


def _measured(result: RunResult) -> Reversal | None:
    """The run's reversal, where it measured one for some joint."""
    rev = result.reversal
    if rev is None or all(at(rev.value_mm, a) is None for a in AXES):
        return None
    return rev


def _at_tool(result: RunResult) -> ToolReversal | None:
    acc = result.accuracy
    return acc.reversal if isinstance(acc, Accuracy) else None


def summary_lines(result: RunResult) -> list[str]:
    """The reversal per joint with its 95 % interval, what it leaves at the tool and
    what to do (none when the run measured none)."""
    rev = _measured(result)
    if rev is None:
        return []
    k = coverage_factor(num(rev.std_errors_dof))
    parts = [_pm(at(rev.value_mm, a), at(rev.std_errors_mm, a), k, a) for a in AXES]
    lines = [f"  lost motion   reversal (ISO 230-2) {', '.join(parts)} (95 %); {rev.stated}"]
    tool = _at_tool(result)
    if tool is not None:
        lines.append(f"    at the tool: a point reached from an unknown side is off by up to "
                     f"{_um(tool.tool_max_mm)} more (half each joint's reversal); "
                     f"{_advice(rev, tool)}")
    return lines


def _stated_table(result: RunResult, rev: Reversal) -> str | None:
    """The table from the statement: each joint's reversal ± U (95 %), k and dof, the
    decision table's word, the measurements (None: the statement holds no reversal)."""
    q = stated(result)
    rows = []
    for a in AXES:
        r = q.get(f"reversal_{a}")
        if r is None:
            continue
        rows.append(f"<tr><td>{a}</td><td class='num'>{html.escape(plus_minus(r))}</td>"
                    f"<td class='num'>{fmt(r.k, 2)}</td><td class='num'>{dof_text(r.dof)}</td>"
                    f"<td class='l'>{html.escape(decision_text(r))}</td>"
                    f"<td class='num'>{rev.n.get(a, 0)}</td></tr>")
    if not rows:
        return None
    return ("<table class='stated'><thead><tr><th>joint</th><th>reversal B (95 %)</th>"
            "<th>k</th><th>dof</th>"
            "<th class='l'>decision</th><th>measurements</th></tr></thead>"
            f"<tbody>{''.join(rows)}</tbody></table><p class='small'>Each ± is the "
            "statement's (95 %); the joint's Δρ is stated for the middle of its band, B/2 "
            "either side. Decision: compensate (or repair above the repair threshold) only "
            "beyond k_act standard uncertainties (the decision table, docs/design.md).</p>")


def section_html(result: RunResult) -> str:
    """The report's "Lost motion" section ("" when the run measured none)."""
    rev = _measured(result)
    if rev is None:
        return ""
    table = _stated_table(result, rev)
    if table is not None:
        return _section(result, rev, table, True)
    return _section(result, rev, _legacy_table(rev), False)


def _section(result: RunResult, rev: Reversal, table: str, stated_: bool) -> str:
    """The section around its ``table``; what to do: the statement's advice (the
    accuracy block's, filled from it), or the legacy reading (``stated_`` False)."""
    tool = _at_tool(result)
    todo = "" if tool is None else (tool.advice if stated_ else _advice(rev, tool))
    at_tool = "" if tool is None else (
        f"<p>At the tool: where a point is reached from an unknown side, each joint may be "
        f"off by up to half its reversal beyond the error field above, up to "
        f"<b>{_um(tool.tool_max_mm)}</b> at the tool over the workspace "
        f"({html.escape(tool.assumes)}). What to do: "
        f"{html.escape(todo)}.</p>")
    return (
        "<h2>Lost motion (reversal)</h2>"
        f"<p>{html.escape(rev.stated)}. Measured: "
        f"{html.escape(rev.method)}.</p>{table}{at_tool}")


def _legacy_table(rev: Reversal) -> str:
    """A record from before the statement: the reversal with k·σ, k from Student's t."""
    k = coverage_factor(num(rev.std_errors_dof))
    rows = []
    for a in AXES:
        value, se = at(rev.value_mm, a), at(rev.std_errors_mm, a)
        rows.append(f"<tr><td>{a}</td><td>{um(value)}</td>"
                    f"<td>{'—' if se is None else f'± {um(k * se)}'}</td>"
                    f"<td>{um((value or 0.0) / 2)}</td><td>{rev.n.get(a, 0)}</td>"
                    "</tr>")
    return ("<table><thead><tr><th>joint (µm)</th><th>reversal B</th><th>95 % (k = "
            f"{fmt(k, 2)})</th><th>B/2 either side of the stated Δρ</th><th>measurements</th>"
            f"</tr></thead><tbody>{''.join(rows)}</tbody></table>")
