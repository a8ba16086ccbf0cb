"""The identified geometry in the controller, in the report (docs/design.md, "The
geometry in the controller"): the result's ``accuracy.compensated`` beside the
offsets alone (``accuracy.after``), as the summary's line, report.html's table and
the advice that names the route (the kinematics component, ``orthocal compensate``).
Said only where the run states it; advice only where it stands out of the noise."""

from __future__ import annotations

import html
from collections.abc import Mapping
from typing import Any

from station.report.format import as_dict, num, um, um_interval


def _e(value: Any) -> str:
    return html.escape(str(value), quote=True)


def _grouped(nominal: Mapping[str, Any]) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for name, why in nominal.items():
        out.setdefault(str(why), []).append(str(name))
    return out


def table(head: list[str], rows: list[list[str]]) -> str:
    """A table whose first column is words and the others numbers."""
    ths = "".join(f'<th class="l">{h}</th>' if i == 0 else f"<th>{h}</th>"
                  for i, h in enumerate(head))
    body = "".join("<tr>" + "".join(
        f'<td class="l">{c}</td>' if i == 0 else f'<td class="num">{c}</td>'
        for i, c in enumerate(row)) + "</tr>" for row in rows)
    return f"<table><thead><tr>{ths}</tr></thead><tbody>{body}</tbody></table>"


def gains(acc: Mapping[str, Any]) -> bool | None:
    """Whether the geometry in the controller stands out of the offsets alone: its
    95 % interval of the RMS lies wholly below the after-figure's (None: either is
    not stated)."""
    comp, after = as_dict(acc.get("compensated")), as_dict(acc.get("after"))
    c_iv, a_iv = comp.get("rms_interval_95_mm"), after.get("rms_interval_95_mm")
    a_rms = num(after.get("rms_mm"))
    if not isinstance(c_iv, list | tuple) or len(c_iv) != 2 or a_rms is None:
        return None
    a_lo = num(a_iv[0]) if isinstance(a_iv, list | tuple) and len(a_iv) == 2 else a_rms
    c_hi = num(c_iv[1])
    return None if c_hi is None or a_lo is None else c_hi < a_lo


def compensation_advice(acc: Mapping[str, Any]) -> str | None:
    """What the geometry in the controller buys, as advice naming the route; None
    where the run states no compensated figure."""
    comp = as_dict(acc.get("compensated"))
    if num(comp.get("rms_mm")) is None:
        return None
    after = as_dict(acc.get("after"))
    if gains(acc):
        return (f"the kinematics component (orthocal export --kinematics) or orthocal "
                f"compensate take it from {um(after.get('rms_mm'))} to "
                f"{um(comp.get('rms_mm'))} µm RMS")
    return (f"the identified geometry in the controller would leave "
            f"{um(comp.get('rms_mm'))} µm RMS, not clearly less than the offsets' "
            f"{um(after.get('rms_mm'))}: nothing to gain from it")


def summary_lines(acc: Mapping[str, Any]) -> list[str]:
    """The summary's line on the geometry in the controller (accuracy.compensated)."""
    comp = as_dict(acc.get("compensated"))
    if num(comp.get("rms_mm")) is None:
        return []
    ivs = [f"{iv} µm {what}" for iv, what in (
        (um_interval(comp.get("rms_interval_95_mm")), "RMS"),
        (um_interval(comp.get("max_interval_95_mm")), "max")) if iv]
    figures = (f"{um(comp.get('rms_mm'))} µm RMS (max {um(comp.get('max_mm'))} µm"
               + (f"; 95 %: {', '.join(ivs)}" if ivs else "") + ")")
    return [f"  in the controller  the identified geometry would leave {figures}; "
            f"{compensation_advice(acc)}"]


def html_section(acc: Mapping[str, Any]) -> str:
    """What the identified geometry in the controller buys, beside the offsets alone."""
    comp = as_dict(acc.get("compensated"))
    if num(comp.get("rms_mm")) is None:
        return ""
    after = as_dict(acc.get("after"))
    rows = [["RMS |E|", um(after.get("rms_mm")), um(comp.get("rms_mm")),
             um_interval(comp.get("rms_interval_95_mm")) or "—"],
            ["max |E|", um(after.get("max_mm")), um(comp.get("max_mm")),
             um_interval(comp.get("max_interval_95_mm")) or "—"]]
    grid = table(["tool-point error (µm)", "offsets only", "geometry in the controller",
                    "geometry in the controller: 95 % interval"], rows)
    told = ", ".join(str(n) for n in comp.get("told") or [])
    nominal = as_dict(comp.get("nominal"))
    routes = "".join(f"<li><code>{_e(r)}</code></li>" for r in comp.get("routes") or [])
    return ("<h3>The geometry in the controller</h3>" + grid
            + f"<p><b>{_e(compensation_advice(acc))}</b>.</p>"
            + f'<p class="small">The controller is told {_e(told)}; left nominal: '
            + _e("; ".join(f"{', '.join(names)} ({why})" for why, names in
                           _grouped(nominal).items()) or "nothing")
            + f". {_e(comp.get('method', ''))}.</p><ul>{routes}</ul>")

