"""The text summary of a run (``summary_text``): its first screen (station.report.
first_screen), then the details that only ``--verbose`` prints: the model and its
test, the verification (the legs' parallelism), the objective, squareness and gaps
(station.report.tool), the lost motion, the budget, the closed loop's rounds, what
the plunger guard did.

The record's sections may be absent (a run that failed halfway): a line whose
section is absent is left out, a figure that is not stated shows "—".
"""

from __future__ import annotations

from collections.abc import Mapping

from station.record.result import RunResult
from station.report import budget_table as budget
from station.report import first_screen, rounds, since, statement_lines, tool
from station.report import reversal_table as reversal
from station.report.boundary import ResultLike, as_result
from station.report.format import (
    NOT_WRITTEN_TEXT,
    fmt,
    minus_signs,
    num,
    param_line,
    param_plain,
    params_of,
    um,
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


def mountings_line(expected: Mapping[str, int]) -> str:
    """What the operator will be asked for (station.engine.closed_loop.mountings_expected)."""
    more = expected.get("per_write_back")
    each = "" if more is None else (
        f", {more} more per further write-back (the last setup's gauges stay on across "
        "each)")
    tested = expected.get("joint_test")
    joints = "" if not tested else f" (the joints' own test's {tested} first)"
    return (f"mountings: expect {expected['usual']}{joints} (one write-back, verified at "
            f"once); {expected['fewest']} if the machine is within tolerance{each}; up to "
            f"{expected['most']} if every round takes all its passes")


def summary_text(result: ResultLike, verbose: bool = True) -> str:
    """The run's summary: its first screen (station.report.first_screen: the verdict,
    each joint as found → as left, the offsets, the tool before → after, what to do,
    the mountings and the time, where the report is), then, ``verbose``, the details
    (the model and its test, the verification, squareness, gaps, lost motion, the
    budget, the rounds …). ``result``: the record, or a document that becomes it
    (station.report.boundary)."""
    record = as_result(result)
    lines = first_screen.lines(record)
    if not verbose:
        lines.append("  details       in the report, or run with --verbose")
    elif details := detail_lines(record):
        lines += ["details:", *details]
    # one minus sign (U+2212) in numbers; the report's path is as the OS has it
    return "\n".join(line if line.startswith("  report  ") else minus_signs(line)
                     for line in lines)


def detail_lines(record: RunResult) -> list[str]:
    """Everything below the first screen, each value said once (the first screen's
    are not repeated); a record with a statement prints its quantities as stated
    (station.report.statement_lines), one value and one ± each."""
    lines = [*_fit_lines(record)]
    lines += _verification_lines(record)
    if record.statement:
        lines += tool.objective_lines(record)
        lines += statement_lines.detail_lines(record)
    else:
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
    lines += rounds.summary_lines(record)
    return lines


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
    # the small errors in µm, as the report's tables and the closed loop's lines say them
    resid = f"  residual      {um(result.residual_rms_mm)} µm RMS"
    if (noise := num(result.noise_mm)) is not None:
        resid += f" (indicator noise {um(noise)} µm)"
    if result.fit_note:
        resid += f": {result.fit_note}"
    # Δρ is the first screen's "as found"; the other parameters here, at 95 % (with a
    # statement, its own lines state them: one value each)
    others = [n for n in names if not n.startswith("drho_")]
    ident = [f"  identified    {param_line(result, others)}"] \
        if others and not result.statement else []
    return [f"  model         {result.model}{why}", *ident, resid]


def _verification_lines(result: RunResult) -> list[str]:
    ver = result.verification
    if ver is None:
        return []
    # The verification measures the legs' parallelism (the method's means);
    # the tool's accuracy is the "at the tool" line's, and the two differ.
    head = (f"  verification  legs' parallelism (the method's means, not the tool's accuracy):"
            f" deviations RMS {um(result.deviations_rms_mm)} → "
            f"{um(ver.deviations_rms_mm)} µm")
    if result.statement:  # the machine as left is the statement's, once
        return [head]
    return [head + "; re-identified "
            + "  ".join(f"{param_plain(n)} = {fmt(v, signed=True)} {unit(n)}"
                        for n, v in ver.identified.items())]
