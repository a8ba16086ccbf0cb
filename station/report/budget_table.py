"""The uncertainty budget in the summary and report.html, from the run JSON's
``uncertainty_budget`` alone (docs/design.md, "Uncertainty budget"): the statement with
its expanded uncertainty, the budget table (largest contribution first), what was
assumed, and a certificate block."""

from __future__ import annotations

import html
from collections.abc import Callable

from station.record.quantity_text import plus_minus
from station.record.result import RunResult
from station.record.result_base import NotStated
from station.record.result_sections import BudgetSource, UncertaintyBudget
from station.report.format import MANY_DOF, at, dof_text, fmt, k_text, num
from station.report.statement_table import stated

NAMES = ("drho_x", "drho_y", "drho_z")


def _um(v: float | None) -> str:
    x = num(v)
    return "—" if x is None else f"{1000 * x:.1f}"


def _top(source: BudgetSource) -> float:
    """The source's largest contribution to a Δρ, mm."""
    return max((num(v) or 0.0 for v in source.contributions_mm.values()), default=0.0)


def _largest(source: BudgetSource) -> tuple[float, str]:
    """Sort key: the source's largest contribution first (to a nanometre), then name."""
    return -round(1e6 * _top(source)), source.source


def statement_values(result: RunResult, b: UncertaintyBudget) -> dict[str, float | None]:
    """The figures the budget is of: remaining.total, or the identified Δρ."""
    if b.statement == "remaining.total":
        return dict(result.remaining.total) if result.remaining is not None else {}
    return dict(result.identified)


def summary_lines(result: RunResult) -> list[str]:
    b = result.uncertainty_budget
    if isinstance(b, NotStated):
        return [f"  uncertainty   {b.error}"] if b.error else []
    if b is None:
        return []
    # the values are the first screen's "as found" (station.report.first_screen):
    # said once; here what their ± is
    kk = [x for x in map(num, b.coverage_factor.values()) if x is not None]
    k = f", k = {k_text(kk)}" if kk else ""
    line = (f"  statement     Δρ as found (above): 95 %{k}, the scatter and the uncertainty "
            "budget (GUM)")
    top = sorted(b.sources, key=_largest)[:3]
    lines = [line, "  budget        largest: " + ", ".join(
        f"{s.source} {_um(_top(s))} µm" for s in top)]
    if b.assumed:
        lines.append(f"  assumed       {len(b.assumed)} input(s) at their defaults "
                     "(report.html, Uncertainty budget): " + "; ".join(
                         a.split(" (")[0] for a in b.assumed))
    return lines


def section_html(result: RunResult) -> str:
    b = result.uncertainty_budget
    if b is None:
        return ""
    if isinstance(b, NotStated):
        return f"<h2>Uncertainty budget</h2><p>{html.escape(b.error)}</p>"
    names = [n for n in NAMES if n in b.expanded_95_mm]
    head = "".join(f"<th>u(Δρ<sub>{n[-1]}</sub>)</th>" for n in names)
    rows = []
    for s in sorted(b.sources, key=_largest):
        value = _um(s.value_mm)
        rows.append(f"<tr><td>{html.escape(s.source)}</td><td>{s.type}</td>"
                    f"<td>{html.escape(s.distribution)}</td><td>{value}</td>"
                    + "".join(f"<td class='num'>{_um(at(s.contributions_mm, n))}</td>"
                              for n in names) + "</tr>")
    dofs, ks, us = _stated_rows(result, b, names)
    dof = "".join(f"<td class='num'>{dof_text(at(dofs, n))}</td>" for n in names)
    table = (f"<table><tr><th>source (µm)</th><th>type</th><th>distribution</th>"
             f"<th>value</th>"
             f"{head}</tr>{''.join(rows)}"
             f"<tr><th colspan='4'>combined standard uncertainty u<sub>c</sub></th>"
             f"{_cells(b.combined_mm, names, _um)}</tr>"
             f"<tr><th colspan='4'>effective degrees of freedom</th>{dof}</tr>"
             f"<tr><th colspan='4'>coverage factor k (95 %)</th>"
             f"{_cells(ks, names, lambda v: fmt(v, 2))}</tr>"
             f"<tr><th colspan='4'>expanded uncertainty U (95 %){_whole(result, names)}</th>"
             f"{_cells(us, names, _um)}</tr></table>"
             f"<p class='small'>Every figure in µm. Effective degrees of freedom above "
             f"{MANY_DOF:.0f} are given as ∞: Student's k is then the normal's to the "
             "digits shown.</p>")
    assumed = "".join(f"<li>{html.escape(a)}</li>" for a in b.assumed)
    return (f"<h2>Uncertainty budget</h2><p>{html.escape(b.method)}. It "
            f"states {html.escape(b.statement)}.</p>{table}"
            + (f"<p>Assumed (not given in the config):</p><ul>{assumed}</ul>" if assumed
               else "") + _certificate(result, b, names))


def _stated_rows(result: RunResult, b: UncertaintyBudget, names: list[str]
                 ) -> tuple[dict[str, float | None], dict[str, float | None],
                            dict[str, float | None]]:
    """Each Δρ's dof, k and U: the statement's (Δρ as found and as left carry the same
    uncertainty), else the budget's (a record from before the statement)."""
    q = stated(result)
    if all(f"{n}.as_found" in q for n in names):
        found = [q[f"{n}.as_found"] for n in names]
        return ({n: x.dof for n, x in zip(names, found, strict=True)},
                {n: x.k for n, x in zip(names, found, strict=True)},
                {n: x.expanded for n, x in zip(names, found, strict=True)})
    return dict(b.effective_dof), dict(b.coverage_factor), dict(b.expanded_95_mm)


def _whole(result: RunResult, names: list[str]) -> str:
    """Where a Δρ's U holds a part added whole (tilts or bows: the statement's basis
    says so), the row says it; else U = k·u_c."""
    q = stated(result)
    added = {line for n in names if (x := q.get(f"{n}.as_found")) is not None
             for line in x.basis if line.endswith("(added whole)")}
    if not added:
        return " = k·u<sub>c</sub>"
    return " = k·u<sub>c</sub> + " + html.escape("; ".join(sorted(added)))


def _cells(values: dict[str, float | None], names: list[str],
           show: Callable[[float | None], str]) -> str:
    """A table row's figures, one per Δρ of ``names``."""
    return "".join(f"<td class='num'>{show(at(values, n))}</td>" for n in names)


def _certificate(result: RunResult, b: UncertaintyBudget, names: list[str]) -> str:
    m = result.machine
    values = statement_values(result, b)
    inst = "".join(
        f"<li>{html.escape(i.name)}: {html.escape(i.protocol)} dial "
        f"indicator, serial "
        f"{html.escape(i.serial or 'not given')}, resolution "
        f"{_um(i.resolution_mm)} µm, MPE {_um(i.mpe_mm)} µm</li>"
        for i in b.instruments)
    env = b.inputs.temperature_change_c
    q = stated(result)
    stmt = "; ".join(
        f"Δρ<sub>{n[-1]}</sub> = {html.escape(plus_minus(q[f'{n}.as_found']))}"
        if f"{n}.as_found" in q else
        f"Δρ<sub>{n[-1]}</sub> = {fmt(at(values, n), signed=True)} mm ± "
        f"{_um(at(b.expanded_95_mm, n))} µm" for n in names)
    sim = " (simulated machine)" if result.simulated else ""
    return (
        "<h3>Certificate</h3><table class='cert'>"
        f"<tr><th>machine</th><td>Orthoglide-type, leg length {fmt(m.leg_length)} mm, "
        f"joints {fmt(m.rho_min)} … {fmt(m.rho_max)} mm{sim}</td></tr>"
        f"<tr><th>instruments</th><td><ul>{inst}</ul></td></tr>"
        f"<tr><th>environment</th><td>temperature change during the run ≤ "
        f"{fmt(env.value)} K ({'stated' if env.given else 'assumed'})</td></tr>"
        f"<tr><th>date</th><td>{html.escape(result.started or '—')}</td></tr>"
        f"<tr><th>operator</th><td>{html.escape(result.operator or 'not given')}</td></tr>"
        "<tr><th>method</th><td>joint offsets from the legs' parallelism at the test "
        "postures Π0, Π<sub>i</sub><sup>±</sup> (Orthoglide calibration, dial indicators), "
        "closed loop; uncertainty after GUM (JCGM 100:2008)</td></tr>"
        f"<tr><th>statement</th><td>{stmt} (95 %; the machine's joint offsets at the start "
        "of the run as the run measured them)</td></tr>"
        f"<tr><th>assumed</th><td>{len(b.assumed)} input(s) at their defaults "
        "(above)</td></tr></table>")
