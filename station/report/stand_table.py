"""report.html's table "Where the stands were": each indicator stand, set by eye at the
middle of its leg, as the first identification placed it (a random effect of the fit,
its standard deviation the fit's own: a nuisance of the measurement, not a quantity of
the machine), or not observable."""

from __future__ import annotations

from station.record.result import RunResult
from station.report.format import esc, fmt, num, table


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
        rows.append([esc(name), esc(where or "—"), value, sigma, esc(note)])
    return ("<h3>Where the stands were</h3>"
            + table(["stand", "indicator", "m: off the leg's middle (mm)", "σ (mm)", "note"],
                     rows, left=2)
            + '<p class="small">Each indicator stand is set by eye at the middle of its leg; '
            "its indicator reads in the plane x<sub>i</sub> = L/2 + m. The identification "
            f"estimates each m as a random effect{esc(_stands_known(result))}, so that a "
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
