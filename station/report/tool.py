"""Accuracy at the tool in the report (docs/design.md and docs/model.md, "Accuracy at the
tool"): the result's ``accuracy`` block as the headline's clause, the summary's
lines and report.html's section. Where the record has a statement (docs/design.md,
"The statement of the machine") every figure with its interval is the statement's
``tool.*`` quantity, printed by station.record.quantity_text, and what the figure is
made of follows the decision table's words on the tilts and gaps; the ``accuracy``
block gives the rest (the grid, the objectives' plug-in figures, the assumptions).

Parallel legs are the method's means, not its end: the machine's user cares where
the tool goes. So wherever the report states the legs' parallelism it also states
the tool's figure, or says that the run does not state one; the two must never be
read as the same thing. The block may be absent (an old result, a run that stopped
before identifying Δρ) or not stated (``accuracy: {"error": ...}``): the readers
here return None or say "not stated".
"""

from __future__ import annotations

from station.record.quantity_text import figure, interval
from station.record.result import RunResult
from station.record.result_accuracy import (
    Accuracy,
    AfterInterval,
    ErrorStats,
    Objective,
    ObjectiveFigures,
)
from station.record.result_base import NotStated
from station.record.result_statement import Quantity
from station.report import gaps, in_controller, leg_form, squareness_table
from station.report.format import (
    AXES,
    at,
    box_text,
    esc,
    fmt,
    num,
    um,
    um_interval,
)
from station.report.format import table as html_table
from station.report.squareness_table import (
    legacy_html,
    square_state,
    squareness,
    squareness_line,
)
from station.report.statement_table import stated

#: What each frame fits away before the error is stated (docs/design.md).
FRAME_TEXT = {
    "translation": "a common translation, as when the tool offset is set by touching off",
    "rigid": "a rigid motion, as when parts are aligned by probing",
}
#: What each objective of ``[writeback] objective`` aims the offsets at.
OBJECTIVE_TEXT = {
    "joints": "the paper's Δρ: legs parallel",
    "tool": "the least predicted tool error",
}
#: The tilts are "most of it" when the legs exactly parallel would still leave at
#: least this fraction of the after-figure (the tilts alone cause that much).
MOST = 0.5
_NOT_STATED = "not stated: "


# -------------------------------------------------------------------- readers


def statement(result: RunResult) -> tuple[Accuracy | None, str | None]:
    """(the accuracy block, None) when the run states it; (None, why not) when it
    tried and could not; (None, None) when the result has no such block (an old
    result, or a run that stopped before identifying Δρ)."""
    acc = result.accuracy
    if isinstance(acc, NotStated):
        text = acc.error or "the result's accuracy block holds no figures"
        return None, text[len(_NOT_STATED):] if text.startswith(_NOT_STATED) else text
    return acc, None


def written(result: RunResult) -> bool:
    """Whether offsets reached the controller: the after-figures are the machine
    now only then; otherwise they are what writing would give."""
    return bool(result.offsets_written)


def objective(acc: Accuracy, name: Objective) -> ObjectiveFigures:
    """What objective ``name``'s offsets would leave."""
    return acc.objectives.joints if name == "joints" else acc.objectives.tool


def _objective_note(acc: Accuracy, after: float, legs: float) -> str:
    """What the other objective's offsets would do to the after-figure (plug-in)."""
    best = num(acc.objectives.tool.after.rms_mm)
    if acc.objective == "joints" and best is not None and best < 0.8 * after:
        return f" (objective tool's offsets would cancel part of it, to {um(best)} µm RMS)"
    if acc.objective == "tool" and legs > 1.2 * after:
        return (f" (the offsets cancel part of it: with the legs exactly parallel it would "
                f"be {um(legs)} µm RMS)")
    return ""


def _made_of(acc: Accuracy, what: str, plural: bool) -> str | None:
    """"``what``, which offsets cannot fix, is most of it", or the joint offsets'
    share, from the objectives' plug-in figures."""
    after, legs = num(acc.after.rms_mm), num(acc.objectives.joints.after.rms_mm)
    if after is None or legs is None:
        return None
    if legs >= MOST * after:
        return (f"{what}, which offsets cannot fix, {'are' if plural else 'is'} most of it"
                + _objective_note(acc, after, legs))
    return (f"most of it is joint offset left uncorrected (with the legs exactly parallel "
            f"it would be {um(legs)} µm RMS); {what}, which offsets cannot fix, "
            f"{'are' if plural else 'is'} the rest")


def cause(acc: Accuracy, result: RunResult | None = None) -> str | None:
    """What the after-figure is made of, in words: the axes' tilts or gaps (which no
    offset fixes) when they alone would leave most of it, else the joint offsets. With
    a statement, which of them counts is the decision table's word on each."""
    q = stated(result) if result is not None else {}
    if q:
        return _cause_stated(acc, q)
    if num(acc.after.rms_mm) is None:
        return None
    state = square_state(acc)
    if state is None:
        return None
    if state is False:
        if any(s.beyond_95 for s in squareness(acc)):
            return ("no axis leans beyond what the data tell apart (nothing to shim); the "
                    "motions' squareness beyond its interval is the gaps' and the offsets' "
                    "shear")
        return "the axes are square within their uncertainty (nothing to shim)"
    return _made_of(acc, "the axes' squareness", plural=False)


def _cause_stated(acc: Accuracy, q: dict[str, Quantity]) -> str | None:
    """:func:`cause` from the statement's decisions on the tilts and gaps."""
    layout = [x for n, x in q.items() if n.startswith(("tilt_", "gap_"))]
    if not layout:
        return None
    if any(x.decision == "undecided" for x in layout):
        return ("the data cannot tell the axes' tilts from the legs' bows (what to do: the "
                "statement's advice)")
    leans = any(x.decision == "act" for x in layout if x.name.startswith("tilt_"))
    passes = any(x.decision == "act" for x in layout if x.name.startswith("gap_"))
    if not leans and not passes:
        return ("no axis leans or passes another beyond its uncertainty (nothing to shim "
                "or move)")
    what = ("the axes' tilts and gaps" if leans and passes else
            "the axes' tilts" if leans else "the gaps between the axes")
    return _made_of(acc, what, plural=True)


def _figures(block: ErrorStats) -> str:
    """"13.7 µm RMS (max 33.3 µm; 95 %: 12.0–15.0 µm RMS, 28.2–37.5 µm max)", the
    intervals where the block states them (a record from before the statement)."""
    text = f"{um(block.rms_mm)} µm RMS (max {um(block.max_mm)} µm"
    if isinstance(block, AfterInterval):
        ivs = [f"{iv} µm {what}" for iv, what in (
            (um_interval(block.rms_interval_95_mm), "RMS"),
            (um_interval(block.max_interval_95_mm), "max")) if iv]
        if ivs:
            text += "; 95 %: " + ", ".join(ivs)
    return text + ")"


def _stated_figures(q: dict[str, Quantity], state: str) -> str | None:
    """"28.3 µm RMS (95 %: 27.5–29.0 µm), max 56.8 µm (95 %: 55.2–58.4 µm)": the
    statement's ``tool.<state>`` figures as every view prints them (None: not stated)."""
    rms, mx = q.get(f"tool.{state}.rms"), q.get(f"tool.{state}.max")
    if rms is None or mx is None:
        return None
    return f"{figure(rms, 'RMS')}, max {figure(mx)}"


def _clause_figures(result: RunResult, acc: Accuracy, state: str) -> str:
    """The figures of ``state`` ("before", "after"): the statement's where it has
    them, else the accuracy block's (a record from before the statement)."""
    said = _stated_figures(stated(result), state)
    if said is not None:
        return said
    return _figures(acc.before if state == "before" else acc.after)


def tool_clause(result: RunResult) -> str | None:
    """The headline's clause on the tool, plain text, lower case; None when the
    run states no accuracy (the caller says so)."""
    acc, _ = statement(result)
    if acc is None:
        return None
    where = (f"of where they should over the workspace {box_text(acc.workspace_mm)} "
             f"(frame {acc.frame})")
    before, after = (_clause_figures(result, acc, s) for s in ("before", "after"))
    if written(result):
        text = ("at the tool, by the identified model, commanded points land within "
                f"{after} {where}, against {before} before calibration")
    else:
        text = (f"at the tool, by the identified model, commanded points land within "
                f"{before} {where} as the machine stands, the offsets not "
                f"written; written, they would land within {after}")
    why = cause(acc, result)
    return text + (f": {why}" if why else "")


# -------------------------------------------------------------------- summary


def objective_lines(result: RunResult) -> list[str]:
    """The objective written and what the other would leave (plug-in figures of the
    offsets each would write: no interval, so no ±)."""
    acc, why_not = statement(result)
    if acc is None:
        return [f"  at the tool   not stated: {why_not}"] if why_not else []
    state, alt = "written" if written(result) else "NOT written", acc.alternative
    return [f"  objective     {acc.objective} ({OBJECTIVE_TEXT[acc.objective]}) {state}; "
            f"objective {alt.objective} would leave {um(alt.after.rms_mm)} µm RMS (max "
            f"{um(alt.after.max_mm)} µm), frame {acc.frame}"]


def summary_lines(result: RunResult) -> list[str]:
    """The summary's details on the tool (its figures are the first screen's): the
    objective and what the other would leave, the geometry in the controller, the
    squareness, the gaps and the legs' form."""
    acc, why_not = statement(result)
    if acc is None:
        return [f"  at the tool   not stated: {why_not}"] if why_not else []
    # the figures before → after are the first screen's (station.report.first_screen)
    state = "written" if written(result) else "NOT written"
    alt = acc.alternative
    line = (f"  objective     {acc.objective} ({OBJECTIVE_TEXT[acc.objective]}) {state}, the "
            f"tool's error in frame {acc.frame} (identified model); objective "
            f"{alt.objective} would leave {um(alt.after.rms_mm)} µm RMS (max "
            f"{um(alt.after.max_mm)} µm)")
    return [line, *in_controller.summary_lines(acc), squareness_line(acc),
            *gaps.summary_lines(acc), *leg_form.summary_lines(result)]


# ----------------------------------------------------------------------- html


def html_section(result: RunResult, figure: str | None = None,
                 number: int | None = None) -> str:
    """The section "Accuracy at the tool" of report.html; ``figure`` the error
    field's inline SVG (field_plot.plot_field), ``number`` its figure number. Empty for
    a run that never got as far as stating it and has no block."""
    acc, why_not = statement(result)
    head = '<h2 id="accuracy">Accuracy at the tool</h2>'
    if acc is None:
        if why_not is None:
            if not any(n.startswith("drho_") for n in result.identified):
                return ""
            why_not = "this result holds no accuracy block"
        return (f'{head}<div class="box warn"><p>Accuracy at the tool is <b>not stated</b> '
                f"for this run: {esc(why_not)}. The legs' parallelism reported here is the "
                "method's means and does not say where the tool goes.</p></div>")
    square = squareness_table.stated_html(result)
    parts = [head, _intro(result, acc), _before_after(result, acc),
             in_controller.html_section(acc, result), _objectives(result, acc),
             legacy_html(acc) if square is None else square, gaps.html_section(acc, result)]
    if bows := leg_form.html_section(result):
        parts.append(bows)
    if figure:
        label = f"Figure {number}. " if number is not None else ""
        parts.append(f"<figure>{figure}<figcaption>{label}{_field_caption(acc)}</figcaption>"
                     "</figure>")
    if acc.assumes:
        parts.append("<h3>What these figures assume</h3><ul>"
                     + "".join(f"<li>{esc(a)}</li>" for a in acc.assumes) + "</ul>")
    parts.append("<p>The run directory holds <code>model.json</code>: the identified machine "
                 "(Δρ, ΔL, the tilts and the gaps, with standard errors, covariance, "
                 "conventions and units), for a controller that compensates kinematics, which "
                 "can correct the squareness and the gaps that offsets cannot.</p>")
    return "\n".join(parts)


def _intro(result: RunResult, acc: Accuracy) -> str:
    g = acc.grid
    grid = f" ({esc(g.points_per_axis)} points per axis; {esc(g.points)} points"
    grid += f", {esc(g.excluded)} outside the soft limits left out)" if g.excluded else ")"
    why = cause(acc, result)
    left = f" What is left after calibration: {esc(why)}." if why else ""
    return (
        "<p>Parallel legs are the method's means, not its end: the machine's user cares "
        "where the tool goes. For each commanded point of a grid over the workspace "
        f"{esc(box_text(acc.workspace_mm))}{grid}, the identified machine says where "
        "the tool lands; the error E, stated as |E| in µm, is what remains after fitting "
        f"away {esc(FRAME_TEXT[acc.frame])} (frame <code>{esc(acc.frame)}</code>).{left}</p>")


def _before_after(result: RunResult, acc: Accuracy) -> str:
    done = written(result)
    after_head = "after (offsets written)" if done else "after, had the offsets been written"
    q = stated(result)
    if "tool.after.rms" in q:  # the statement's figures, each once
        rows = [[f"{label} |E|", um(q[f"tool.before.{s}"].value), um(q[f"tool.after.{s}"].value),
                 interval(q[f"tool.after.{s}"]).removesuffix(" µm")]
                for label, s in (("RMS", "rms"), ("max", "max"))]
    else:
        before, after = acc.before, acc.after
        rows = [["RMS |E|", um(before.rms_mm), um(after.rms_mm),
                 um_interval(after.rms_interval_95_mm) or "—"],
                ["max |E|", um(before.max_mm), um(after.max_mm),
                 um_interval(after.max_interval_95_mm) or "—"]]
    table = html_table(["tool-point error (µm)", "before (offsets as they were)",
                    esc(after_head), "after: 95 % interval"], rows)
    basis = ("After: Δρ as the last verification measured it, with the tilts the run states."
             if result.remaining is not None and done else
             "After: predicted, the correction taken as written exactly.")
    method = f" Interval: {esc(acc.after_method)}." if acc.after_method else ""
    not_done = ("" if done else " <b>The offsets were not written</b>: the machine is still "
                "as in the column \"before\".")
    return f'{table}<p class="small">{esc(basis)}{method}{not_done}</p>'


def _objectives(result: RunResult, acc: Accuracy) -> str:
    rows, offsets = [], []  # the figures in µm, the offsets in mm: one unit a table
    names: tuple[Objective, ...] = ("joints", "tool")
    for name in names:
        obj, label = objective(acc, name), f"{esc(name)}: {esc(OBJECTIVE_TEXT[name])}"
        mark = ("not chosen" if name != acc.objective else "<b>written</b>"
                if written(result) else "<b>chosen</b> (not written)")
        rows.append([label, um(obj.after.rms_mm), um(obj.after.max_mm), mark])
        offsets.append([label, *(fmt(at(obj.offsets_mm, a), signed=True) for a in AXES)])
    table = (html_table(["objective (tool error, µm)", "after: RMS |E|", "after: max |E|",
                     "this run"], rows)
             + html_table(["objective (offsets, mm)", *(f"o<sub>{a}</sub>" for a in AXES)],
                      offsets))
    return ("<h3>The two objectives</h3>" + table +
            '<p class="small">Each objective\'s predicted figures with its offsets written '
            "exactly, and the offset registers it writes. <code>[writeback] objective</code> "
            "chooses: <i>joints</i> writes the paper's correction o<sub>i</sub> ← "
            "o<sub>i</sub> − Δρ<sub>i</sub> (legs parallel); <i>tool</i> writes the offsets "
            "that minimise the predicted RMS tool error, cancelling part of what the tilts "
            "leave. Written registers are rounded to the controller's resolution.</p>")


def _field_caption(acc: Accuracy) -> str:
    return ("The tool-point error E over the workspace, in three horizontal slices of the "
            "grid (lowest, middle and highest z), before calibration (top row), after "
            "(second row) and, where the run states it, with the identified geometry in the "
            "controller (bottom row: the |E| expected, no arrows, since what is left there is "
            "the identification's error). Colour: |E| in µm, each row on its own scale; "
            "arrows: the x–y part "
            "of E, to the scale of the arrow in the corner (its z part shows in the colour "
            f"only); after fitting away {esc(FRAME_TEXT[acc.frame])}. Blank cells are "
            "grid points outside the soft limits.")


