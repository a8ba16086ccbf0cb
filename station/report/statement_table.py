"""report.html's "The statement of the machine" (docs/design.md, "The statement of the
machine" and "The decision table"): every quantity the run states, as the record holds
it (value, ± or interval at 95 %, k, dof, the decision table's word, the basis), with a
simulated machine's hidden value beside it, and the advice, each text verbatim. Nothing
here computes a value or an uncertainty: each is printed by station.record.quantity_text,
the one way every view prints a quantity. The page's other sections read the
quantities through :func:`stated` and print them the same way."""

from __future__ import annotations

import html

from station.record.quantity_text import figure, interval, plus_minus, um
from station.record.result import RunResult, Simulation
from station.record.result_statement import Quantity
from station.report.format import at, dof_text, fmt, hidden, true_value
from station.report.statement_lines import DECIDED

#: A quantity's symbol in the page, by the kind its name starts with.
_SYMBOL = {"drho": "Δρ", "tilt": "tilt", "gap": "gap", "squareness": "squareness",
           "reversal": "reversal", "dl": "ΔL", "lead": "lead"}
#: The decision words the details do not name (the Δρ's), as the page says them.
_WORDS = {**DECIDED, "within": "within the loop's limit", "not shown within":
          "not shown within the loop's limit", "outside": "outside the loop's limit",
          "not verified": "not verified (nothing measured after the last write)",
          "corrected": "corrected (offset written)", "left": "left (no offset written)"}
#: Where the table says what its columns mean.
CAPTION = ("Each quantity once, as result.json's <code>statement</code> holds it: its value "
           "with its 95 % expanded uncertainty U = k·u<sub>c</sub> (Type A and B combined, "
           "GUM; Welch–Satterthwaite's dof, Student's k), or, for the tool's figures (never "
           "negative), the median and the 2.5 %–97.5 % quantiles of the Monte Carlo draws "
           "(GUM Supplement 1; no k). Every other ± and interval on this page is one of "
           "these. Decision: the decision table's word (docs/design.md); basis: the "
           "sources in the quantity's budget, largest first.")


def stated(result: RunResult) -> dict[str, Quantity]:
    """The record's statement by name (empty for a record from before it)."""
    return {q.name: q for q in result.statement or []}


def symbol_html(name: str) -> str:
    """"drho_x.as_found" as "Δρ<sub>x</sub> as found", "tool.after.rms" as "tool after:
    RMS |E|"."""
    if name.startswith("tool."):
        _, state, stat = name.split(".")
        return f"tool {html.escape(state)}: {'RMS' if stat == 'rms' else 'max'} |E|"
    base, _, state = name.partition(".")
    kind, _, sub = base.partition("_")
    text = f"{_SYMBOL.get(kind, html.escape(kind))}<sub>{html.escape(sub)}</sub>"
    return text + (f" {html.escape(state.replace('_', ' '))}" if state else "")


def said(q: Quantity) -> str:
    """The quantity with its 95 % uncertainty, as every view prints it (plain text): a
    tool's figure with its interval, any other with its ±."""
    return figure(q) if bounded(q) else plus_minus(q)


def bounded(q: Quantity) -> bool:
    """A figure from Monte Carlo draws (the tool's RMS and max): no k, an interval."""
    return q.k is None


def decision_text(q: Quantity) -> str:
    """The decision table's word on ``q``, in words ("—" for none)."""
    return _WORDS.get(q.decision or "", q.decision or "—")


def _truth(sim: Simulation | None, q: Quantity) -> float | None:
    """The simulated machine's hidden value of ``q`` where it names one (Δρ as found,
    the tilts, gaps, leg lengths and each joint's reversal)."""
    if sim is None:
        return None
    base, _, state = q.name.partition(".")
    kind, _, sub = base.partition("_")
    if kind == "drho" and state == "as_found":
        return true_value(sim, base)
    if kind in ("tilt", "gap"):
        return true_value(sim, base)
    if kind == "dl":
        return at(sim.true_dl, sub)
    if kind == "reversal":
        return at(sim.backlash_mm, sub)
    return None


def _row(q: Quantity, sim: Simulation | None, with_truth: bool) -> str:
    e = html.escape
    value = f"{um(q.value)} µm" if bounded(q) else plus_minus(q)
    k, dof = ("—", "—") if bounded(q) else (fmt(q.k, 2), dof_text(q.dof))
    cells = [(symbol_html(q.name), "l"), (e(value), "num"), (e(interval(q)), "num"),
             (k, "num"), (dof, "num"), (e(decision_text(q)), "l")]
    if with_truth:
        t = _truth(sim, q)
        cells.append(("—" if t is None else
                      e(plus_minus(q.model_copy(update={"value": t, "expanded": None}))),
                      "num truth"))
    cells.append((e("; ".join(q.basis)) or "—", "l"))
    return "<tr>" + "".join(f'<td class="{c}">{t}</td>' for t, c in cells) + "</tr>"


def advice_html(result: RunResult) -> str:
    """The advice, each text verbatim, with the quantities it rests on."""
    items = result.advice or []
    if not items:
        return ""
    e = html.escape
    return ("<h3>What to do</h3><ul>" + "".join(
        f"<li>{e(a.text)} <span class=\"small\">(rests on "
        f"{e(', '.join(a.rests_on)) or 'the run'})</span></li>" for a in items) + "</ul>")


def section_html(result: RunResult) -> str:
    """The section "The statement of the machine" ("" for a record without one)."""
    quantities = result.statement or []
    if not quantities:
        return ""
    sim = hidden(result)
    with_truth = any(_truth(sim, q) is not None for q in quantities)
    head = ["quantity", "value (95 %)", "95 % interval", "k", "dof", "decision"]
    if with_truth:
        head.append("hidden truth")
    head.append("basis")
    ths = "".join(f'<th class="l">{h}</th>' if h in ("quantity", "decision", "basis")
                  else f"<th>{h}</th>" for h in head)
    rows = "".join(_row(q, sim, with_truth) for q in quantities)
    truth = (" Hidden truth: the value the simulated machine was given (a joint's Δρ as "
             "found, the tilts, gaps and leg lengths, the joints' reversal)."
             if with_truth else "")
    return ('<h2 id="statement">The statement of the machine</h2>'
            f'<table class="stated"><thead><tr>{ths}</tr></thead><tbody>{rows}</tbody>'
            f'</table><p class="small">{CAPTION}{truth}</p>' + advice_html(result))
