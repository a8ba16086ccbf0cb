"""The squareness of the tool's motions in the report (docs/design.md, "Accuracy at the
tool"; docs/model.md): report.html's table and the text summary's line. With a
statement (docs/design.md, "The statement of the machine") each squareness, and the
tilt of the axis it mirrors, is the statement's quantity, printed by
station.record.quantity_text with the decision table's word on it; nothing is computed
here. A record from before the statement keeps the legacy reading of its
``accuracy`` block (:func:`squareness`, below :func:`stated_html`), which builds each
95 % half-width from a standard error and a k."""

from __future__ import annotations

import math
from dataclasses import dataclass

from station.record.quantity_text import plus_minus
from station.record.result import RunResult
from station.record.result_accuracy import Accuracy
from station.record.result_base import Interval
from station.report.format import at, esc, fmt, num, param_html
from station.report.statement_table import decision_text, stated

#: Squareness of the tool's motions and the tilt it equals to first order (docs/model.md).
PAIRS = (("xy", "tilt_yx"), ("xz", "tilt_zx"), ("yz", "tilt_zy"))
#: Coverage factor of a 95 % interval when the result gives none (normal; legacy).
K_NORMAL = 1.96
#: Under the table: what squareness is, and why it differs from the tilt.
ISO_TEXT = ("ISO 230-1 squareness of the tool's motions along commanded x, y and z; to "
            "first order it equals the tilts of the actuator axes (1 mrad = 1 mm/m). The "
            "gaps and the offsets written shear the motions too, so the two columns differ "
            "by that. Offsets cannot fix squareness.")


def _table(head: list[str], rows: list[list[str]], stated_: bool = False,
           left: tuple[int, ...] = ()) -> str:
    """The cells of a table ``stated_`` are the statement's quantities, each printed
    with its unit (report.html's other tables say their unit in the header); columns
    ``left`` (and the first and last) are words."""
    def words(i: int, n: int) -> bool:
        return i in (0, n - 1) or i in left

    ths = "".join(f'<th class="l">{h}</th>' if words(i, len(head)) else f"<th>{h}</th>"
                  for i, h in enumerate(head))
    body = "".join("<tr>" + "".join(
        f'<td class="l">{c}</td>' if words(i, len(row)) else f'<td class="num">{c}</td>'
        for i, c in enumerate(row)) + "</tr>" for row in rows)
    cls = ' class="stated"' if stated_ else ""
    return f"<table{cls}><thead><tr>{ths}</tr></thead><tbody>{body}</tbody></table>"


def advice_list(texts: list[str]) -> str:
    """The statement's advice on the rails, each text verbatim."""
    return ("<p><b>What to do:</b></p><ul>" + "".join(f"<li>{esc(a)}</li>" for a in texts)
            + "</ul>") if texts else ""


def stated_html(result: RunResult) -> str | None:
    """report.html's squareness table from the statement: each pair's squareness and
    its axis' tilt, value ± U (95 %), the decision table's word on each, what of the
    squareness the tilt makes (the statement's basis); None without a statement."""
    q = stated(result)
    rows = []
    for pair, tilt in PAIRS:
        s = q.get(f"squareness_{pair}")
        if s is None:
            continue
        t = q.get(tilt)
        parts = s.basis[-1] if s.basis and s.basis[-1].startswith("of the value") else "—"
        rows.append([f"{pair.upper()}; {param_html(tilt)}", esc(plus_minus(s)),
                     esc(decision_text(s)), "—" if t is None else esc(plus_minus(t)),
                     "—" if t is None else esc(decision_text(t)), esc(parts)])
    if not q:
        return None
    out = ["<h3>Squareness of the axes</h3>"]
    if not rows:
        out.append("<p>Squareness is not stated: the tilts were not identified.</p>")
        return "".join(out)
    out.append(_table(["motions; the axis' tilt", "squareness (95 %)", "decision",
                       "tilt (95 %)",
                       "decision", "what makes it"], rows, stated_=True, left=(2, 4)))
    out.append(f'<p class="small">{ISO_TEXT} Each ± is the statement\'s (95 %). Decision: '
               "act only beyond k_act combined standard uncertainties (the decision "
               "table, docs/design.md).</p>")
    advice = [a.text for a in result.advice or []
              if a.id.startswith(("shim.", "undecided."))]
    return "".join(out) + advice_list(advice)


# ---------------------------------------------------------------- legacy: no statement


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


def squareness_line(acc: Accuracy) -> str:
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


def legacy_html(acc: Accuracy) -> str:
    rows = squareness(acc)
    advice = acc.squareness_advice
    out = ["<h3>Squareness of the axes</h3>"]
    if not tilts_stated(acc) or not rows:
        out.append("<p>Squareness is not stated: the tilts were not identified.</p>")
        out.extend(f"<p>{esc(a)}</p>" for a in advice if "not stated" not in a)
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
        out.append(f'<p class="small">Verdict: {esc(decision.rule)}.</p>')
    if advice:
        out.append("<p><b>What to do:</b></p><ul>"
                   + "".join(f"<li>{esc(a)}</li>" for a in advice) + "</ul>")
    return "".join(out)


