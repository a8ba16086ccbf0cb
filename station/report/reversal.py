"""The joints' lost motion in the report: the summary's lines and the report's
section (a table per joint: reversal with its 95 % interval, half of it, what it
leaves at the tool, what to do), from the result's ``reversal`` and
``accuracy.reversal`` alone."""

from __future__ import annotations

import html
from collections.abc import Mapping
from typing import Any

from station.report.format import AXES, as_dict, num


def _k95(rev: Mapping[str, Any]) -> float:
    from orthocal import coverage_factor

    return coverage_factor(num(rev.get("std_errors_dof")))


def _um(value: Any, digits: int = 1) -> str:
    v = num(value)
    return "—" if v is None else f"{1000 * v:.{digits}f} µm"


def summary_lines(result: Mapping[str, Any]) -> list[str]:
    """The reversal per joint with its 95 % interval, what it leaves at the tool and
    what to do (none when the run measured none)."""
    rev = as_dict(result.get("reversal"))
    values = as_dict(rev.get("value_mm"))
    if not any(num(values.get(a)) is not None for a in AXES):
        return []
    ses = as_dict(rev.get("std_errors_mm"))
    k = _k95(rev)
    parts = [f"{a} {_um(values.get(a))}" + (f" ± {1000 * k * se:.1f}" if (se := num(
        ses.get(a))) is not None else "") for a in AXES]
    lines = [f"  lost motion   reversal (ISO 230-2) {', '.join(parts)} (95 %); "
             f"{rev.get('stated', '')}"]
    tool = as_dict(as_dict(result.get("accuracy")).get("reversal"))
    if tool:
        lines.append(f"    at the tool: a point reached from an unknown side is off by up to "
                     f"{_um(tool.get('tool_max_mm'))} more (half each joint's reversal); "
                     f"{tool.get('advice', '')}")
    return lines


def section_html(result: Mapping[str, Any]) -> str:
    """The report's "Lost motion" section ("" when the run measured none)."""
    rev = as_dict(result.get("reversal"))
    values = as_dict(rev.get("value_mm"))
    if not any(num(values.get(a)) is not None for a in AXES):
        return ""
    ses, n = as_dict(rev.get("std_errors_mm")), as_dict(rev.get("n"))
    k = _k95(rev)
    rows = []
    for a in AXES:
        se = num(ses.get(a))
        rows.append(f"<tr><td>{a}</td><td>{_um(values.get(a))}</td>"
                    f"<td>{'—' if se is None else f'± {1000 * k * se:.1f} µm'}</td>"
                    f"<td>{_um((num(values.get(a)) or 0.0) / 2)}</td><td>{n.get(a, 0)}</td>"
                    "</tr>")
    tool = as_dict(as_dict(result.get("accuracy")).get("reversal"))
    at_tool = "" if not tool else (
        f"<p>At the tool: where a point is reached from an unknown side, each joint may be "
        f"off by up to half its reversal beyond the error field above, up to "
        f"<b>{_um(tool.get('tool_max_mm'))}</b> at the tool over the workspace "
        f"({html.escape(str(tool.get('assumes', '')))}). What to do: "
        f"{html.escape(str(tool.get('advice', '')))}.</p>")
    return (
        "<h2>Lost motion (reversal)</h2>"
        f"<p>{html.escape(str(rev.get('stated', '')))}. Measured: "
        f"{html.escape(str(rev.get('method', '')))}.</p>"
        "<table><thead><tr><th>joint</th><th>reversal B</th><th>95 % (k = "
        f"{k:.2f})</th><th>B/2 either side of the stated Δρ</th><th>measurements</th></tr>"
        f"</thead><tbody>{''.join(rows)}</tbody></table>{at_tool}")
