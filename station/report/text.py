"""The short text summary of a run (``summary_text``): what was identified and
written, the verification (the legs' parallelism), the accuracy at the tool and
the squareness (station.report.tool), the closed loop's rounds, what the plunger
guard did.

The record's sections may be absent (a run that failed halfway): a line whose
section is absent is left out, a figure that is not stated shows "—".
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from station.record.result import RunResult
from station.report import budget_table as budget
from station.report import reversal_table as reversal
from station.report import rounds, since, tool
from station.report.boundary import ResultLike, as_result
from station.report.format import (
    AXES,
    NOT_WRITTEN_TEXT,
    STATE_TEXT,
    at,
    fmt,
    held_by_station,
    held_offsets_text,
    not_converged_why,
    num,
    param_line,
    param_plain,
    params_of,
    run_state,
    unit,
)


def model_notes(result: RunResult) -> list[str]:
    """What the report must say about the model: why auto chose it, what cannot
    be identified from these measurements, what cannot be written."""
    notes = []
    sel = result.model_selection
    if sel is not None and sel.reason:
        notes.append(f"Model chosen by auto ({sel.test}, level "
                     f"{sel.level}): {sel.reason}.")
    notes += result.not_identifiable or []
    if any(not n.startswith("drho_") for n in params_of(result)):
        notes.append(NOT_WRITTEN_TEXT)
    return notes


def guard_lines(result: RunResult) -> list[str]:
    """The plunger guard's stops that the run recovered from (or none)."""
    guard = result.plunger_guard
    if not guard.recovered:
        return []
    lines = [f"  plunger guard stopped the axes {guard.stops} time(s) and the run "
             f"recovered ({guard.retakes} cycle(s) taken again):"]
    for r in guard.recovered:
        lines.append(f"    indicator {r.indicator} on {r.where}, move to "
                     f"{r.move}: re-planned from where the axes stopped via "
                     f"{r.waypoints} waypoint(s) at {fmt(r.speed_mm_s, 1)} mm/s")
    return lines


def headline(result: RunResult) -> str:
    """The summary's first line: what happened, before anything else. A completed
    run whose closed loop did not converge says NOT CONVERGED and why (exit status
    3); offsets the station holds say so, with their values, to be entered in the
    drive (the "offsets held" line below says where)."""
    state = run_state(result)
    head = f"orthocal run: {STATE_TEXT[state].upper()}"
    if state == "not-converged":
        head += f" — {not_converged_why(result)}"
    elif result.message:
        head += f" — {result.message}"
    if held_by_station(result):
        values = held_offsets_text(result)
        head += (" — offsets HELD BY THE STATION, not by the drive"
                 + (f": {values}" if values else "")
                 + "; enter them in the drive (see \"offsets held\" below)")
    return head


def mountings_line(expected: Mapping[str, int]) -> str:
    """What the operator will be asked for (station.engine.closed_loop.mountings_expected)."""
    return (f"mountings: expect {expected['usual']} (one write-back, verified at once); "
            f"{expected['fewest']} if the machine is within tolerance, up to "
            f"{expected['most']} if every round takes all its passes")


def timing_line(result: RunResult) -> str | None:
    """The mountings the run took and the operator's time at them, or None (an older
    result without them)."""
    timing = result.timing
    if timing.mountings is None:
        return None
    operator = num(timing.operator_s)
    took = f", {operator:.0f} s at the machine" if operator is not None else ""
    wall = num(timing.wall_s)
    total = f"; the whole run {wall:.0f} s" if wall is not None else ""
    return f"  mountings     {timing.mountings}{took}{total}"


def summary_text(result: ResultLike) -> str:
    """A few lines for the end of a run: status, identified values, residual,
    offsets written, verification before → after, where the report is. ``result``:
    the record, or a document that becomes it (station.report.boundary)."""
    record = as_result(result)
    lines = [headline(record), *_fit_lines(record), *_offsets_lines(record)]
    lines += _verification_lines(record)
    lines += tool.summary_lines(record)
    lines += reversal.summary_lines(record)
    lines += budget.summary_lines(record)
    lines += since.summary_lines(record)
    names = params_of(record)
    if names and record.not_identifiable:
        two = any("ΔL cannot be separated" in n for n in record.not_identifiable)
        lines.append("  not identifiable  a rotation of the whole machine"
                     + ("; ΔL beside the tilts (two postures per leg)" if two else ""))
    if any(not n.startswith("drho_") for n in names):
        lines.append("  not written   tilts, gaps and ΔL (a controller's offsets take only Δρ; "
                     "its kinematics can take the rest: orthocal export --kinematics, or "
                     "orthocal compensate for a program)")
    lines += guard_lines(record)
    if (line := timing_line(record)) is not None:
        lines.append(line)
    lines += rounds.summary_lines(record)
    if record.run_dir:
        lines.append(f"  report        {Path(record.run_dir) / 'report.html'}")
    return "\n".join(lines)


def _fit_lines(result: RunResult) -> list[str]:
    """The model (and why auto chose it), the identified values, the residual."""
    names = params_of(result)
    if not names:
        return []
    sel = result.model_selection
    chosen = [c for c in (sel.candidates if sel is not None else [])
              if c.model == result.model and c.F is not None]
    why = (f" (auto: F = {fmt(chosen[0].F, 2)}, p = {fmt(chosen[0].p_value)}"
           f" against the measured noise, level {sel.level})" if chosen and sel else
           " (auto: no candidate explains the data)" if sel else "")
    resid = f"  residual      {fmt(result.residual_rms_mm)} mm RMS"
    if (noise := num(result.noise_mm)) is not None:
        resid += f" (indicator noise {fmt(noise)} mm)"
    if result.fit_note:
        resid += f": {result.fit_note}"
    return [f"  model         {result.model}{why}",
            f"  identified    {param_line(result, names)}", resid]


def _offsets_lines(result: RunResult) -> list[str]:
    """The offsets before → written (or why not written), and who holds them."""
    lines = []
    written, wb = result.offsets_written, result.writeback
    if written:
        pairs = ", ".join(f"{a} {fmt(at(result.offsets_before, a))} → {fmt(written[a])}"
                          for a in AXES if a in written)
        status: str = wb.status if wb is not None else "written"
        if held_by_station(result) and status == "written":
            status = "held by the station"
        lines.append(f"  offsets       {pairs} mm ({status})")
    elif wb is not None:
        reason = f": {wb.reason}" if wb.reason else ""
        lines.append(f"  offsets       not written ({wb.status}{reason})")
    if held_by_station(result):
        lines.append(f"  offsets held  by the station: {result.offsets_note or ''}")
    return lines


def _verification_lines(result: RunResult) -> list[str]:
    ver = result.verification
    if ver is None:
        return []
    # The verification measures the legs' parallelism (the method's means);
    # the tool's accuracy is the "at the tool" line's, and the two differ.
    return [
        f"  verification  legs' parallelism (the method's means, not the tool's accuracy):"
        f" deviations RMS {fmt(result.deviations_rms_mm)} → "
        f"{fmt(ver.deviations_rms_mm)} mm; re-identified "
        + "  ".join(f"{param_plain(n)} = {fmt(v, signed=True)} {unit(n)}"
                    for n, v in ver.identified.items())
    ]
