"""The top of report.html: what happened, before anything else (a closed loop that
did not converge and why; offsets the station holds, their values and where to
enter them), so that nothing below can be read against it."""

from __future__ import annotations

from station.record.result import RunResult
from station.report.format import (
    esc,
    held_by_station,
    held_offsets_text,
    not_converged_why,
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


def header_boxes(result: RunResult) -> str:
    """What happened, at the top of the page: a closed loop that did not converge
    and why; offsets the station holds and where to enter them ("" for neither)."""
    out = []
    if run_state(result) == "not-converged":
        out.append('<div class="box warn"><b>Not converged</b>: the closed loop did not '
                   f"converge — {esc(not_converged_why(result))}. What each round measured "
                   "and wrote: <i>Closed loop</i>, below.</div>")
    if held_by_station(result):
        out.append(held_box(result))
    return "".join(f"{box}\n" for box in out)
