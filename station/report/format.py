"""The report's vocabulary: parameter and deviation names in text, HTML and TeX,
number, time and duration formatting, and the readers of the record shared by the
text summary, the plots and the page (the record's sections may be absent, None: a
run that failed halfway).
"""


from __future__ import annotations

import html
import re
from collections.abc import Iterable, Mapping, Sequence
from datetime import datetime

from orthocal import AXES, PARAM_NAMES
from orthocal.numbers import finite
from station.record.keys import dev_parts
from station.record.result import Deviation, RunResult, Simulation
from station.record.result_accuracy import Accuracy
from station.record.result_base import Interval
from station.report.boundary import ResultLike, as_result

# Grouped by leg, then posture, then direction: the order an operator measures in
# (one setup per leg), so the plot and the tables read setup by setup.
DEVIATION_KEYS = tuple(
    f"{sign}{leg}{d}" for leg in AXES for sign in "+-" for d in AXES if d != leg
)
MODEL_TEXT = {
    "rho": "joint offsets Δρ only",
    "L": "leg-length errors ΔL only",
    "full": "joint offsets Δρ and leg-length errors ΔL together",
    "rho+tilt": "joint offsets Δρ and the tilts of the actuator axes",
    "full+tilt": "joint offsets Δρ, leg-length errors ΔL and the tilts of the actuator axes",
    "rho+gap": "joint offsets Δρ and the gaps between the actuator axes",
    "rho+tilt+gap": "joint offsets Δρ, the tilts of the actuator axes and the gaps between them",
    "full+tilt+gap": ("the whole rigid geometry: joint offsets Δρ, leg-length errors ΔL, "
                      "the tilts of the actuator axes and the gaps between them"),
}
# Only Δρ reaches a controller (its zero offsets); the rest is the machine's build.
NOT_WRITTEN_TEXT = ("Axis tilts, gaps between the axes and leg-length errors cannot be written "
                    "to a controller's offsets: only the joint offsets Δρ were corrected; the "
                    "rest stays in the machine (and in the verification's deviations) until "
                    "the controller's kinematics takes it (orthocal export --kinematics; "
                    "orthocal compensate for a program) or the axes are "
                    "re-squared and re-aligned mechanically.")
STATUS_TEXT = {
    "ok": "Completed",
    "failed": "Failed",
    "refused": "Write-back refused",
    "aborted": "Aborted",
}
#: The closed loop's stop reasons (the result's ``loop.stopped``) that mean it did
#: not converge: the run completed, and its summary's first line, the report's badge
#: and the exit status (3) say so before anything else.
NOT_CONVERGED_STOPS = ("not-converged", "max_iterations")
#: What the run came to (run_state): the result's status, or "not-converged".
STATE_TEXT = {**STATUS_TEXT, "not-converged": "Not converged"}
WRITEBACK_TEXT = {
    "written": "the corrected offsets were written to the controller and read back",
    "refused": "the corrections were NOT written: the station refused them",
    "declined": "the corrections were NOT written: the operator declined",
    "skipped": "the corrections were not written (write-back skipped)",
    "failed-restored": "writing the corrections failed; the previous offsets were restored",
}
#: The same where the station holds the offsets (a drive with no OFFSET register):
#: nothing reaches the drive until the operator enters the offsets there.
HELD_WRITEBACK_TEXT = {
    **WRITEBACK_TEXT,
    "written": "the corrected offsets are held by the station, not by the drive (it takes "
               "no zero offset over Modbus): enter them in the drive as the top of this "
               "report says",
    "failed-restored": "taking the corrections failed; the station holds the previous "
                       "offsets again",
}


# ------------------------------------------------------------------- formatting


num = finite  # the report's short name for it


def esc(value: object) -> str:
    """Any value as text safe inside report.html's markup and attributes."""
    return html.escape(str(value), quote=True)


def table(head: list[str], rows: list[list[str]], left: int = 1, caption: str = "") -> str:
    """Cells are trusted HTML fragments: callers escape text with esc()."""
    ths = "".join(
        f'<th class="l">{h}</th>' if i < left else f"<th>{h}</th>" for i, h in enumerate(head)
    )
    body = "".join(
        "<tr>" + "".join(
            f'<td class="l">{c}</td>' if i < left else f'<td class="num">{c}</td>'
            for i, c in enumerate(row)
        ) + "</tr>"
        for row in rows
    )
    cap = f'<p class="small">{caption}</p>' if caption else ""
    return f"<table><thead><tr>{ths}</tr></thead><tbody>{body}</tbody></table>{cap}"


def fmt(value: object, digits: int = 3, signed: bool = False) -> str:
    v = num(value)
    if v is None:
        return "—"
    text = f"{v:+.{digits}f}" if signed else f"{v:.{digits}f}"
    # "−0.000" reads like a real negative value; it is rounding noise.
    if float(text) == 0.0:
        text = f"{0.0:.{digits}f}"
    return text.replace("-", "−")


#: An ASCII hyphen-minus that starts a number: not after a letter, digit, dot, hyphen
#: or slash, so that dates (2024-05-02), ranges of standards (ISO 230-2), file names
#: and options (--seed) keep theirs.
_HYPHEN_MINUS = re.compile(r"(?<![\w.\-/])-(?=\.?\d)")
#: What report.html does not typeset: figures, code, the stylesheet, and the tags.
_NOT_TEXT = re.compile(r"(<svg\b.*?</svg>|<code\b.*?</code>|<style\b.*?</style>"
                       r"|<script\b.*?</script>|<[^>]*>)", re.S)


def minus_signs(text: str) -> str:
    """``text`` with every number's ASCII hyphen-minus made the minus sign U+2212, as
    fmt writes it: the report has one minus sign, whichever code formatted the number."""
    return _HYPHEN_MINUS.sub("−", text)


def minus_signs_html(page: str) -> str:
    """:func:`minus_signs` on the text of an HTML page, leaving its tags, figures,
    code and stylesheet as they are."""
    return "".join(part if i % 2 else minus_signs(part)
                   for i, part in enumerate(_NOT_TEXT.split(page)))


_SYMBOL = {"drho": ("Δρ", r"\Delta\rho"), "dL": ("ΔL", r"\Delta L"), "tilt": ("tilt ", "t")}


def unit(name: str) -> str:
    """Tilts are angles in mrad (docs/model.md); everything else is a length in mm."""
    return "mrad" if name.startswith("tilt_") else "mm"


def param_plain(name: str) -> str:
    kind, axis = name.split("_", 1)
    return _SYMBOL.get(kind, (kind + " ", ""))[0] + axis


def param_html(name: str) -> str:
    kind, axis = name.split("_", 1)
    return _SYMBOL.get(kind, (kind + " ", ""))[0].strip() + f"<sub>{html.escape(axis)}</sub>"


def param_tex(name: str) -> str:
    kind, axis = name.split("_", 1)
    return "$" + _SYMBOL.get(kind, ("", kind))[1] + "_{" + axis + "}$"


def posture_html(posture: str, leg: str) -> str:
    posture, _, plane = posture.partition("@")
    at = f" at {html.escape(plane)} of the leg" if plane else ""
    if posture in ("+", "-"):
        return f"Π<sub>{leg}</sub><sup>{'+' if posture == '+' else '−'}</sup>{at}"
    return f"Π<sub>{leg}</sub>({posture.replace('-', '−')} mm){at}"


def dev_html(key: str) -> str:
    parts = dev_parts(key)
    if parts is None:
        return html.escape(key)
    sign, leg, d = parts
    return f"{posture_html(sign, leg)} along {d}"


def dev_tex(key: str) -> str:
    parts = dev_parts(key)
    if parts is None:
        return key
    sign, leg, d = parts
    sign, _, plane = sign.partition("@")
    at = f" at {plane}" if plane else ""
    if sign not in ("+", "-"):
        return rf"$\Pi_{leg}({sign})$" + f"\nalong {d}{at}"
    return rf"$\Pi_{leg}^{{{sign}}}$" + f"\nalong {d}{at}"


def hidden(result: RunResult) -> Simulation | None:
    """The simulated machine of a simulated run (None: a real machine)."""
    return result.simulation if result.simulated else None


def true_value(sim: Simulation | None, name: str) -> float | None:
    """The hidden value of parameter ``name`` in the simulated machine ``sim`` (None:
    no simulation, or a parameter it does not name)."""
    if sim is None:
        return None
    kind, axis = name.split("_", 1)
    # Tilts and gaps by full name, Δρ and ΔL by axis.
    if kind in ("tilt", "gap"):
        return at(sim.true_tilt if kind == "tilt" else sim.true_gap, name)
    return at(sim.true_drho if kind == "drho" else sim.true_dl, axis)


def at(table: Mapping[str, float | None] | None, key: str) -> float | None:
    """``table[key]`` of a map keyed by axis or name (Axis3, Params): None where the
    map or the key is absent, or the value is not a finite number."""
    return None if table is None else num(table.get(key))


def not_converged(result: ResultLike) -> bool:
    """A run that completed but whose closed loop did not converge (exit status 3)."""
    return stalled(as_result(result))


def not_accepted(result: ResultLike) -> bool:
    """A run that completed whose tool the config's [acceptance] does not accept at
    95 % (FAIL, or not decided): exit status 4 (station.analysis.acceptance)."""
    record = as_result(result)
    return (record.status == "ok" and record.acceptance is not None
            and record.acceptance.outcome != "pass")


def stalled(result: RunResult) -> bool:
    """:func:`not_converged` of the record."""
    return (result.status == "ok" and result.loop is not None
            and result.loop.stopped in NOT_CONVERGED_STOPS)


def run_state(result: RunResult) -> str:
    """What the run came to, for the first line and the badge: the result's status
    ("ok", "failed", …), or "not-converged" for a completed run whose loop did not."""
    return "not-converged" if stalled(result) else result.status


_NOT_CONVERGED_PREFIX = "closed loop did not converge: "


def not_converged_why(result: RunResult) -> str:
    """Why the loop did not converge, in words: ``loop.detail``, else the run's
    message without its "closed loop did not converge" prefix."""
    loop = result.loop
    if loop is not None and loop.detail:
        return loop.detail
    message = result.message or ""
    if message.startswith(_NOT_CONVERGED_PREFIX):
        message = message[len(_NOT_CONVERGED_PREFIX):]
    if message:
        return message
    if loop is not None and loop.stopped == "max_iterations":
        return (f"{loop.max_iterations} write-back(s) done and the "
                "last verification still finds a significant correction")
    return "the last verification could not show every joint offset within converge_mm"


def held_by_station(result: RunResult) -> bool:
    """The station holds the offsets (the drive's map has no OFFSET registers)."""
    return result.offsets_held_by == "station"


def held_offsets_text(result: RunResult) -> str | None:
    """The offsets the station holds when the run stops ("x +1.3553, y −0.7808,
    z −0.9890 mm"), or None when the result does not say."""
    final = result.offsets_final
    values = [(a, at(final, a)) for a in AXES]
    if not final or any(v is None for _, v in values):
        return None
    return ", ".join(f"{a} {fmt(v, 4, signed=True)}" for a, v in values) + " mm"


def rolled_back_text(result: RunResult) -> str | None:
    """What ``orthocal rollback`` did to this run's offsets ("on 2025-… the offsets
    were restored: x +1.8170 → +0.0000, … mm; …"), or None where it was not rolled
    back."""
    back = result.rolled_back
    if back is None:
        return None
    pairs = ", ".join(f"{a} {fmt(at(back.replaced, a), 4, signed=True)} → "
                      f"{fmt(at(back.restored, a), 4, signed=True)}" for a in AXES)
    earlier = [b.at for b in result.rollback_history()[:-1]]
    before = f" (rolled back before on {', '.join(earlier)})" if earlier else ""
    return (f"on {back.at} the offsets saved before the first write-back were restored: "
            f"{pairs} mm{before}; the controller no longer holds what this run wrote, and "
            "its verification no longer describes the machine")


def writeback_text(result: RunResult, status: str) -> str:
    """What a write-back status means for this run: written to the controller, or
    held by the station where the drive takes no offsets."""
    table = HELD_WRITEBACK_TEXT if held_by_station(result) else WRITEBACK_TEXT
    return table.get(status, f"write-back: {status}")


def machine_parameters(result: RunResult) -> dict[str, float | None]:
    """The identified parameters as the machine has them. ``identified`` holds the
    total correction written; with objective "tool" that aims the joint errors at
    a target instead of 0, so the machine's Δρ at the start is the run's statement
    ``remaining.total`` (the correction written plus what is left from the aim)."""
    ident = dict(result.identified)
    total = result.remaining.total if result.remaining is not None else {}
    if isinstance(result.accuracy, Accuracy) and result.accuracy.objective == "tool" and total:
        ident.update({n: v for n, v in total.items() if n in ident})
    return ident


def params_of(result: RunResult) -> list[str]:
    ident = result.identified
    names = [n for n in PARAM_NAMES if n in ident]
    return names + sorted(n for n in ident if n not in PARAM_NAMES)


def format_when(iso: str | None) -> str:
    if iso is None:
        return "—"
    try:
        dt = datetime.fromisoformat(iso)
    except ValueError:
        return iso
    text = dt.strftime("%Y-%m-%d %H:%M:%S")
    if dt.utcoffset() is not None:
        text += " " + (dt.strftime("%z") or "")
    return text


def format_duration(seconds: float | None) -> str:
    s = num(seconds)
    if s is None:
        return "—"
    if s < 60:
        return f"{s:.1f} s"
    minutes, sec = divmod(round(s), 60)
    if minutes < 60:
        return f"{minutes} min {sec:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"


def mountings_text(result: RunResult) -> str | None:
    """The mountings the run took and the operator's time at them, or None (an older
    result without them). Mountings nobody waited at are said so, not "0 s at the
    machine": a simulated run's virtual operator mounts at once, and on real devices
    prompts answered within half a second in all were answered by --yes (a person
    takes a minute or two per mounting)."""
    t = result.timing
    if t.mountings is None:
        return None
    operator = num(t.operator_s)
    if result.simulation is not None:
        return f"{t.mountings} (mounted by the simulator: nobody waited)"
    if operator is None:
        return str(t.mountings)
    if operator < 0.5:
        return f"{t.mountings} (answered by --yes: nobody waited at the machine)"
    return f"{t.mountings}, {format_duration(operator)} at the machine"


def max_abs(devs: Mapping[str, Deviation]) -> float | None:
    values = [num(d.mean) for d in devs.values()]
    finite = [abs(v) for v in values if v is not None]
    return max(finite) if finite else None


# -------------------------------------------------------------------- summary


def param_line(result: RunResult, names: Iterable[str]) -> str:
    """The parameters, each ± its 95 % half-width (k from Student's t on the
    identification's dof), labelled: one value and one uncertainty per quantity."""
    from orthocal import coverage_factor

    ident = machine_parameters(result)
    k = coverage_factor(num(result.std_errors_dof))
    parts = []
    for n in names:
        se = at(result.std_errors, n)
        pm = "" if se is None else f" ± {fmt(k * se)}"
        parts.append(f"{param_plain(n)} = {fmt(at(ident, n), signed=True)}{pm} {unit(n)}")
    return "   ".join(parts) + (f" (95 %, k = {k:.2f})" if parts else "")


# ------------------------------------------------------------ accuracy at the tool


def um(value_mm: float | None, digits: int = 1) -> str:
    """A length given in mm, written in µm: the tool's error is tens of µm, and
    "0.014 mm" hides the one digit the reader compares before and after."""
    v = num(value_mm)
    return "—" if v is None else fmt(1000.0 * v, digits)


def um_signed(value_mm: float | None, digits: int = 1) -> str:
    """:func:`um` with its sign: a deviation or an error that may be either."""
    v = num(value_mm)
    return "—" if v is None else fmt(1000.0 * v, digits, signed=True)


#: Degrees of freedom above which Student's k is the normal's to the digits stated
#: (t at 1000 dof is 1.962 for 95 %, the normal's 1.960): said "∞", not "321746.7".
MANY_DOF = 1000.0


def dof_text(dof: float | None) -> str:
    """Degrees of freedom as the report says them: "∞" for none stated (infinite) or
    above :data:`MANY_DOF`, else to one decimal ("14.0")."""
    v = num(dof)
    return "∞" if v is None or v > MANY_DOF else f"{v:.1f}"


def k_text(factors: Iterable[float | None]) -> str:
    """Coverage factors said once: "1.96" when all equal to the digits shown, else
    "2.03–2.14"; "—" for none."""
    shown = sorted({round(v, 2) for v in map(num, factors) if v is not None})
    if not shown:
        return "—"
    return fmt(shown[0], 2) if len(shown) == 1 else f"{fmt(shown[0], 2)}–{fmt(shown[-1], 2)}"


def um_interval(pair: Interval | None, digits: int = 1) -> str | None:
    """A 95 % interval [lo, hi] given in mm as "lo–hi" in µm (None: none given)."""
    lo, hi = (None, None) if pair is None else (num(pair[0]), num(pair[1]))
    if lo is None or hi is None:
        return None
    return f"{um(lo, digits)}–{um(hi, digits)}"


def box_text(box: Sequence[Interval]) -> str:
    """The workspace box [[xmin, xmax], ...] as "[−100, 60]³ mm" when it is a
    cube, else axis by axis; "—" when it is not a box of three spans."""
    if len(box) != 3:
        return "—"
    spans = []
    for span in box:
        lo, hi = num(span[0]), num(span[1])
        if lo is None or hi is None:
            return "—"
        spans.append(f"[{lo:g}, {hi:g}]".replace("-", "−"))
    if len(set(spans)) == 1:
        return f"{spans[0]}³ mm"
    return ", ".join(f"{a} {s}" for a, s in zip(AXES, spans, strict=True)) + " mm"
