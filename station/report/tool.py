"""Accuracy at the tool in the report (docs/design.md and docs/model.md, "Accuracy at the
tool"): the result's ``accuracy`` block as the headline's clause, the summary's
lines and report.html's section, and the ``stands`` table.

Parallel legs are the method's means, not its end: the machine's user cares where
the tool goes. So wherever the report states the legs' parallelism it also states
the tool's figure, or says that the run does not state one; the two must never be
read as the same thing. Every field may be missing (an old result, a run that
failed halfway, ``accuracy: {"error": ...}``): the readers here return None or
say "not stated", never raise.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from station.report import form, gaps, in_controller
from station.report.format import (
    AXES,
    as_dict,
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


def _e(value: Any) -> str:
    return html.escape(str(value), quote=True)


# -------------------------------------------------------------------- readers


def statement(result: Mapping[str, Any]) -> tuple[dict[str, Any] | None, str | None]:
    """(the accuracy block, None) when the run states it; (None, why not) when it
    tried and could not; (None, None) when the result has no such block (an old
    result, or a run that stopped before identifying Δρ)."""
    acc = result.get("accuracy")
    if acc is None:
        return None, None
    if not isinstance(acc, Mapping):
        return None, "the result's accuracy block is not readable"
    if acc.get("error"):
        text = str(acc["error"])
        return None, text[len("not stated: "):] if text.startswith("not stated: ") else text
    if not as_dict(acc.get("after")) and not as_dict(acc.get("before")):
        return None, "the result's accuracy block holds no figures"
    return dict(acc), None


def written(result: Mapping[str, Any]) -> bool:
    """Whether offsets reached the controller: the after-figures are the machine
    now only then; otherwise they are what writing would give."""
    w = result.get("offsets_written")
    return isinstance(w, Mapping) and bool(w)


def _rms(block: Any) -> float | None:
    return num(as_dict(block).get("rms_mm"))


def _objective_after(acc: Mapping[str, Any], name: str) -> dict[str, Any]:
    return as_dict(as_dict(as_dict(acc.get("objectives")).get(name)).get("after"))


def alternative(acc: Mapping[str, Any]) -> tuple[str | None, dict[str, Any]]:
    """(name, after-figures) of the objective not chosen."""
    alt = as_dict(acc.get("alternative"))
    name = alt.get("objective")
    if name is None:
        chosen = acc.get("objective")
        name = {"joints": "tool", "tool": "joints"}.get(str(chosen))
    after = as_dict(alt.get("after")) or (_objective_after(acc, str(name)) if name else {})
    return (str(name) if name is not None else None), after


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


def squareness(acc: Mapping[str, Any]) -> list[Square]:
    """The squareness values of the result, each with its 95 % half-width: from
    an interval the result gives (its own, else the tilt's coverage factor),
    else k = 1.96 on the standard error."""
    values = as_dict(acc.get("squareness_mm_per_m"))
    ses = as_dict(acc.get("squareness_std_errors"))
    own = as_dict(acc.get("squareness_interval_95"))
    tilt_iv = as_dict(acc.get("tilt_interval_95"))
    tilt_se = as_dict(acc.get("tilt_std_errors"))
    decision = acc.get("squareness_decision")
    k_decide: float | None = None
    if isinstance(decision, Mapping):
        k_decide = num(decision.get("k"))
        k_decide = math.inf if k_decide is None else k_decide
    out = []
    for pair, tilt in PAIRS:
        v = num(values.get(pair))
        if v is None:
            continue
        se = num(ses.get(pair))
        se = se if se is not None and se > 0 else None
        half = k = None
        lo_hi = own.get(pair)
        if isinstance(lo_hi, list | tuple) and len(lo_hi) == 2 and \
                num(lo_hi[0]) is not None and num(lo_hi[1]) is not None:
            half = (num(lo_hi[1]) - num(lo_hi[0])) / 2
            k = half / se if se else None
        elif se is not None:
            k = K_NORMAL
            t_iv, t_se = tilt_iv.get(tilt), num(tilt_se.get(tilt))
            if isinstance(t_iv, list | tuple) and len(t_iv) == 2 and t_se and \
                    num(t_iv[0]) is not None and num(t_iv[1]) is not None:
                k = (num(t_iv[1]) - num(t_iv[0])) / 2 / t_se
            half = k * se
        limit = None if k_decide is None or se is None else k_decide * se
        out.append(Square(pair, v, se, half, k, tilt, limit))
    return out


def tilts_stated(acc: Mapping[str, Any]) -> bool:
    """The tilts entered the figure (without them squareness is not stated)."""
    return isinstance(acc.get("tilts"), Mapping) and bool(acc["tilts"])


def square_state(acc: Mapping[str, Any]) -> bool | None:
    """True: some axis leans (beyond the result's squareness_decision, else its 95 %
    interval); False: none; None: not stated (no tilts, or no uncertainty)."""
    if not tilts_stated(acc):
        return None
    verdicts = [s.significant for s in squareness(acc)]
    if not verdicts or any(v is None for v in verdicts):
        return None
    return any(verdicts)


def cause(acc: Mapping[str, Any]) -> str | None:
    """What the after-figure is made of, in words: the squareness (which no offset
    fixes) when the tilts alone would leave most of it, else the joint offsets."""
    after = _rms(acc.get("after"))
    state = square_state(acc)
    if after is None or state is None:
        return None
    if state is False:
        return "the axes are square within their uncertainty (nothing to shim)"
    legs = num(_objective_after(acc, "joints").get("rms_mm"))
    best = num(_objective_after(acc, "tool").get("rms_mm"))
    chosen = acc.get("objective")
    if legs is not None and legs >= MOST * after:
        text = "the axes' squareness, which offsets cannot fix, is most of it"
        if chosen == "joints" and best is not None and best < 0.8 * after:
            text += (f" (objective tool's offsets would cancel part of it, to {um(best)} µm "
                     "RMS)")
        elif chosen == "tool" and legs > 1.2 * after:
            text += (f" (the offsets cancel part of it: with the legs exactly parallel it "
                     f"would be {um(legs)} µm RMS)")
        return text
    if legs is None:
        return None
    return (f"most of it is joint offset left uncorrected (with the legs exactly parallel "
            f"it would be {um(legs)} µm RMS); the axes' squareness, which offsets cannot "
            "fix, is the rest")


def _figures(block: Mapping[str, Any], with_interval: bool) -> str:
    """"13.7 µm RMS (max 33.3 µm; 95 %: 12.0–15.0 µm RMS, 28.2–37.5 µm max)"."""
    text = f"{um(block.get('rms_mm'))} µm RMS (max {um(block.get('max_mm'))} µm"
    if with_interval:
        ivs = [f"{iv} µm {what}" for iv, what in (
            (um_interval(block.get("rms_interval_95_mm")), "RMS"),
            (um_interval(block.get("max_interval_95_mm")), "max")) if iv]
        if ivs:
            text += "; 95 %: " + ", ".join(ivs)
    return text + ")"


def tool_clause(result: Mapping[str, Any]) -> str | None:
    """The headline's clause on the tool, plain text, lower case; None when the
    run states no accuracy (the caller says so)."""
    acc, _ = statement(result)
    if acc is None:
        return None
    before, after = as_dict(acc.get("before")), as_dict(acc.get("after"))
    where = (f"of where they should over the workspace {box_text(acc.get('workspace_mm'))} "
             f"(frame {acc.get('frame', '—')})")
    if written(result) or not before:
        text = ("at the tool, by the identified model, commanded points land within "
                f"{_figures(after, True)} {where}")
        if before:
            text += f", against {_figures(before, False)} before calibration"
    else:
        text = (f"at the tool, by the identified model, commanded points land within "
                f"{_figures(before, False)} {where} as the machine stands, the offsets not "
                f"written; written, they would land within {_figures(after, True)}")
    why = cause(acc)
    return text + (f": {why}" if why else "")


# -------------------------------------------------------------------- summary


def summary_lines(result: Mapping[str, Any]) -> list[str]:
    """The summary's "at the tool" line (before → after, the interval, the
    objective and what the other would leave) and its "squareness" line."""
    acc, why_not = statement(result)
    if acc is None:
        return [f"  at the tool   not stated: {why_not}"] if why_not else []
    before, after = as_dict(acc.get("before")), as_dict(acc.get("after"))
    rms_iv = um_interval(after.get("rms_interval_95_mm"))
    max_iv = um_interval(after.get("max_interval_95_mm"))
    rms_after = f"{um(after.get('rms_mm'))} µm RMS" + (f" (95 %: {rms_iv})" if rms_iv else "")
    max_after = f"{um(after.get('max_mm'))} µm" + (f" (95 %: {max_iv})" if max_iv else "")
    chosen = str(acc.get("objective", "—"))
    if written(result):
        state = "written"
        figures = (f"{um(before.get('rms_mm'))} → {rms_after}, max "
                   f"{um(before.get('max_mm'))} → {max_after}")
    else:  # no arrow: nothing changed on the machine
        state = "NOT written"
        figures = (f"{um(before.get('rms_mm'))} µm RMS (max {um(before.get('max_mm'))} µm) as "
                   f"the machine stands; written, the offsets would leave {rms_after}, max "
                   f"{max_after}")
    line = (f"  at the tool   {figures}, over {box_text(acc.get('workspace_mm'))}, frame "
            f"{acc.get('frame', '—')} (identified model); objective {chosen} "
            f"({OBJECTIVE_TEXT.get(chosen, chosen)}) {state}")
    alt_name, alt_after = alternative(acc)
    if alt_name and alt_after:
        line += (f"; objective {alt_name} would leave {um(alt_after.get('rms_mm'))} µm RMS "
                 f"(max {um(alt_after.get('max_mm'))} µm)")
    return [line, *in_controller.summary_lines(acc), _squareness_line(acc),
            *gaps.summary_lines(result), *form.summary_lines(result)]


def _squareness_line(acc: Mapping[str, Any]) -> str:
    rows = squareness(acc)
    if not tilts_stated(acc) or not rows:
        advice = [str(a) for a in acc.get("squareness_advice") or []]
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


def html_section(result: Mapping[str, Any], figure: str | None = None,
                 number: int | None = None) -> str:
    """The section "Accuracy at the tool" of report.html; ``figure`` the error
    field's inline SVG (plots.plot_field), ``number`` its figure number. Empty for
    a run that never got as far as stating it and has no block."""
    acc, why_not = statement(result)
    head = '<h2 id="accuracy">Accuracy at the tool</h2>'
    if acc is None:
        if why_not is None:
            ident = as_dict(result.get("identified"))
            if not any(n.startswith("drho_") for n in ident):
                return ""
            why_not = "this result holds no accuracy block"
        return (f'{head}<div class="box warn"><p>Accuracy at the tool is <b>not stated</b> '
                f"for this run: {_e(why_not)}. The legs' parallelism reported here is the "
                "method's means and does not say where the tool goes.</p></div>")
    parts = [head, _intro(result, acc), _before_after(result, acc), in_controller.html_section(acc),
             _objectives(result, acc),
             _squareness_html(acc), gaps.html_section(acc)]
    if bows := form.html_section(result):
        parts.append(bows)
    if figure:
        label = f"Figure {number}. " if number is not None else ""
        parts.append(f"<figure>{figure}<figcaption>{label}{_field_caption(acc)}</figcaption>"
                     "</figure>")
    assumes = [str(a) for a in acc.get("assumes") or []]
    if assumes:
        parts.append("<h3>What these figures assume</h3><ul>"
                     + "".join(f"<li>{_e(a)}</li>" for a in assumes) + "</ul>")
    parts.append("<p>The run directory holds <code>model.json</code>: the identified machine "
                 "(Δρ, ΔL, the tilts and the gaps, with standard errors, covariance, "
                 "conventions and units), for a controller that compensates kinematics, which "
                 "can correct the squareness and the gaps that offsets cannot.</p>")
    return "\n".join(parts)


def _intro(result: Mapping[str, Any], acc: Mapping[str, Any]) -> str:
    g = as_dict(acc.get("grid"))
    grid = ""
    if g.get("points") is not None:
        grid = f" ({_e(g.get('points_per_axis', '—'))} points per axis; {_e(g['points'])} points"
        grid += (f", {_e(g['excluded'])} outside the soft limits left out)"
                 if g.get("excluded") else ")")
    frame = str(acc.get("frame", "—"))
    why = cause(acc)
    left = f" What is left after calibration: {_e(why)}." if why else ""
    return (
        "<p>Parallel legs are the method's means, not its end: the machine's user cares "
        "where the tool goes. For each commanded point of a grid over the workspace "
        f"{_e(box_text(acc.get('workspace_mm')))}{grid}, the identified machine says where "
        "the tool lands; the error E, stated as |E| in µm, is what remains after fitting "
        f"away {_e(FRAME_TEXT.get(frame, frame))} (frame <code>{_e(frame)}</code>).{left}</p>")


def _before_after(result: Mapping[str, Any], acc: Mapping[str, Any]) -> str:
    before, after = as_dict(acc.get("before")), as_dict(acc.get("after"))
    done = written(result)
    after_head = "after (offsets written)" if done else "after, had the offsets been written"
    rows = [
        ["RMS |E|", um(before.get("rms_mm")), um(after.get("rms_mm")),
         um_interval(after.get("rms_interval_95_mm")) or "—"],
        ["max |E|", um(before.get("max_mm")), um(after.get("max_mm")),
         um_interval(after.get("max_interval_95_mm")) or "—"],
    ]
    table = _table(["tool-point error (µm)", "before (offsets as they were)",
                    _e(after_head), "after: 95 % interval"], rows)
    basis = ("After: Δρ as the last verification measured it, with the tilts the run states."
             if result.get("remaining") and done else
             "After: predicted, the correction taken as written exactly.")
    method = f" Interval: {_e(acc['after_method'])}." if acc.get("after_method") else ""
    not_done = ("" if done else " <b>The offsets were not written</b>: the machine is still "
                "as in the column \"before\".")
    return f'{table}<p class="small">{_e(basis)}{method}{not_done}</p>'


def _objectives(result: Mapping[str, Any], acc: Mapping[str, Any]) -> str:
    objectives = as_dict(acc.get("objectives"))
    alt_name, alt_after = alternative(acc)
    chosen = str(acc.get("objective"))
    names = [n for n in ("joints", "tool") if n in objectives or n == alt_name]
    if not names:
        return ""
    rows = []
    for name in names:
        obj = as_dict(objectives.get(name))
        after = as_dict(obj.get("after")) or (alt_after if name == alt_name else {})
        offsets = as_dict(obj.get("offsets_mm"))
        if name == chosen:
            mark = "<b>written</b>" if written(result) else "<b>chosen</b> (not written)"
        else:
            mark = "not chosen"
        rows.append([f"{_e(name)}: {_e(OBJECTIVE_TEXT.get(name, name))}",
                     um(after.get("rms_mm")), um(after.get("max_mm")),
                     *(fmt(offsets.get(a), signed=True) for a in AXES), mark])
    table = _table(["objective", "after: RMS |E| (µm)", "after: max |E| (µm)",
                    *(f"offset o<sub>{a}</sub> (mm)" for a in AXES), "this run"], rows)
    return ("<h3>The two objectives</h3>" + table +
            '<p class="small">Each objective\'s predicted figures with its offsets written '
            "exactly, and the offset registers it writes. <code>[writeback] objective</code> "
            "chooses: <i>joints</i> writes the paper's correction o<sub>i</sub> ← "
            "o<sub>i</sub> − Δρ<sub>i</sub> (legs parallel); <i>tool</i> writes the offsets "
            "that minimise the predicted RMS tool error, cancelling part of what the tilts "
            "leave. Written registers are rounded to the controller's resolution.</p>")


def _squareness_html(acc: Mapping[str, Any]) -> str:
    rows = squareness(acc)
    advice = [str(a) for a in acc.get("squareness_advice") or []]
    out = ["<h3>Squareness of the axes</h3>"]
    if not tilts_stated(acc) or not rows:
        out.append("<p>Squareness is not stated: the tilts were not identified.</p>")
        out.extend(f"<p>{_e(a)}</p>" for a in advice if "not stated" not in a)
        return "".join(out)
    tilts, tilt_se = as_dict(acc.get("tilts")), as_dict(acc.get("tilt_std_errors"))
    table_rows = []
    for s in rows:
        t = num(tilts.get(s.tilt))
        t_se = num(tilt_se.get(s.tilt))
        verdict = {True: "beyond its uncertainty", False: "within its uncertainty",
                   None: "—"}[s.significant]
        table_rows.append([
            s.pair.upper(), fmt(s.value, signed=True),
            fmt(s.half) if s.half is not None else "—",
            fmt(s.se, 4) if s.se is not None else "—",
            param_html(s.tilt) + f" = {fmt(t, signed=True)}"
            + (f" ± {fmt(t_se, 4)}" if t_se is not None else ""), verdict])
    ks = {round(s.k, 2) for s in rows if s.k is not None}
    k_text = f"k = {ks.pop():.2f}" if len(ks) == 1 else "k from each interval"
    out.append(_table(["motions", "squareness (mm/m)", f"± 95 % ({k_text})", "σ (mm/m)",
                       "axis tilt (mrad) ± σ", "verdict"], table_rows))
    out.append('<p class="small">ISO 230-1 squareness of the tool\'s motions along commanded '
               "x, y and z; to first order it equals the tilts of the actuator axes "
               "(1 mrad = 1 mm/m). The offsets written shear the motions a little, so the two "
               "columns differ by that. Offsets cannot fix squareness.</p>")
    decision = acc.get("squareness_decision")
    if isinstance(decision, Mapping) and decision.get("rule"):
        out.append(f'<p class="small">Verdict: {_e(str(decision["rule"]))}.</p>')
    if advice:
        out.append("<p><b>What to do:</b></p><ul>"
                   + "".join(f"<li>{_e(a)}</li>" for a in advice) + "</ul>")
    return "".join(out)


def _field_caption(acc: Mapping[str, Any]) -> str:
    frame = str(acc.get("frame", "—"))
    return ("The tool-point error E over the workspace, in three horizontal slices of the "
            "grid (lowest, middle and highest z), before calibration (top row), after "
            "(second row) and, where the run states it, with the identified geometry in the "
            "controller (bottom row: the |E| expected, no arrows, since what is left there is "
            "the identification's error). Colour: |E| in µm, each row on its own scale; "
            "arrows: the x–y part "
            "of E, to the scale of the arrow in the corner (its z part shows in the colour "
            f"only); after fitting away {_e(FRAME_TEXT.get(frame, frame))}. Blank cells are "
            "grid points outside the soft limits.")


# --------------------------------------------------------------------- stands


def stands_html(result: Mapping[str, Any]) -> str:
    """The table "Where the stands were": each indicator stand, set by eye at the
    middle of its leg, as the identification placed it (or not observable)."""
    stands = result.get("stands")
    if not isinstance(stands, Mapping) or not stands:
        return ""
    rows = []
    for name, est in stands.items():
        est = as_dict(est)
        gauges = [str(g) for g in est.get("gauges") or []]
        where = ", ".join(f"leg {g[0]}, along {g[1]}" if len(g) == 2 else g for g in gauges)
        off, se = num(est.get("offset_mm")), num(est.get("std_error_mm"))
        if est.get("observable") and off is not None:
            value, sigma, note = fmt(off, 2, signed=True), fmt(se, 2), ""
        else:
            value, sigma = "—", "—"
            note = est.get("note") or "not observable"
        rows.append([_e(name), _e(where or "—"), value, sigma, _e(note)])
    sel = as_dict(as_dict(result.get("model_selection")).get("stands"))
    tol, prior = num(sel.get("tolerance_mm")), num(sel.get("prior_sd_mm"))
    if prior is None:
        priors = {num(as_dict(e).get("prior_sd_mm")) for e in stands.values()} - {None}
        prior = priors.pop() if len(priors) == 1 else None
    known = []
    if tol is not None:
        known.append(f"within ±{tol:g} mm of L/2")
    if prior is not None:
        known.append(f"prior SD {fmt(prior, 2)} mm")
    how = f" ({', '.join(known)})" if known else ""
    return ("<h3>Where the stands were</h3>"
            + _table(["stand", "indicator", "m: off the leg's middle (mm)", "σ (mm)", "note"],
                     rows, left=2)
            + '<p class="small">Each indicator stand is set by eye at the middle of its leg; '
            "its indicator reads in the plane x<sub>i</sub> = L/2 + m. The identification "
            f"estimates each m as a random effect{_e(how)}, so that a misplaced stand is not "
            "read as a tilt. Not observable: the offsets Δρ were too small for that stand to "
            "change the deviations; the data say nothing of where it stood.</p>")
