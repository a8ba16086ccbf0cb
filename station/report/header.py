"""The top of report.html: what happened, before anything else (a run rolled back,
the offsets it restored; a closed loop that did not converge and why; offsets the
station holds, their values and where to enter them), so that nothing below can be
read against it."""

from __future__ import annotations

from station.record.result import Gauge, RunResult
from station.record.result_sections import UncertaintyBudget
from station.report.format import (
    esc,
    held_by_station,
    held_offsets_text,
    not_converged_why,
    rolled_back_text,
    run_state,
)


def held_box(result: RunResult) -> str:
    """Where the station holds the offsets: their values and where to enter them
    (the result's ``offsets_final`` and ``offsets_note``)."""
    values = held_offsets_text(result)
    note = (result.offsets_note or "the drive takes no zero offset over Modbus: "
            "enter them in the drive's own home-offset parameter").rstrip(".")
    return ('<div class="box warn"><b>Offsets held by the station, not by the drive</b>'
            + (f": {esc(values)}" if values else "") + f" — {esc(note)}.</div>")


def gauges_text(result: RunResult) -> str:
    """The run's indicators by what identifies them ("A: mitutoyo, serial 12345"), in
    the config's order; the result's ``gauges``, else the budget's instruments (a
    result written before runs recorded their gauges), else "not recorded"."""
    gauges = result.gauges
    if gauges is None and isinstance(result.uncertainty_budget, UncertaintyBudget):
        gauges = [Gauge(name=i.name, protocol=i.protocol, serial=i.serial)
                  for i in result.uncertainty_budget.instruments]
    if not gauges:
        return "not recorded"
    return "; ".join(f"{g.name}: {g.protocol}, serial {g.serial or 'not given'}"
                     for g in gauges)


def run_facts(result: RunResult) -> list[tuple[str, str]]:
    """Who calibrated with what, for the header's list (HTML, escaped): the operator
    ([station] operator, run --operator; "not given" where neither said) and the
    gauges by serial."""
    return [("operator", esc(result.operator or "not given")),
            ("gauges", esc(gauges_text(result)))]


def header_boxes(result: RunResult) -> str:
    """What happened, at the top of the page: a closed loop that did not converge
    and why; offsets the station holds and where to enter them ("" for neither)."""
    out = []
    if run_state(result) == "not-converged":
        out.append('<div class="box warn"><b>Not converged</b>: the closed loop did not '
                   f"converge — {esc(not_converged_why(result))}. What each round measured "
                   "and wrote: <i>Closed loop</i>, below.</div>")
    if (back := rolled_back_text(result)) is not None:
        out.append(f'<div class="box warn"><b>Rolled back</b>: {esc(back)}.</div>')
    if held_by_station(result):
        out.append(held_box(result))
    return "".join(f"{box}\n" for box in out)
