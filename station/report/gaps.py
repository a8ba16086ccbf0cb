"""The gaps between the actuator axes in the report (docs/model.md, "Axes that do
not meet"): the result's ``accuracy.gaps`` as the summary's line and report.html's
table, beside the squareness, each with its 95 % interval and what to do. Every
field may be missing (a result from before the gaps, a run that failed halfway):
then nothing is said."""

from __future__ import annotations

import html

from station.record.quantity_text import interval, plus_minus
from station.record.result import RunResult
from station.record.result_accuracy import Accuracy
from station.record.result_base import Interval
from station.report.format import at, dof_text, fmt, num, param_html
from station.report.squareness_table import advice_list
from station.report.statement_table import decision_text, stated

#: Which axis passes which, and along what (gap_xy: x passes y along +z).
PASSES = {"gap_xy": ("x", "y", "z"), "gap_xz": ("x", "z", "y"), "gap_yz": ("y", "z", "x")}


def _rows(acc: Accuracy) -> list[tuple[str, float, Interval | None, float | None]]:
    """(name, gap mm, its 95 % interval, its standard error) of every gap stated."""
    ivs = acc.gap_interval_95 or {}
    out = []
    for name in PASSES:
        v = at(acc.gaps, name)
        if v is None:
            continue
        iv = ivs[name] if name in ivs else None
        interval = iv if iv is not None and all(num(x) is not None for x in iv) else None
        out.append((name, v, interval, at(acc.gap_std_errors, name)))
    return out


def _half(interval: Interval | None, value: float) -> float | None:
    return None if interval is None else max(interval[1] - value, value - interval[0])


def summary_lines(acc: Accuracy) -> list[str]:
    """The summary's "gaps" line: each pair of axes, how far they pass each other
    (µm, ± its 95 % half-width) and, where one counts (gap_advice), what to do."""
    rows = _rows(acc)
    if not rows:
        return []
    text = ", ".join(f"{n[4:].upper()} {1000 * v:+.0f}".replace("-", "−")
                     + (f" ± {1000 * h:.0f}" if (h := _half(iv, v)) is not None else "")
                     for n, v, iv, _ in rows)
    advice = acc.gap_advice or []
    acting = [a for a in advice if "offsets cannot fix it" in a]
    # what to do is the first screen's "to do" (station.report.first_screen), which
    # weighs the routes against the tool's figures
    tail = ": beyond their noise, and offsets cannot fix them (what to do: above)" \
        if acting else ": none beyond its uncertainty"
    return [f"  axes' gaps    {text} µm (95 %; how far each pair of axes passes the other)"
            + tail]


#: Under the table: what a gap is and what can take it.
ABOUT = ("The paper's machine has three axes that meet in one point; an assembled frame's "
         "rails pass each other. Every leg hangs from its carriage, so where a rail runs "
         "moves the tool. Offsets cannot fix a gap; the controller's kinematics can "
         "(model.json holds the gaps with their convention), and so can moving a rail "
         "across by the gap.")


def _stated_html(result: RunResult) -> str:
    """The gaps' table from the statement: value ± U, the 95 % interval, k and dof, the
    decision table's word; the advice on the rails, each text verbatim."""
    q = stated(result)
    rows = []
    for name, (a, b, along) in PASSES.items():
        g = q.get(name)
        if g is None:
            continue
        rows.append(f"<tr><td class=\"l\">{param_html(name)}: axis {a} past axis {b}, along "
                    f"+{along}</td><td class=\"num\">{html.escape(plus_minus(g))}</td>"
                    f"<td class=\"num\">{html.escape(interval(g))}</td>"
                    f"<td class=\"num\">{fmt(g.k, 2)}</td><td class=\"num\">"
                    f"{dof_text(g.dof)}</td><td class=\"l\">"
                    f"{html.escape(decision_text(g))}</td></tr>")
    if not rows:
        return ""
    advice = [a.text for a in result.advice or [] if a.id.startswith(("rail.", "undecided."))]
    return ("<h3>Gaps between the axes</h3>"
            "<table class=\"stated\"><thead><tr><th class=\"l\">pair</th><th>gap (95 %)</th>"
            "<th>95 % interval</th><th>k</th><th>dof</th><th class=\"l\">decision</th></tr>"
            "</thead><tbody>" + "".join(rows) + "</tbody></table>"
            f'<p class="small">{ABOUT} Each ± is the statement\'s (95 %).</p>'
            + advice_list(advice))


def html_section(acc: Accuracy, result: RunResult | None = None) -> str:
    """report.html's "Gaps between the axes" beside the squareness; empty without gaps.
    With a statement, its gaps (``result``'s); else the accuracy block's (legacy)."""
    if result is not None and result.statement:
        return _stated_html(result)
    rows = _rows(acc)
    if not rows:
        return ""
    table = []
    for name, v, iv, se in rows:
        a, b, along = PASSES[name]
        span = "—" if iv is None else f"{1000 * iv[0]:+.1f} … {1000 * iv[1]:+.1f}"
        table.append(
            f"<tr><td class=\"l\">{param_html(name)}: axis {a} past axis {b}, along +{along}"
            f"</td><td class=\"num\">{1000 * v:+.1f}</td><td class=\"num\">{span}</td>"
            f"<td class=\"num\">{'—' if se is None else f'{1000 * se:.1f}'}</td></tr>")
    advice = acc.gap_advice or []
    return ("<h3>Gaps between the axes</h3>"
            "<table><thead><tr><th class=\"l\">pair</th><th>gap (µm)</th>"
            "<th>95 % interval (µm)</th><th>σ (µm)</th></tr></thead><tbody>"
            + "".join(table) + "</tbody></table>"
            f'<p class="small">{ABOUT}</p>'
            + ("<p><b>What to do:</b></p><ul>" + "".join(
                f"<li>{html.escape(a)}</li>" for a in advice) + "</ul>" if advice else ""))
