"""The identified geometry in the controller, in the report (docs/design.md, "The
geometry in the controller"): the result's ``accuracy.compensated`` beside the
offsets alone (``accuracy.after``), as the summary's line, report.html's table and
the advice that names the route (the kinematics component, ``orthocal compensate``).
Said only where the run states it; advice only where it stands out of the noise."""

from __future__ import annotations

from station.record.quantity_text import figure, interval
from station.record.result import RunResult
from station.record.result_accuracy import Accuracy, Compensated
from station.report.format import esc, num, table, um, um_interval
from station.report.statement_table import stated as quantities


def _grouped(nominal: dict[str, str]) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for name, why in nominal.items():
        out.setdefault(why, []).append(name)
    return out


def stated(acc: Accuracy) -> Compensated | None:
    """The run's figure with the geometry in the controller (None: not stated)."""
    comp = acc.compensated
    return comp if comp is not None and num(comp.rms_mm) is not None else None


def gains(acc: Accuracy) -> bool | None:
    """Whether the geometry in the controller stands out of the offsets alone: its
    95 % interval of the RMS lies wholly below the after-figure's (None: either is
    not stated)."""
    comp, after = acc.compensated, acc.after
    if comp is None or num(after.rms_mm) is None:
        return None
    a_lo, c_hi = num(after.rms_interval_95_mm[0]), num(comp.rms_interval_95_mm[1])
    return None if c_hi is None or a_lo is None else c_hi < a_lo


def compensation_advice(acc: Accuracy, comp: Compensated) -> str:
    """What the geometry in the controller (``comp``, :func:`stated`) buys, as
    advice naming the route."""
    if gains(acc):
        return (f"the kinematics component (orthocal export --kinematics) or orthocal "
                f"compensate take it from {um(acc.after.rms_mm)} to "
                f"{um(comp.rms_mm)} µm RMS")
    return (f"the identified geometry in the controller would leave "
            f"{um(comp.rms_mm)} µm RMS, not clearly less than the offsets' "
            f"{um(acc.after.rms_mm)}: nothing to gain from it")


def summary_lines(acc: Accuracy) -> list[str]:
    """The summary's line on the geometry in the controller (accuracy.compensated):
    the advice; its figure with its interval is the first screen's."""
    comp = stated(acc)
    if comp is None:
        return []
    return [f"  in the controller  {compensation_advice(acc, comp)}"]


def _stated_rows(result: RunResult) -> list[list[str]] | None:
    """The table's rows from the statement (None: it holds no such figures)."""
    q = quantities(result)
    if "tool.compensated.rms" not in q or "tool.after.rms" not in q:
        return None
    return [[f"{label} |E|", um(q[f"tool.after.{s}"].value), um(q[f"tool.compensated.{s}"].value),
             interval(q[f"tool.compensated.{s}"]).removesuffix(" µm")]
            for label, s in (("RMS", "rms"), ("max", "max")) if f"tool.compensated.{s}" in q]


def stated_advice(result: RunResult) -> str | None:
    """What the statement says the geometry in the controller buys: its advice's text
    verbatim where the decision table says "gain", else the decision in words (None:
    no statement, or it states no such figure)."""
    comp = quantities(result).get("tool.compensated.rms")
    if comp is None:
        return None
    said = [a.text for a in result.advice or [] if a.id == "controller"]
    if said:
        return said[0]
    return (f"with the geometry in the controller {figure(comp, 'RMS')}: not clearly lower "
            "than the offsets' alone (the decision table: no gain)")


def html_section(acc: Accuracy, result: RunResult | None = None) -> str:
    """What the identified geometry in the controller buys, beside the offsets alone
    (the statement's figures and its decision where ``result`` has one)."""
    comp = stated(acc)
    if comp is None:
        return ""
    rows = None if result is None else _stated_rows(result)
    advice = None if result is None else stated_advice(result)
    if rows is None or advice is None:  # a record from before the statement
        after = acc.after
        rows = [["RMS |E|", um(after.rms_mm), um(comp.rms_mm),
                 um_interval(comp.rms_interval_95_mm) or "—"],
                ["max |E|", um(after.max_mm), um(comp.max_mm),
                 um_interval(comp.max_interval_95_mm) or "—"]]
        advice = compensation_advice(acc, comp)
    grid = table(["tool-point error (µm)", "offsets only", "geometry in the controller",
                  "geometry in the controller: 95 % interval"], rows)
    routes = "".join(f"<li><code>{esc(r)}</code></li>" for r in comp.routes)
    nominal = "; ".join(f"{', '.join(names)} ({why})"
                        for why, names in _grouped(comp.nominal).items())
    return ("<h3>The geometry in the controller</h3>" + grid
            + f"<p><b>{esc(advice)}</b>.</p>"
            + f'<p class="small">The controller is told {esc(", ".join(comp.told))}; left '
            f"nominal: {esc(nominal or 'nothing')}. {esc(comp.method)}.</p><ul>{routes}</ul>")
