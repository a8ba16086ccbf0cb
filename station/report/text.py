"""The run report's words: names, number formatting and the short text summary
(``summary_text``), shared by the HTML report (station/report_html.py).

Every section of the result may be missing (a run that failed halfway), so
everything here reads with ``.get`` and shows "—" rather than raising.
"""

from __future__ import annotations

import html
import math
import re
from collections.abc import Iterable, Mapping
from datetime import datetime
from pathlib import Path
from typing import Any

AXES = ("x", "y", "z")
PARAM_NAMES = ("drho_x", "drho_y", "drho_z", "dL_x", "dL_y", "dL_z",
               "tilt_yx", "tilt_zx", "tilt_zy")
# Grouped by leg, then posture, then direction: the order an operator measures in
# (one setup per leg), so the plot and the tables read setup by setup.
DEVIATION_KEYS = tuple(
    f"{sign}{leg}{d}" for leg in AXES for sign in "+-" for d in AXES if d != leg
)
_MODEL_TEXT = {
    "rho": "joint offsets Δρ only",
    "L": "leg-length errors ΔL only",
    "full": "joint offsets Δρ and leg-length errors ΔL together",
    "rho+tilt": "joint offsets Δρ and the tilts of the actuator axes",
    "full+tilt": "joint offsets Δρ, leg-length errors ΔL and the tilts of the actuator axes",
}
# Only Δρ reaches a controller (its zero offsets); the rest is the machine's build.
NOT_WRITTEN_TEXT = ("Axis tilts and leg-length errors cannot be written to a controller: "
                    "only the joint offsets Δρ were corrected; the tilts stay in the machine "
                    "(and in the verification's deviations) until it is re-squared mechanically.")
_STATUS_TEXT = {
    "ok": "Completed",
    "failed": "Failed",
    "refused": "Write-back refused",
    "aborted": "Aborted",
}
_WRITEBACK_TEXT = {
    "written": "the corrected offsets were written to the controller and read back",
    "refused": "the corrections were NOT written: the station refused them",
    "declined": "the corrections were NOT written: the operator declined",
    "skipped": "the corrections were not written (write-back skipped)",
    "failed-restored": "writing the corrections failed; the previous offsets were restored",
}


# ------------------------------------------------------------------- formatting


def _num(value: Any) -> float | None:
    if isinstance(value, bool) or value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _fmt(value: Any, digits: int = 3, signed: bool = False) -> str:
    v = _num(value)
    if v is None:
        return "—"
    text = f"{v:+.{digits}f}" if signed else f"{v:.{digits}f}"
    # "−0.000" reads like a real negative value; it is rounding noise.
    if float(text) == 0.0:
        text = f"{0.0:.{digits}f}"
    return text.replace("-", "−")


_SYMBOL = {"drho": ("Δρ", r"\Delta\rho"), "dL": ("ΔL", r"\Delta L"), "tilt": ("tilt ", "t")}


def _unit(name: str) -> str:
    """Tilts are angles in mrad (model.md); everything else is a length in mm."""
    return "mrad" if name.startswith("tilt_") else "mm"


def _param_plain(name: str) -> str:
    kind, axis = name.split("_", 1)
    return _SYMBOL.get(kind, (kind + " ", ""))[0] + axis


def _param_html(name: str) -> str:
    kind, axis = name.split("_", 1)
    return _SYMBOL.get(kind, (kind + " ", ""))[0].strip() + f"<sub>{html.escape(axis)}</sub>"


def _param_tex(name: str) -> str:
    kind, axis = name.split("_", 1)
    return "$" + _SYMBOL.get(kind, ("", kind))[1] + "_{" + axis + "}$"


def _dev_parts(key: str) -> tuple[str, str, str] | None:
    """(posture, leg, direction) of "+xy" or of a stroke key such as "+30xy"."""
    if re.fullmatch(r"[+-](\d+(\.\d*)?|\.\d+)?[xyz][xyz]", key):
        return key[:-2], key[-2], key[-1]
    return None


def _posture_html(posture: str, leg: str) -> str:
    if posture in ("+", "-"):
        return f"Π<sub>{leg}</sub><sup>{'+' if posture == '+' else '−'}</sup>"
    return f"Π<sub>{leg}</sub>({posture.replace('-', '−')} mm)"


def _dev_html(key: str) -> str:
    parts = _dev_parts(key)
    if parts is None:
        return html.escape(key)
    sign, leg, d = parts
    return f"{_posture_html(sign, leg)} along {d}"


def _dev_tex(key: str) -> str:
    parts = _dev_parts(key)
    if parts is None:
        return key
    sign, leg, d = parts
    if sign not in ("+", "-"):
        return rf"$\Pi_{leg}({sign})$" + f"\nalong {d}"
    return rf"$\Pi_{leg}^{{{sign}}}$" + f"\nalong {d}"


def _truth(result: Mapping[str, Any], name: str) -> float | None:
    sim = result.get("simulation")
    if not result.get("simulated") or not isinstance(sim, Mapping):
        return None
    kind, axis = name.split("_", 1)
    if kind == "tilt":
        table = sim.get("true_tilt")
        return _num(table.get(name)) if isinstance(table, Mapping) else None
    table = sim.get("true_drho" if kind == "drho" else "true_dl")
    if not isinstance(table, Mapping):
        return None
    return _num(table.get(axis))


def _dict(value: Any) -> dict:
    return value if isinstance(value, dict) else {}


def _params_of(result: Mapping[str, Any]) -> list[str]:
    ident = _dict(result.get("identified"))
    names = [n for n in PARAM_NAMES if n in ident]
    return names + sorted(n for n in ident if n not in PARAM_NAMES)


def _dev_keys(*tables: Mapping[str, Any]) -> list[str]:
    present: set[str] = set()
    for t in tables:
        present.update(t)
    return sorted(present, key=_dev_order)


def _dev_order(key: str) -> tuple:
    """Leg, then posture from ρmax down to ρmin ('+', '+30', '-50', '-'), then
    direction: DEVIATION_KEYS' order, with intermediate strokes in their place."""
    parts = _dev_parts(key)
    if parts is None:
        return (1, key)
    posture, leg, d = parts
    s = {"+": math.inf, "-": -math.inf}.get(posture)
    return (0, leg, -(float(posture) if s is None else s), d)


def _when(iso: Any) -> str:
    if not isinstance(iso, str):
        return "—"
    try:
        dt = datetime.fromisoformat(iso)
    except ValueError:
        return iso
    text = dt.strftime("%Y-%m-%d %H:%M:%S")
    if dt.utcoffset() is not None:
        text += " " + (dt.strftime("%z") or "")
    return text


def _duration(seconds: Any) -> str:
    s = _num(seconds)
    if s is None:
        return "—"
    if s < 60:
        return f"{s:.1f} s"
    minutes, sec = divmod(round(s), 60)
    if minutes < 60:
        return f"{minutes} min {sec:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"


def _max_abs(devs: Mapping[str, Any]) -> float | None:
    values = [_num(_dict(v).get("mean")) for v in devs.values()]
    finite = [abs(v) for v in values if v is not None]
    return max(finite) if finite else None


# -------------------------------------------------------------------- summary


def _param_line(result: Mapping[str, Any], names: Iterable[str]) -> str:
    ident = _dict(result.get("identified"))
    errs = _dict(result.get("std_errors"))
    return "   ".join(
        f"{_param_plain(n)} = {_fmt(ident.get(n), signed=True)} ± {_fmt(errs.get(n))} {_unit(n)}"
        for n in names
    )


def model_notes(result: Mapping[str, Any]) -> list[str]:
    """What the report must say about the model: why auto chose it, what cannot
    be identified from these measurements, what cannot be written."""
    notes = []
    sel = _dict(result.get("model_selection"))
    if sel.get("reason"):
        notes.append(f"Model chosen by auto ({sel.get('test', 'F test')}, level "
                     f"{sel.get('level')}): {sel['reason']}.")
    for line in result.get("not_identifiable") or []:
        notes.append(str(line))
    names = _params_of(result)
    if any(not n.startswith("drho_") for n in names):
        notes.append(NOT_WRITTEN_TEXT)
    return notes


def guard_lines(result: dict) -> list[str]:
    """The plunger guard's stops that the run recovered from (or none)."""
    guard = _dict(result.get("plunger_guard"))
    recovered = [r for r in guard.get("recovered") or [] if isinstance(r, dict)]
    if not recovered:
        return []
    lines = [f"  plunger guard stopped the axes {guard.get('stops')} time(s) and the run "
             f"recovered ({guard.get('retakes', 0)} cycle(s) taken again):"]
    for r in recovered:
        lines.append(f"    indicator {r.get('indicator')} on {r.get('where')}, move to "
                     f"{r.get('move')}: re-planned from where the axes stopped via "
                     f"{r.get('waypoints')} waypoint(s) at {_fmt(r.get('speed_mm_s'), 1)} mm/s")
    return lines


def summary_text(result: dict) -> str:
    """A few lines for the end of a run: status, identified values, residual,
    offsets written, verification before → after, where the report is."""
    status = str(result.get("status", "unknown"))
    head = f"orthocal run: {_STATUS_TEXT.get(status, status).upper()}"
    if result.get("message"):
        head += f" — {result['message']}"
    lines = [head]
    names = _params_of(result)
    if names:
        model = str(result.get("model", ""))
        sel = _dict(result.get("model_selection"))
        chosen = [c for c in sel.get("candidates") or [] if isinstance(c, dict)
                  and c.get("model") == model and c.get("F") is not None]
        why = (f" (auto: F = {_fmt(chosen[0]['F'], 2)}, p = {_fmt(chosen[0].get('p_value'))}"
               f" against the measured noise, level {sel.get('level')})" if chosen else
               " (auto: no candidate explains the data)" if sel else "")
        lines.append(f"  model         {model}{why}")
        lines.append(f"  identified    {_param_line(result, names)}")
        noise = _num(result.get("noise_mm"))
        resid = f"  residual      {_fmt(result.get('residual_rms_mm'))} mm RMS"
        if noise is not None:
            resid += f" (indicator noise {_fmt(noise)} mm)"
        if result.get("fit_note"):
            resid += f": {result['fit_note']}"
        lines.append(resid)
    before = _dict(result.get("offsets_before"))
    written = result.get("offsets_written")
    wb = _dict(result.get("writeback"))
    if isinstance(written, dict) and written:
        pairs = ", ".join(
            f"{a} {_fmt(before.get(a))} → {_fmt(written.get(a))}" for a in AXES if a in written
        )
        lines.append(f"  offsets       {pairs} mm ({wb.get('status', 'written')})")
    elif wb:
        reason = f": {wb['reason']}" if wb.get("reason") else ""
        lines.append(f"  offsets       not written ({wb.get('status')}{reason})")
    ver = result.get("verification")
    if isinstance(ver, dict) and ver:
        lines.append(
            f"  verification  deviations RMS {_fmt(result.get('deviations_rms_mm'))} → "
            f"{_fmt(ver.get('deviations_rms_mm'))} mm; re-identified "
            + "  ".join(
                f"{_param_plain(n)} = {_fmt(v, signed=True)} {_unit(n)}"
                for n, v in _dict(ver.get("identified")).items()
            )
        )
    if names and result.get("not_identifiable"):
        two = any("ΔL cannot be separated" in str(n) for n in result["not_identifiable"])
        lines.append("  not identifiable  a rotation of the whole machine"
                     + ("; ΔL beside the tilts (two postures per leg)" if two else ""))
    if any(not n.startswith("drho_") for n in names):
        lines.append("  not written   tilts and ΔL (a controller takes only Δρ)")
    lines += guard_lines(result)
    from station import report_loop

    lines += report_loop.summary_lines(result)
    if result.get("run_dir"):
        lines.append(f"  report        {Path(str(result['run_dir'])) / 'report.html'}")
    return "\n".join(lines)
