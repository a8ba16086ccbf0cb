"""Accuracy at the tool in the report (docs/design.md and docs/model.md, "Accuracy at the
tool"): the result's ``accuracy`` block as the headline's clause, the summary's
lines and report.html's section, and the ``stands`` table.

Parallel legs are the method's means, not its end: the machine's user cares where
the tool goes. So wherever the report states the legs' parallelism it also states
the tool's figure, or says that the run does not state one; the two must never be
read as the same thing. The block may be absent (an old result, a run that stopped
before identifying Δρ) or not stated (``accuracy: {"error": ...}``): the readers
here return None or say "not stated".
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass

from station.record.result import RunResult
from station.record.result_accuracy import (
    Accuracy,
    AfterInterval,
    ErrorStats,
    Objective,
    ObjectiveFigures,
)
from station.record.result_base import Interval, NotStated
from station.report import gaps, in_controller, leg_form
from station.report.format import (
    AXES,
    at,
    box_text,
    fmt,
    num,
    param_html,
    um,
    um_interval,
)

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
#: Squareness of the tool's motions and the tilt it equals to first order (docs/model.md).
PAIRS = (("xy", "tilt_yx"), ("xz", "tilt_zx"), ("yz", "tilt_zy"))
#: Coverage factor of a 95 % interval when the result gives none (normal).
K_NORMAL = 1.96
#: The tilts are "most of it" when the legs exactly parallel would still leave at
#: least this fraction of the after-figure (the tilts alone cause that much).
MOST = 0.5
_NOT_STATED = "not stated: "


def _e(value: object) -> str:
    return html.escape(str(value), quote=True)


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


@dataclass(frozen=True)
class Square:
    """One squareness (mm/m) with its 95 % half-width and the tilt it mirrors."""

    pair: str
    value: float
    se: float | None
    half: float | None
    k: float | None
    tilt: str
    # beyond this |value| the axis counts as leaning (the result's
    # squareness_decision); inf: the model test kept no tilt; None: the 95 % half
    limit: float | None = None

    @property
    def significant(self) -> bool | None:
        limit = self.limit if self.limit is not None else self.half
        return None if limit is None else abs(self.value) > limit

    @property
    def beyond_95(self) -> bool:
        """The 95 % interval excludes zero: the motions are out of square, whatever
        the decision on the axis' lean (the gaps and the offsets written shear the
        motions too, and the lean is decided at a stricter k or by the model test)."""
        return self.half is not None and abs(self.value) > self.half

    @property
    def verdict(self) -> str:
        """The row's word, which never says "within" of an interval that excludes zero."""
        if self.significant:
            return "beyond its uncertainty"
        if self.beyond_95:
            return "beyond its 95 % interval; no lean of the axis told apart"
        return "within its uncertainty" if self.significant is False else "—"


def _half_width(interval: Interval | None) -> float | None:
    lo, hi = (None, None) if interval is None else (num(interval[0]), num(interval[1]))
    return None if lo is None or hi is None else (hi - lo) / 2


def _decision_k(acc: Accuracy) -> float | None:
    """The result's squareness_decision's k: inf where the model test kept no tilt
    (no axis counts as leaning), None where the result states no decision."""
    decision = acc.squareness_decision
    if decision is None:
        return None
    k = num(decision.k)
    return math.inf if k is None else k


def squareness(acc: Accuracy) -> list[Square]:
    """The squareness values of the result, each with its 95 % half-width: k from
    the tilt's interval where the result gives one, else k = 1.96, on the
    squareness' standard error."""
    tilt_iv = acc.tilt_interval_95 or {}
    k_decide = _decision_k(acc)
    out = []
    for pair, tilt in PAIRS:
        v = at(acc.squareness_mm_per_m, pair)
        if v is None:
            continue
        se = at(acc.squareness_std_errors, pair)
        se = se if se is not None and se > 0 else None
        half = k = None
        if se is not None:
            k = K_NORMAL
            t_half, t_se = _half_width(tilt_iv.get(tilt)), at(acc.tilt_std_errors, tilt)
            if t_se and t_half is not None:
                k = t_half / t_se
            half = k * se
        limit = None if k_decide is None or se is None else k_decide * se
        out.append(Square(pair, v, se, half, k, tilt, limit))
    return out


def tilts_stated(acc: Accuracy) -> bool:
    """The tilts entered the figure (without them squareness is not stated)."""
    return bool(acc.tilts)


def square_state(acc: Accuracy) -> bool | None:
    """True: some axis leans (beyond the result's squareness_decision, else its 95 %
    interval); False: none; None: not stated (no tilts, or no uncertainty)."""
    if not tilts_stated(acc):
        return None
    verdicts = [s.significant for s in squareness(acc)]
    if not verdicts or any(v is None for v in verdicts):
        return None
    return any(verdicts)


def cause(acc: Accuracy) -> str | None:
    """What the after-figure is made of, in words: the squareness (which no offset
    fixes) when the tilts alone would leave most of it, else the joint offsets."""
    after = num(acc.after.rms_mm)
    state = square_state(acc)
    if after is None or state is None:
        return None
    if state is False:
        if any(s.beyond_95 for s in squareness(acc)):
            return ("no axis leans beyond what the data tell apart (nothing to shim); the "
                    "motions' squareness beyond its interval is the gaps' and the offsets' "
                    "shear")
        return "the axes are square within their uncertainty (nothing to shim)"
    legs = num(acc.objectives.joints.after.rms_mm)
    best = num(acc.objectives.tool.after.rms_mm)
    if legs is not None and legs >= MOST * after:
        text = "the axes' squareness, which offsets cannot fix, is most of it"
        if acc.objective == "joints" and best is not None and best < 0.8 * after:
            text += (f" (objective tool's offsets would cancel part of it, to {um(best)} µm "
                     "RMS)")
        elif acc.objective == "tool" and legs > 1.2 * after:
            text += (f" (the offsets cancel part of it: with the legs exactly parallel it "
                     f"would be {um(legs)} µm RMS)")
        return text
    if legs is None:
        return None
    return (f"most of it is joint offset left uncorrected (with the legs exactly parallel "
            f"it would be {um(legs)} µm RMS); the axes' squareness, which offsets cannot "
            "fix, is the rest")


def _figures(block: ErrorStats) -> str:
    """"13.7 µm RMS (max 33.3 µm; 95 %: 12.0–15.0 µm RMS, 28.2–37.5 µm max)", the
    intervals where the block states them (the after-figures)."""
    text = f"{um(block.rms_mm)} µm RMS (max {um(block.max_mm)} µm"
    if isinstance(block, AfterInterval):
        ivs = [f"{iv} µm {what}" for iv, what in (
            (um_interval(block.rms_interval_95_mm), "RMS"),
            (um_interval(block.max_interval_95_mm), "max")) if iv]
        if ivs:
            text += "; 95 %: " + ", ".join(ivs)
    return text + ")"


def tool_clause(result: RunResult) -> str | None:
    """The headline's clause on the tool, plain text, lower case; None when the
    run states no accuracy (the caller says so)."""
    acc, _ = statement(result)
    if acc is None:
        return None
    where = (f"of where they should over the workspace {box_text(acc.workspace_mm)} "
             f"(frame {acc.frame})")
    if written(result):
        text = ("at the tool, by the identified model, commanded points land within "
                f"{_figures(acc.after)} {where}, against {_figures(acc.before)} before "
                "calibration")
    else:
        text = (f"at the tool, by the identified model, commanded points land within "
                f"{_figures(acc.before)} {where} as the machine stands, the offsets not "
                f"written; written, they would land within {_figures(acc.after)}")
    why = cause(acc)
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
    return [line, *in_controller.summary_lines(acc), _squareness_line(acc),
            *gaps.summary_lines(acc), *leg_form.summary_lines(result)]


def _squareness_line(acc: Accuracy) -> str:
    rows = squareness(acc)
    if not tilts_stated(acc) or not rows:
        advice = acc.squareness_advice
        return "  squareness    not stated" + (f": {advice[0]}" if advice else "")
    values = ", ".join(f"{s.pair.upper()} {fmt(s.value, signed=True)}"
                       + (f" ± {fmt(s.half)}" if s.half is not None else "") for s in rows)
    state = square_state(acc)
    ks = {round(s.k, 2) for s in rows if s.k is not None}
    band = f" (95 %, k = {ks.pop():.2f})" if len(ks) == 1 else " (95 %)"
    text = f"  squareness    {values} mm/m{band if any(s.half for s in rows) else ''}"
    if state:
        text += (": offsets cannot fix it; shim the rails or put the geometry into the "
                 "controller (orthocal export --kinematics, or orthocal compensate)")
    elif state is False:
        sheared = [s.pair.upper() for s in rows if s.beyond_95]
        kept_none = all(s.limit == math.inf for s in rows)
        if sheared:
            text += (f": the motions {', '.join(sheared)} are out of square beyond their "
                     "95 % interval, yet no axis leans beyond what the data tell apart ("
                     + ("the model test kept no tilt" if kept_none else
                        "its decision limit") + "): the gaps and the offsets written shear "
                     "the motions, not the rails (nothing to shim)")
        else:
            text += ": square within its uncertainty"
    return text


# ----------------------------------------------------------------------- html


def _table(head: list[str], rows: list[list[str]], left: int = 1) -> str:
    ths = "".join(f'<th class="l">{h}</th>' if i < left else f"<th>{h}</th>"
                  for i, h in enumerate(head))
    body = "".join("<tr>" + "".join(
        f'<td class="l">{c}</td>' if i < left else f'<td class="num">{c}</td>'
        for i, c in enumerate(row)) + "</tr>" for row in rows)
    return f"<table><thead><tr>{ths}</tr></thead><tbody>{body}</tbody></table>"


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
                f"for this run: {_e(why_not)}. The legs' parallelism reported here is the "
                "method's means and does not say where the tool goes.</p></div>")
    parts = [head, _intro(acc), _before_after(result, acc), in_controller.html_section(acc),
             _objectives(result, acc), _squareness_html(acc), gaps.html_section(acc)]
    if bows := leg_form.html_section(result):
        parts.append(bows)
    if figure:
        label = f"Figure {number}. " if number is not None else ""
        parts.append(f"<figure>{figure}<figcaption>{label}{_field_caption(acc)}</figcaption>"
                     "</figure>")
    if acc.assumes:
        parts.append("<h3>What these figures assume</h3><ul>"
                     + "".join(f"<li>{_e(a)}</li>" for a in acc.assumes) + "</ul>")
    parts.append("<p>The run directory holds <code>model.json</code>: the identified machine "
                 "(Δρ, ΔL, the tilts and the gaps, with standard errors, covariance, "
                 "conventions and units), for a controller that compensates kinematics, which "
                 "can correct the squareness and the gaps that offsets cannot.</p>")
    return "\n".join(parts)


def _intro(acc: Accuracy) -> str:
    g = acc.grid
    grid = f" ({_e(g.points_per_axis)} points per axis; {_e(g.points)} points"
    grid += f", {_e(g.excluded)} outside the soft limits left out)" if g.excluded else ")"
    why = cause(acc)
    left = f" What is left after calibration: {_e(why)}." if why else ""
    return (
        "<p>Parallel legs are the method's means, not its end: the machine's user cares "
        "where the tool goes. For each commanded point of a grid over the workspace "
        f"{_e(box_text(acc.workspace_mm))}{grid}, the identified machine says where "
        "the tool lands; the error E, stated as |E| in µm, is what remains after fitting "
        f"away {_e(FRAME_TEXT[acc.frame])} (frame <code>{_e(acc.frame)}</code>).{left}</p>")


def _before_after(result: RunResult, acc: Accuracy) -> str:
    before, after = acc.before, acc.after
    done = written(result)
    after_head = "after (offsets written)" if done else "after, had the offsets been written"
    rows = [
        ["RMS |E|", um(before.rms_mm), um(after.rms_mm),
         um_interval(after.rms_interval_95_mm) or "—"],
        ["max |E|", um(before.max_mm), um(after.max_mm),
         um_interval(after.max_interval_95_mm) or "—"],
    ]
    table = _table(["tool-point error (µm)", "before (offsets as they were)",
                    _e(after_head), "after: 95 % interval"], rows)
    basis = ("After: Δρ as the last verification measured it, with the tilts the run states."
             if result.remaining is not None and done else
             "After: predicted, the correction taken as written exactly.")
    method = f" Interval: {_e(acc.after_method)}." if acc.after_method else ""
    not_done = ("" if done else " <b>The offsets were not written</b>: the machine is still "
                "as in the column \"before\".")
    return f'{table}<p class="small">{_e(basis)}{method}{not_done}</p>'


def _objectives(result: RunResult, acc: Accuracy) -> str:
    rows, offsets = [], []  # the figures in µm, the offsets in mm: one unit a table
    names: tuple[Objective, ...] = ("joints", "tool")
    for name in names:
        obj, label = objective(acc, name), f"{_e(name)}: {_e(OBJECTIVE_TEXT[name])}"
        mark = ("not chosen" if name != acc.objective else "<b>written</b>"
                if written(result) else "<b>chosen</b> (not written)")
        rows.append([label, um(obj.after.rms_mm), um(obj.after.max_mm), mark])
        offsets.append([label, *(fmt(at(obj.offsets_mm, a), signed=True) for a in AXES)])
    table = (_table(["objective (tool error, µm)", "after: RMS |E|", "after: max |E|",
                     "this run"], rows)
             + _table(["objective (offsets, mm)", *(f"o<sub>{a}</sub>" for a in AXES)],
                      offsets))
    return ("<h3>The two objectives</h3>" + table +
            '<p class="small">Each objective\'s predicted figures with its offsets written '
            "exactly, and the offset registers it writes. <code>[writeback] objective</code> "
            "chooses: <i>joints</i> writes the paper's correction o<sub>i</sub> ← "
            "o<sub>i</sub> − Δρ<sub>i</sub> (legs parallel); <i>tool</i> writes the offsets "
            "that minimise the predicted RMS tool error, cancelling part of what the tilts "
            "leave. Written registers are rounded to the controller's resolution.</p>")


def _squareness_html(acc: Accuracy) -> str:
    rows = squareness(acc)
    advice = acc.squareness_advice
    out = ["<h3>Squareness of the axes</h3>"]
    if not tilts_stated(acc) or not rows:
        out.append("<p>Squareness is not stated: the tilts were not identified.</p>")
        out.extend(f"<p>{_e(a)}</p>" for a in advice if "not stated" not in a)
        return "".join(out)
    table_rows = []
    for s in rows:
        t, t_se = at(acc.tilts, s.tilt), at(acc.tilt_std_errors, s.tilt)
        verdict = s.verdict
        table_rows.append([
            s.pair.upper(), fmt(s.value, signed=True),
            fmt(s.half) if s.half is not None else "—",
            fmt(s.se, 4) if s.se is not None else "—",
            param_html(s.tilt) + f" = {fmt(t, signed=True)}"
            + (f" ± {fmt(t_se, 4)}" if t_se is not None else ""), verdict])
    ks = {round(s.k, 2) for s in rows if s.k is not None}
    k_text = f"k = {ks.pop():.2f}" if len(ks) == 1 else "k from each interval"
    out.append(_table(["motions (mm/m)", "squareness", f"± 95 % ({k_text})", "σ",
                       "axis tilt ± σ", "verdict"], table_rows))
    out.append('<p class="small">ISO 230-1 squareness of the tool\'s motions along commanded '
               "x, y and z; to first order it equals the tilts of the actuator axes "
               "(1 mrad = 1 mm/m). The offsets written shear the motions a little, so the two "
               "columns differ by that. Offsets cannot fix squareness.</p>")
    decision = acc.squareness_decision
    if decision is not None and decision.rule:
        out.append(f'<p class="small">Verdict: {_e(decision.rule)}.</p>')
    if advice:
        out.append("<p><b>What to do:</b></p><ul>"
                   + "".join(f"<li>{_e(a)}</li>" for a in advice) + "</ul>")
    return "".join(out)


def _field_caption(acc: Accuracy) -> str:
    return ("The tool-point error E over the workspace, in three horizontal slices of the "
            "grid (lowest, middle and highest z), before calibration (top row), after "
            "(second row) and, where the run states it, with the identified geometry in the "
            "controller (bottom row: the |E| expected, no arrows, since what is left there is "
            "the identification's error). Colour: |E| in µm, each row on its own scale; "
            "arrows: the x–y part "
            "of E, to the scale of the arrow in the corner (its z part shows in the colour "
            f"only); after fitting away {_e(FRAME_TEXT[acc.frame])}. Blank cells are "
            "grid points outside the soft limits.")


# --------------------------------------------------------------------- stands


def stands_html(result: RunResult) -> str:
    """The table "Where the stands were": each indicator stand, set by eye at the
    middle of its leg, as the identification placed it (or not observable)."""
    stands = result.stands
    if not stands:
        return ""
    rows = []
    for name, est in stands.items():
        where = ", ".join(f"leg {g[0]}, along {g[1]}" if len(g) == 2 else g
                          for g in est.gauges)
        off, se = num(est.offset_mm), num(est.std_error_mm)
        if est.observable and off is not None:
            value, sigma, note = fmt(off, 2, signed=True), fmt(se, 2), ""
        else:
            value, sigma = "—", "—"
            note = est.note or "not observable"
        rows.append([_e(name), _e(where or "—"), value, sigma, _e(note)])
    return ("<h3>Where the stands were</h3>"
            + _table(["stand", "indicator", "m: off the leg's middle (mm)", "σ (mm)", "note"],
                     rows, left=2)
            + '<p class="small">Each indicator stand is set by eye at the middle of its leg; '
            "its indicator reads in the plane x<sub>i</sub> = L/2 + m. The identification "
            f"estimates each m as a random effect{_e(_stands_known(result))}, so that a "
            "misplaced stand is not read as a tilt. Not observable: the offsets Δρ were too "
            "small for that stand to change the deviations; the data say nothing of where it "
            "stood.</p>")


def _stands_known(result: RunResult) -> str:
    """What the stands' prior was, in words (" (within ±5 mm of L/2, prior SD 2.89
    mm)"), from model_selection.stands, else the estimates' common prior."""
    sel = result.model_selection.stands if result.model_selection is not None else None
    tol = num(sel.tolerance_mm) if sel is not None else None
    prior = num(sel.prior_sd_mm) if sel is not None else None
    if prior is None and result.stands:
        priors = {num(e.prior_sd_mm) for e in result.stands.values()} - {None}
        prior = priors.pop() if len(priors) == 1 else None
    known = []
    if tol is not None:
        known.append(f"within ±{tol:g} mm of L/2")
    if prior is not None:
        known.append(f"prior SD {fmt(prior, 2)} mm")
    return f" ({', '.join(known)})" if known else ""
