"""How a quantity of the statement is printed (station.record.result_statement), the one
way every view prints it (the first screen, --verbose, report.html, compare, the
exports' comments, the advice): its value with its 95 % uncertainty, in the unit its
size calls for.

- lengths (unit mm): in µm to 0.1 µm where the value is below 0.1 mm, else in mm to
  0.001 mm with the uncertainty in µm to 0.1 µm ("+0.697 mm ± 19.5 µm");
- angles and squareness (mrad, mm/m): to 0.001 ("+0.200 ± 0.011 mm/m");
- a lead (µm/m): to 1 µm/m;
- a bounded figure (the tool's RMS and max): its value and its interval in µm
  ("28.1 µm (95 %: 0.8–48.7 µm)").

Minus signs are ASCII here; the report's pages make them U+2212."""

from __future__ import annotations

import math

from station.record.result_statement import Quantity

#: Below this magnitude (mm) a length is printed in µm.
UM_BELOW_MM = 0.1


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _clean(text: str, digits: int) -> str:
    """"−0.0" is rounding noise: printed as 0."""
    try:
        return f"{0.0:.{digits}f}" if float(text) == 0.0 else text
    except ValueError:
        return text


def um(value_mm: float | None, digits: int = 1, signed: bool = False) -> str:
    """A length in µm ("—" where not stated)."""
    v = _num(value_mm)
    if v is None:
        return "—"
    text = _clean(f"{1000 * v:{'+' if signed else ''}.{digits}f}", digits)
    return "+" + text if signed and text[0].isdigit() else text


def plus_minus(q: Quantity) -> str:
    """"value ± expanded unit" of a linear quantity, in the unit its size calls for;
    "—" without a value."""
    v, u = _num(q.value), _num(q.expanded)
    if v is None:
        return "—"
    if q.unit == "mm":
        if abs(v) < UM_BELOW_MM:
            return f"{um(v, signed=True)}" + (f" ± {um(u)} µm" if u is not None else " µm")
        return _clean(f"{v:+.3f}", 3) + " mm" + (f" ± {um(u)} µm" if u is not None else "")
    digits = 0 if q.unit == "µm/m" else 3
    text = _clean(f"{v:+.{digits}f}", digits)
    return text + (f" ± {u:.{digits}f}" if u is not None else "") + f" {q.unit}"


def interval(q: Quantity) -> str:
    """"lo–hi µm" of a quantity's 95 % interval (a length), or "—"."""
    if q.interval_95 is None:
        return "—"
    lo, hi = q.interval_95
    if q.unit == "mm":
        return f"{um(lo)}–{um(hi)} µm"
    digits = 0 if q.unit == "µm/m" else 3
    return f"{lo:.{digits}f}–{hi:.{digits}f} {q.unit}"


def figure(q: Quantity, what: str = "") -> str:
    """A bounded figure: "28.1 µm RMS (95 %: 0.8–48.7 µm)" (``what``: "RMS", "max" or
    nothing, after the unit)."""
    if _num(q.value) is None:
        return "—"
    return f"{um(q.value)} µm{' ' + what if what else ''} (95 %: {interval(q)})"
