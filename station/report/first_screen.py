"""The first screen of a run's summary and of report.html: what the operator needs,
each value once, at 95 % and labelled, in µm where it is small (docs/design.md,
"The first screen"):

- the verdict (the headline) and the shop's acceptance, where it sets one;
- each joint's Δρ as found → as left;
- the offsets before → written;
- the tool's error before → after, and with the geometry in the controller;
- what to do: only actions whose figure stands out of its noise;
- the mountings and the time; where the report is.

Everything else (the model test, the budget, the rounds …) comes below it: in the
text summary only with ``--verbose``, in report.html further down the page.
:func:`items` is the one source of both, so that the two never say different things.
"""

from __future__ import annotations

import html
import textwrap
from dataclasses import dataclass
from pathlib import Path

from orthocal import coverage_factor
from station.record.quantity_text import figure, plus_minus
from station.record.result import RunResult
from station.record.result_accuracy import Accuracy
from station.record.result_sections import UncertaintyBudget
from station.record.result_statement import Quantity
from station.report import budget_table as budget
from station.report import in_controller, rounds, tool
from station.report.format import (
    AXES,
    STATE_TEXT,
    at,
    box_text,
    fmt,
    held_by_station,
    held_offsets_text,
    not_converged_why,
    num,
    rolled_back_text,
    run_state,
    um,
    um_interval,
)

WRITABLE = tuple(f"drho_{a}" for a in AXES)
#: The first screen's widest line (characters): a verdict line longer than this wraps.
WIDTH = 160
#: Below this |Δρ| (mm) a joint's value is written in µm, above in mm (an offset of a
#: millimetre reads as the controller's register does).
UM_BELOW_MM = 0.1
#: A completed run's record without advice: its model identified no joint offset (Δρ),
#: so no statement of the machine was made, or the record is older than the statement.
NO_ADVICE = ("none stated: the record holds no advice (its model identifies no joint "
             "offset, or it was written before the statement of the machine)")
#: What to do once a run's offsets were rolled back (the record's advice after it).
ROLLED_BACK_TODO = ("calibrate the machine again (orthocal run): the offsets this run "
                    "wrote were rolled back")
#: The tool's line with the geometry in the controller, by the route it rests on
#: (accuracy.compensated.route; a record from before the joints: none).
IN_CONTROLLER = {"": "with the geometry in the controller",
                 "kinematics": "with the geometry in the controller (the joints' errors "
                               "stay)",
                 "kinematics+tables": "with the geometry and the joint tables in the "
                                      "controller"}


@dataclass(frozen=True)
class Item:
    """One line of the first screen: its label and its text."""

    label: str
    text: str


# ----------------------------------------------------------------- the verdict


def headline(result: RunResult) -> str:
    """The summary's first line: what happened, before anything else. A completed
    run whose closed loop did not converge says NOT CONVERGED and why (exit status
    3); offsets the station holds say so, with their values, to be entered in the
    drive (the "offsets held" line below says where)."""
    state = run_state(result)
    head = f"orthocal run: {STATE_TEXT[state].upper()}"
    # the offsets held come first: they need the operator's hand whatever the verdict,
    # and a long why wraps below the first line (lines)
    if held_by_station(result):
        values = held_offsets_text(result)
        head += (" — offsets HELD BY THE STATION, not by the drive"
                 + (f": {values}" if values else "")
                 + "; enter them in the drive (see \"offsets held\" below)")
    if result.rolled_back is not None:
        head += rolled_back_head(result)
    elif state == "not-converged":
        head += f" — {not_converged_why(result)}"
    elif result.message:
        head += f" — {result.message}"
    return head


def rolled_back_head(result: RunResult) -> str:
    """The headline of a rolled-back run: when, the tool as it now is (back as found)
    and what to do; the figures the run left describe a machine no longer there."""
    back = result.rolled_back
    acc, _ = tool.statement(result)
    now = "" if acc is None else f", at the tool {um(acc.before.rms_mm)} µm RMS"
    when = "" if back is None else f" on {back.at}"
    return (f", then rolled back{when} — the machine is back as found{now}; to do: "
            "calibrate it again")


def acceptance_text(result: RunResult) -> str | None:
    """The shop's acceptance at 95 %, PASS, FAIL or NOT DECIDED, with each limit's
    finding (the figures themselves are the "at the tool" line's); None without
    ``[acceptance]``."""
    acc = result.acceptance
    if acc is None:
        return None
    parts = []
    for c in acc.checks:
        limit = f"{c.figure.upper() if c.figure == 'rms' else c.figure} {c.limit_um:g} µm"
        if c.outcome == "pass":
            parts.append(f"{limit}: its whole 95 % interval within")
        elif c.outcome == "fail":
            parts.append(f"{limit}: exceeded by its whole 95 % interval")
        elif c.interval_95_um is None:
            parts.append(f"{limit}: the figure is not stated")
        else:
            parts.append(f"{limit}: inside its 95 % interval, not decided")
    word = {"pass": "PASS", "fail": "FAIL", "undecided": "NOT DECIDED"}[acc.outcome]
    note = f" ({acc.note})" if acc.note else ""
    return (f"{word} at 95 %, the tool's error after calibration against [acceptance]: "
            + "; ".join(parts) + note)


# ---------------------------------------------------------------- the joints


def value_pm(value_mm: float | None, half_mm: float | None) -> str:
    """A value with its 95 % half-width: "+1.1 ± 1.6 µm" when small, "+0.697 mm ±
    19.5 µm" when not (the half-width always in µm)."""
    v = num(value_mm)
    if v is None:
        return "—"
    pm = "" if (h := num(half_mm)) is None else f" ± {um(h)} µm"
    if abs(v) < UM_BELOW_MM:
        return f"{fmt(1000 * v, 1, signed=True)}" + (pm or " µm")
    return f"{fmt(v, 3, signed=True)} mm{pm}"


def as_found(result: RunResult) -> dict[str, tuple[float | None, float | None]]:
    """Each joint's Δρ at the start of the run with its 95 % half-width: the
    statement with its expanded uncertainty (the scatter and the budget, GUM) where
    the run states one, else the identification's ±k σ (k from Student's t)."""
    b = result.uncertainty_budget
    if isinstance(b, UncertaintyBudget):
        values = budget.statement_values(result, b)
        return {n: (at(values, n), at(b.expanded_95_mm, n)) for n in WRITABLE
                if n in b.expanded_95_mm}
    k = coverage_factor(num(result.std_errors_dof))
    out: dict[str, tuple[float | None, float | None]] = {}
    for n in WRITABLE:
        if n in result.identified:
            se = at(result.std_errors, n)
            out[n] = (at(result.identified, n), None if se is None else k * se)
    return out


def _nothing_written(result: RunResult) -> bool:
    return not result.offsets_written and not any(
        e.offsets_written for e in result.iterations or [])


def as_left(result: RunResult, name: str) -> str:
    """Joint ``name``'s Δρ as the run leaves it: what the last verification found
    left (± its 95 % half-width, widened by what the data cannot decide), or why there
    is no such figure."""
    if _nothing_written(result):
        return "unchanged (nothing written)"
    if result.rolled_back is not None:  # the offsets from before: Δρ is as found again
        value, half = as_found(result).get(name, (None, None))
        return f"{value_pm(value, half)}, rolled back"
    rem = result.remaining
    if rem is None or at(rem.estimate, name) is None:
        return "not verified (the correction written, not measured after)"
    k = num(rem.coverage_factor_95) or coverage_factor(num(rem.std_errors_dof))
    se = at(rem.std_errors, name)
    # where the legs' bows explain the data as well, how far they put it: the noise's
    # interval alone would claim what the data cannot decide (verdict.judge adds it too)
    last = result.iterations[-1] if result.iterations else None
    apart = (at(last.ambiguity.apart_mm, name) or 0.0) if last and last.ambiguity else 0.0
    text = value_pm(at(rem.estimate, name), None if se is None else k * se + apart)
    aim = rounds.aim_of(result, len(result.iterations or []) - 1).get(name)
    if aim:
        text += f" (aimed at {value_pm(aim, None)}, objective tool)"
    return text


def stated(result: RunResult) -> dict[str, Quantity]:
    """The record's statement by name (empty for a record from before it)."""
    return {q.name: q for q in result.statement or []}


def joint_items(result: RunResult) -> list[Item]:
    """One line per joint: Δρ as found → as left, at 95 % (the statement's; a record
    from before it: its budget and remaining)."""
    q = stated(result)
    if q:
        out = []
        for n in WRITABLE:
            found, left = q.get(f"{n}.as_found"), q.get(f"{n}.as_left")
            if found is None or left is None:
                continue
            # rolled back: the offsets from before are restored, Δρ is as found again
            after = "unchanged (nothing written)" if _nothing_written(result) else \
                f"{plus_minus(found)}, rolled back" if result.rolled_back is not None else \
                "not verified (the correction written, not measured after)" \
                if left.decision == "not verified" else plus_minus(left)
            out.append(Item(f"joint {n[-1]}", f"Δρ as found {plus_minus(found)} → as left "
                                              f"{after} (95 %)"))
        return out
    return [Item(f"joint {n[-1]}", f"Δρ as found {value_pm(value, half)} → as left "
                                   f"{as_left(result, n)} (95 %)")
            for n, (value, half) in as_found(result).items()]


def offsets_item(result: RunResult) -> Item | None:
    """The offsets before → written (or why not written)."""
    written, wb = result.offsets_written, result.writeback
    if written:
        pairs = ", ".join(f"{a} {fmt(at(result.offsets_before, a))} → {fmt(written[a])}"
                          for a in AXES if a in written)
        status: str = wb.status if wb is not None else "written"
        if held_by_station(result) and status == "written":
            status = "held by the station"
        if result.rolled_back is not None:
            status += ", then rolled back"
        return Item("offsets", f"{pairs} mm ({status})")
    if wb is not None:
        reason = f": {wb.reason}" if wb.reason else ""
        return Item("offsets", f"not written ({wb.status}{reason})")
    return None


# ------------------------------------------------------------------- the tool


def _figure(before: float | None, after: float | None, interval: str | None,
            what: str = "") -> str:
    """"333.4 → 36.7 µm RMS (95 %: 9.3–57.5 µm)": the interval is the after-figure's."""
    return (f"{um(before)} → {um(after)} µm{what}"
            + (f" (95 %: {interval} µm)" if interval else ""))


def _tool_statement(result: RunResult, acc: Accuracy) -> list[Item]:
    """The tool's lines from the statement: before → after (RMS, max), and with the
    geometry in the controller."""
    q = stated(result)
    b_rms, b_max = q["tool.before.rms"], q["tool.before.max"]
    a_rms, a_max = q["tool.after.rms"], q["tool.after.max"]
    c_rms = q.get("tool.compensated.rms")
    box = box_text(acc.workspace_mm)
    if tool.written(result):
        lines = [f"{um(b_rms.value)} → {figure(a_rms, 'RMS')}, max {um(b_max.value)} → "
                 f"{figure(a_max)}, over {box}, with the offsets written"]
    else:  # no arrow: nothing changed on the machine
        lines = [f"{figure(b_rms, 'RMS')}, max {figure(b_max)}, over {box}, as the machine "
                 "stands"]
    if c_rms is not None:
        route = acc.compensated.route if acc.compensated is not None else None
        if route == "kinematics" and not _bounded_joints(result):
            route = None  # every joint exact: no joint error stays
        lines.append(f"{IN_CONTROLLER.get(route or '', IN_CONTROLLER[''])} "
                     f"{figure(c_rms, 'RMS')}")
    return [Item("at the tool" if i == 0 else "", t) for i, t in enumerate(lines)]


def _bounded_joints(result: RunResult) -> list[str]:
    """The joints without a table whose bound is not zero."""
    joints = result.joints
    return [] if joints is None else \
        [a for a in AXES if (j := getattr(joints, a)).table is None and j.bound_um_per_m]


def joints_item(result: RunResult) -> Item | None:
    """What the joints were taken to be, the tool's figures resting on it: each joint's
    test and its lead at 95 % (the statement's), or the bound assumed or stated."""
    joints = result.joints
    if joints is None:
        return None
    q = stated(result)
    parts, bounded = [], []
    for a in AXES:
        j = getattr(joints, a)
        lead = q.get(f"lead_{a}")
        said = plus_minus(lead) if lead is not None else \
            f"{fmt(j.lead_um_per_m, 0, signed=True)} µm/m"
        if j.source == "test":
            parts.append(f"{a} test ({Path(j.file or '').name}), lead {said}")
        elif j.source == "station":
            parts.append(f"{a} the station's own test, lead {said}")
        else:
            bounded.append(a)
    if bounded:
        b = getattr(joints, bounded[0]).bound_um_per_m
        word = "stated" if joints.bound.given else "assumed"
        parts.append(f"{', '.join(bounded)} {word} within ±{fmt(b, 0)} µm/m from Π0, "
                     "not measured" if b else f"{', '.join(bounded)} {word} exact")
    text = "the tool's figures take " + "; ".join(parts)
    acc = result.accuracy
    count = acc.drive_count if isinstance(acc, Accuracy) else None
    if count is not None:  # (J17): the figures are the geometry's, the count is apart
        counts = sorted({v for v in count.target_mm.values() if v})
        text += (f"; the drive's {'/'.join(f'{v:g}' for v in counts)} mm count adds up to "
                 f"{1000 * count.max_mm:.1f} µm ({1000 * count.rms_mm:.1f} µm RMS) at the "
                 "tool, not in these figures")
    return Item("joints", text)


def tool_items(result: RunResult) -> list[Item]:
    """The tool's error lines (:func:`tool_item`, or the statement's)."""
    acc, _ = tool.statement(result)
    if acc is not None and "tool.after.rms" in stated(result):
        return _tool_statement(result, acc)
    item = tool_item(result)
    return [] if item is None else [item]


def tool_item(result: RunResult) -> Item | None:
    """The tool's error over the workspace before → after (the after-figure with its
    95 % interval), and with the geometry in the controller where the run states it."""
    acc, why = tool.statement(result)
    if acc is None:
        return Item("at the tool", f"not stated: {why}") if why else None
    a, b = acc.after, acc.before
    rms_iv, max_iv = um_interval(a.rms_interval_95_mm), um_interval(a.max_interval_95_mm)
    if tool.written(result) and result.rolled_back is None:
        text = (f"{_figure(b.rms_mm, a.rms_mm, rms_iv, ' RMS')}, max "
                f"{_figure(b.max_mm, a.max_mm, max_iv)}, over {box_text(acc.workspace_mm)}, "
                "with the offsets written")
    else:  # no arrow: nothing changed on the machine
        text = (f"{um(b.rms_mm)} µm RMS (max {um(b.max_mm)} µm) as the machine stands, "
                f"over {box_text(acc.workspace_mm)}; written, the offsets would leave "
                f"{um(a.rms_mm)} µm RMS" + (f" (95 %: {rms_iv} µm)" if rms_iv else "")
                + f", max {um(a.max_mm)} µm" + (f" (95 %: {max_iv} µm)" if max_iv else ""))
    comp = in_controller.stated(acc)
    if comp is not None:
        iv = um_interval(comp.rms_interval_95_mm)
        text += (f"; with the geometry in the controller {um(comp.rms_mm)} µm RMS"
                 + (f" (95 %: {iv} µm)" if iv else ""))
    return Item("at the tool", text)


# ------------------------------------------------------------------ what to do


def todo_items(result: RunResult) -> list[Item]:
    """What to do: the record's advice, verbatim (station.statement.advice; a
    rolled-back run's: calibrate again, which its rollback put into the record). A
    record without advice gets none made up here: the advice has one decision behind
    it, and a second reading of the sections would be a second decision."""
    if result.rolled_back is not None:  # what the run found no longer applies as it stands
        return [Item("to do", ROLLED_BACK_TODO)]
    if result.advice is not None:
        texts = [a.text for a in result.advice]
        return [Item("to do" if i == 0 else "", t) for i, t in enumerate(texts)]
    if result.status != "ok":
        return []  # the headline says what stopped the run
    return [Item("to do", NO_ADVICE)]


# -------------------------------------------------------------------- the rest


def timing_text(result: RunResult) -> str | None:
    """The mountings the run took and the operator's time at them (format.
    mountings_text), and the whole run from its journal's header to its end, every
    session of a resumed run and the pauses between (``duration_s``; ``timing.wall_s``
    is the last session's alone), or None (an older result without mountings)."""
    from station.report.format import format_duration, mountings_text

    mountings = mountings_text(result)
    if mountings is None:
        return None
    whole = num(result.duration_s)
    whole = num(result.timing.wall_s) if whole is None else whole
    total = f"; the whole run {format_duration(whole)}" if whole is not None else ""
    return f"{mountings}{total}"


def items(result: RunResult) -> list[Item]:
    """The first screen below the headline, in order."""
    out = []
    if (accepted := acceptance_text(result)) is not None:
        out.append(Item("acceptance", accepted))
    out += joint_items(result)
    back = rolled_back_text(result)
    out += [i for i in (offsets_item(result), None if back is None else
                        Item("ROLLED BACK", back)) if i is not None]
    tools = tool_items(result)
    out += tools
    if tools and (joints := joints_item(result)) is not None:
        out.append(joints)
    if held_by_station(result):  # the headline's "enter them in the drive": how
        out.append(Item("offsets held", f"by the station: {result.offsets_note or ''}"))
    out += todo_items(result)
    if (timing := timing_text(result)) is not None:
        out.append(Item("mountings", timing))
    if result.run_dir:
        out.append(Item("report", str(Path(result.run_dir) / "report.html")))
    return out


def lines(result: RunResult) -> list[str]:
    """The summary's first lines: the headline, then :func:`items`, each at most WIDTH
    characters (:func:`wrapped`)."""
    out = wrapped(headline(result), "")
    for i in items(result):
        out += wrapped(i.text, f"  {i.label:<13} ")
    return out


def wrapped(text: str, first: str) -> list[str]:
    """``text`` after ``first`` in lines of at most WIDTH characters, broken between
    words: a verdict read at a glance fits the screen, its detail goes on below it,
    indented two further than the item's text (so that it is not read as the next
    advice) and the headline's by 16. A word longer than a line (a path) stays whole."""
    indent = " " * (len(first) + 2 if first else 16)
    return textwrap.wrap(text, WIDTH, initial_indent=first, subsequent_indent=indent,
                         break_long_words=False, break_on_hyphens=False) or [first.rstrip()]


def html_block(result: RunResult) -> str:
    """report.html's first screen: the same as :func:`lines`, as one block at the
    top of the page (the report's path left out: the reader has it open)."""
    verdict = headline(result).removeprefix("orthocal run: ")
    rows = [Item("verdict", verdict), *(i for i in items(result) if i.label != "report")]
    dl = [f"<dt>{html.escape(i.label)}</dt><dd>{html.escape(i.text)}</dd>" for i in rows]
    return ('<section id="first-screen" class="box"><h2 style="margin-top:0">The result '
            'at a glance</h2><dl class="kv">' + "".join(dl) + "</dl>"
            '<p class="small">At 95 %: each ± and each interval is the 95 % expanded '
            "uncertainty. The details follow below.</p></section>")
