"""The uncertainty budget in the summary and report.html, from the run JSON's
``uncertainty_budget`` alone (docs/design.md, "Uncertainty budget"): the statement with
its expanded uncertainty, the budget table (largest contribution first), what was
assumed, and a certificate block."""

from __future__ import annotations

import html
from collections.abc import Mapping
from typing import Any

from station.report.format import as_dict, fmt, num

NAMES = ("drho_x", "drho_y", "drho_z")


def _um(v: Any) -> str:
    x = num(v)
    return "—" if x is None else f"{1000 * x:.1f}"


def _largest(source: Mapping[str, Any]) -> tuple[float, str]:
    """Sort key: the source's largest contribution first (to a nanometre), then name."""
    top = max((num(v) or 0.0 for v in as_dict(source.get("contributions_mm")).values()),
              default=0.0)
    return -round(1e6 * top), str(source.get("source"))


def _statement(result: Mapping[str, Any], b: Mapping[str, Any]) -> dict[str, float | None]:
    where = str(b.get("statement", "identified"))
    if where == "remaining.total":
        return dict(as_dict(as_dict(result.get("remaining")).get("total")))
    return dict(as_dict(result.get("identified")))


def summary_lines(result: Mapping[str, Any]) -> list[str]:
    b = as_dict(result.get("uncertainty_budget"))
    if not b or "expanded_95_mm" not in b:
        return [f"  uncertainty   {b['error']}"] if b.get("error") else []
    values = _statement(result, b)
    k = as_dict(b.get("coverage_factor"))
    line = "  statement     " + "   ".join(
        f"Δρ{n[-1]} = {fmt(values.get(n), signed=True)} ± {_um(b['expanded_95_mm'].get(n))} µm"
        for n in NAMES if n in b["expanded_95_mm"])
    kk = [num(v) for v in k.values() if num(v) is not None]
    line += (f" (95 %, k = {min(kk):.2f}–{max(kk):.2f}: the scatter and the uncertainty "
             "budget, GUM)" if kk else "")
    srcs = [s for s in b.get("sources") or [] if isinstance(s, dict)]
    top = sorted(srcs, key=_largest)[:3]
    lines = [line, "  budget        largest: " + ", ".join(
        f"{s['source']} {_um(max(num(v) or 0.0 for v in s['contributions_mm'].values()))} µm"
        for s in top)]
    if b.get("assumed"):
        lines.append(f"  assumed       {len(b['assumed'])} input(s) at their defaults "
                     "(report.html, Uncertainty budget): " + "; ".join(
                         str(a).split(" (")[0] for a in b["assumed"]))
    return lines


def section_html(result: Mapping[str, Any]) -> str:
    b = as_dict(result.get("uncertainty_budget"))
    if not b:
        return ""
    if "expanded_95_mm" not in b:
        return f"<h2>Uncertainty budget</h2><p>{html.escape(str(b.get('error', '')))}</p>"
    names = [n for n in NAMES if n in b["expanded_95_mm"]]
    srcs = [s for s in b.get("sources") or [] if isinstance(s, dict)]
    srcs.sort(key=_largest)
    head = "".join(f"<th>u(Δρ<sub>{n[-1]}</sub>) µm</th>" for n in names)
    rows = []
    for s in srcs:
        c = as_dict(s.get("contributions_mm"))
        value = "—" if s.get("value_mm") is None else f"{_um(s['value_mm'])} µm"
        rows.append(f"<tr><td>{html.escape(str(s['source']))}</td><td>{s.get('type')}</td>"
                    f"<td>{html.escape(str(s.get('distribution')))}</td><td>{value}</td>"
                    + "".join(f"<td class='num'>{_um(c.get(n))}</td>" for n in names) + "</tr>")
    total = lambda key: "".join(  # noqa: E731
        f"<td class='num'>{v}</td>" for v in (
            _um(b[key].get(n)) if key != "coverage_factor" else fmt(b[key].get(n), 2)
            for n in names))
    nus = [b["effective_dof"].get(n) for n in names]
    dof = "".join(f"<td class='num'>{'∞' if v is None else fmt(v, 1)}</td>" for v in nus)
    table = (f"<table><tr><th>source</th><th>type</th><th>distribution</th><th>value</th>"
             f"{head}</tr>{''.join(rows)}"
             f"<tr><th colspan='4'>combined standard uncertainty u<sub>c</sub></th>"
             f"{total('combined_mm')}</tr>"
             f"<tr><th colspan='4'>effective degrees of freedom</th>{dof}</tr>"
             f"<tr><th colspan='4'>coverage factor k (95 %)</th>{total('coverage_factor')}</tr>"
             f"<tr><th colspan='4'>expanded uncertainty U = k·u<sub>c</sub></th>"
             f"{total('expanded_95_mm')}</tr></table>")
    assumed = "".join(f"<li>{html.escape(str(a))}</li>" for a in b.get("assumed") or [])
    return (f"<h2>Uncertainty budget</h2><p>{html.escape(str(b.get('method', '')))}. It "
            f"states {html.escape(str(b.get('statement')))}.</p>{table}"
            + (f"<p>Assumed (not given in the config):</p><ul>{assumed}</ul>" if assumed
               else "") + _certificate(result, b, names))


def _certificate(result: Mapping[str, Any], b: Mapping[str, Any], names: list[str]) -> str:
    m = as_dict(result.get("machine"))
    values = _statement(result, b)
    inst = "".join(
        f"<li>{html.escape(str(i.get('name')))}: {html.escape(str(i.get('protocol')))} dial "
        f"indicator, serial "
        f"{html.escape(str(i.get('serial') or 'not given'))}, resolution "
        f"{_um(i.get('resolution_mm'))} µm, MPE {_um(i.get('mpe_mm'))} µm</li>"
        for i in b.get("instruments") or [] if isinstance(i, dict))
    inputs = as_dict(b.get("inputs"))
    env = as_dict(inputs.get("temperature_change_c"))
    stmt = "; ".join(
        f"Δρ<sub>{n[-1]}</sub> = {fmt(values.get(n), signed=True)} mm ± "
        f"{_um(b['expanded_95_mm'].get(n))} µm" for n in names)
    sim = " (simulated machine)" if result.get("simulated") else ""
    return (
        "<h3>Certificate</h3><table class='cert'>"
        f"<tr><th>machine</th><td>Orthoglide-type, leg length {fmt(m.get('leg_length'))} mm, "
        f"joints {fmt(m.get('rho_min'))} … {fmt(m.get('rho_max'))} mm{sim}</td></tr>"
        f"<tr><th>instruments</th><td><ul>{inst}</ul></td></tr>"
        f"<tr><th>environment</th><td>temperature change during the run ≤ "
        f"{fmt(env.get('value'))} K ({'stated' if env.get('given') else 'assumed'})</td></tr>"
        f"<tr><th>date</th><td>{html.escape(str(result.get('started') or '—'))}</td></tr>"
        "<tr><th>operator</th><td>not recorded by the station</td></tr>"
        "<tr><th>method</th><td>joint offsets from the legs' parallelism at the test "
        "postures Π0, Π<sub>i</sub><sup>±</sup> (Orthoglide calibration, dial indicators), "
        "closed loop; uncertainty after GUM (JCGM 100:2008)</td></tr>"
        f"<tr><th>statement</th><td>{stmt} (95 %; the machine's joint offsets at the start "
        "of the run as the run measured them)</td></tr>"
        f"<tr><th>assumed</th><td>{len(b.get('assumed') or [])} input(s) at their defaults "
        "(above)</td></tr></table>")
