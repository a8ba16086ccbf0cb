"""The short text summary of a run (``summary_text``): what was identified and
written, the verification (the legs' parallelism), the accuracy at the tool and
the squareness (station.report.tool), the closed loop's rounds, what the plunger
guard did.

Every section of the result may be missing (a run that failed halfway), so
everything here reads with ``.get`` and shows "—" rather than raising.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from station.report import budget, reversal, since, tool
from station.report.format import (
    AXES,
    NOT_WRITTEN_TEXT,
    STATE_TEXT,
    as_dict,
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


def model_notes(result: Mapping[str, Any]) -> list[str]:
    """What the report must say about the model: why auto chose it, what cannot
    be identified from these measurements, what cannot be written."""
    notes = []
    sel = as_dict(result.get("model_selection"))
    if sel.get("reason"):
        notes.append(f"Model chosen by auto ({sel.get('test', 'F test')}, level "
                     f"{sel.get('level')}): {sel['reason']}.")
    for line in result.get("not_identifiable") or []:
        notes.append(str(line))
    names = params_of(result)
    if any(not n.startswith("drho_") for n in names):
        notes.append(NOT_WRITTEN_TEXT)
    return notes


def guard_lines(result: dict) -> list[str]:
    """The plunger guard's stops that the run recovered from (or none)."""
    guard = as_dict(result.get("plunger_guard"))
    recovered = [r for r in guard.get("recovered") or [] if isinstance(r, dict)]
    if not recovered:
        return []
    lines = [f"  plunger guard stopped the axes {guard.get('stops')} time(s) and the run "
             f"recovered ({guard.get('retakes', 0)} cycle(s) taken again):"]
    for r in recovered:
        lines.append(f"    indicator {r.get('indicator')} on {r.get('where')}, move to "
                     f"{r.get('move')}: re-planned from where the axes stopped via "
                     f"{r.get('waypoints')} waypoint(s) at {fmt(r.get('speed_mm_s'), 1)} mm/s")
    return lines


def headline(result: Mapping[str, Any]) -> str:
    """The summary's first line: what happened, before anything else. A completed
    run whose closed loop did not converge says NOT CONVERGED and why (exit status
    3); offsets the station holds say so, with their values, to be entered in the
    drive (the "offsets held" line below says where)."""
    state = run_state(result)
    head = f"orthocal run: {STATE_TEXT.get(state, state).upper()}"
    if state == "not-converged":
        head += f" — {not_converged_why(result)}"
    elif result.get("message"):
        head += f" — {result['message']}"
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


def timing_line(result: Mapping[str, Any]) -> str | None:
    """The mountings the run took and the operator's time at them, or None (an older
    result without them)."""
    timing = as_dict(result.get("timing"))
    count = num(timing.get("mountings"))
    if count is None:
        return None
    operator = num(timing.get("operator_s"))
    took = f", {operator:.0f} s at the machine" if operator is not None else ""
    wall = num(timing.get("wall_s"))
    total = f"; the whole run {wall:.0f} s" if wall is not None else ""
    return f"  mountings     {int(count)}{took}{total}"


def summary_text(result: dict) -> str:
    """A few lines for the end of a run: status, identified values, residual,
    offsets written, verification before → after, where the report is."""
    lines = [headline(result)]
    names = params_of(result)
    if names:
        model = str(result.get("model", ""))
        sel = as_dict(result.get("model_selection"))
        chosen = [c for c in sel.get("candidates") or [] if isinstance(c, dict)
                  and c.get("model") == model and c.get("F") is not None]
        why = (f" (auto: F = {fmt(chosen[0]['F'], 2)}, p = {fmt(chosen[0].get('p_value'))}"
               f" against the measured noise, level {sel.get('level')})" if chosen else
               " (auto: no candidate explains the data)" if sel else "")
        lines.append(f"  model         {model}{why}")
        lines.append(f"  identified    {param_line(result, names)}")
        noise = num(result.get("noise_mm"))
        resid = f"  residual      {fmt(result.get('residual_rms_mm'))} mm RMS"
        if noise is not None:
            resid += f" (indicator noise {fmt(noise)} mm)"
        if result.get("fit_note"):
            resid += f": {result['fit_note']}"
        lines.append(resid)
    before = as_dict(result.get("offsets_before"))
    written = result.get("offsets_written")
    wb = as_dict(result.get("writeback"))
    if isinstance(written, dict) and written:
        pairs = ", ".join(
            f"{a} {fmt(before.get(a))} → {fmt(written.get(a))}" for a in AXES if a in written
        )
        status = wb.get("status", "written")
        if result.get("offsets_held_by") == "station" and status == "written":
            status = "held by the station"
        lines.append(f"  offsets       {pairs} mm ({status})")
    elif wb:
        reason = f": {wb['reason']}" if wb.get("reason") else ""
        lines.append(f"  offsets       not written ({wb.get('status')}{reason})")
    if result.get("offsets_held_by") == "station":
        lines.append(f"  offsets held  by the station: {result.get('offsets_note', '')}")
    ver = result.get("verification")
    if isinstance(ver, dict) and ver:
        # The verification measures the legs' parallelism (the method's means);
        # the tool's accuracy is the "at the tool" line's, and the two differ.
        lines.append(
            f"  verification  legs' parallelism (the method's means, not the tool's accuracy):"
            f" deviations RMS {fmt(result.get('deviations_rms_mm'))} → "
            f"{fmt(ver.get('deviations_rms_mm'))} mm; re-identified "
            + "  ".join(
                f"{param_plain(n)} = {fmt(v, signed=True)} {unit(n)}"
                for n, v in as_dict(ver.get("identified")).items()
            )
        )
    lines += tool.summary_lines(result)
    lines += reversal.summary_lines(result)
    lines += budget.summary_lines(result)
    lines += since.summary_lines(result)
    if names and result.get("not_identifiable"):
        two = any("ΔL cannot be separated" in str(n) for n in result["not_identifiable"])
        lines.append("  not identifiable  a rotation of the whole machine"
                     + ("; ΔL beside the tilts (two postures per leg)" if two else ""))
    if any(not n.startswith("drho_") for n in names):
        lines.append("  not written   tilts, gaps and ΔL (a controller's offsets take only Δρ; "
                     "its kinematics can take the rest: orthocal export --kinematics, or "
                     "orthocal compensate for a program)")
    lines += guard_lines(result)
    if (line := timing_line(result)) is not None:
        lines.append(line)
    from station.report import rounds

    lines += rounds.summary_lines(result)
    if result.get("run_dir"):
        lines.append(f"  report        {Path(str(result['run_dir'])) / 'report.html'}")
    return "\n".join(lines)
