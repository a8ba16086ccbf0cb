"""report.html's figure of the statement (docs/design.md, "The statement of the
machine"): each joint's Δρ as found and as left, the tilts, the gaps and the leg lengths
where identified, each with its 95 % expanded uncertainty as the record states it; in a
simulated run the hidden value beside it. Drawn, not computed: every value and bar is a
quantity of the record's ``statement``."""

from __future__ import annotations

from orthocal import PARAM_NAMES
from station.record.quantity_text import plus_minus
from station.record.result import RunResult
from station.record.result_statement import Quantity
from station.report.format import hidden, unit
from station.report.plots import C_AFTER, C_BEFORE, Parameters, pyplot
from station.report.statement_table import stated

#: The figure's bar, as its legend says it.
BAR = "95 % expanded uncertainty (the statement's U)"


def _parameter(name: str) -> str | None:
    """The parameter a quantity of the statement is a value of ("drho_x.as_left" →
    "drho_x", "dl_y" → "dL_y"); None for the others (squareness, reversal, tool)."""
    base = name.split(".")[0]
    base = "dL_" + base[3:] if base.startswith("dl_") else base
    return base if base in PARAM_NAMES else None


def _of(quantities: dict[str, Quantity], left: bool
        ) -> tuple[dict[str, float | None], dict[str, float | None], dict[str, str]]:
    """The values, their expanded uncertainties and their texts by parameter: Δρ as
    left (``left``), else Δρ as found and every layout quantity (one value each)."""
    values: dict[str, float | None] = {}
    halves: dict[str, float | None] = {}
    texts: dict[str, str] = {}
    for name, q in quantities.items():
        param = _parameter(name)
        if param is not None and name.endswith(".as_left") == left:
            values[param], halves[param], texts[param] = q.value, q.expanded, plus_minus(q)
    return values, halves, texts


def plot_statement(result: RunResult) -> str | None:
    """The figure as inline SVG, or None where the statement holds no parameter."""
    quantities = stated(result)
    found = _of(quantities, left=False)
    left = _of(quantities, left=True)
    names = [n for n in PARAM_NAMES if n in found[0]]
    if not names:
        return None
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 3.8))
    p = Parameters(ax, ax.twinx() if any(unit(n) == "mrad" for n in names) else None,
                   names, annotate=len(names) <= 3)
    shift = -0.12 if left[0] else 0.0
    p.draw(*found[:2], shift, C_BEFORE, "o", "as found (Δρ at the run's start; the "
           "tilts, gaps and ΔL)", texts=found[2])
    if left[0]:
        p.draw(*left[:2], 0.12, C_AFTER, "s", "Δρ as left (should be ≈ 0)", above=False,
               texts=left[2])
    p.truth(hidden(result), shift)
    return p.finish(plt, fig, BAR)
