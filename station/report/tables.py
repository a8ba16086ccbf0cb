"""report.html's tables of the measurement: the identified parameters (with the
hidden truth of a simulated run and the values after calibration), the model's
candidates, the correlation of the estimates, the deviations and the setups."""

from __future__ import annotations

from orthocal import coverage_factor
from station.record.keys import dev_keys
from station.record.result import Deviation, RunResult
from station.report.format import (
    PARAM_NAMES,
    at,
    dev_html,
    dof_text,
    esc,
    fmt,
    hidden,
    machine_parameters,
    num,
    param_html,
    params_of,
    table,
    true_value,
    um,
    um_signed,
    unit,
)
from station.report.text import model_notes


def params_table(result: RunResult) -> str:
    """The identified parameters, one table per unit: the lengths (Δρ, ΔL, the gaps)
    in µm, the tilts in mm/m (= mrad)."""
    names = params_of(result)
    if not names:
        return "<p>No parameters were identified.</p>"
    tilts = [n for n in names if unit(n) == "mrad"]
    lengths = [n for n in names if n not in tilts]
    return "".join(_params_table(result, group, scale, label) for group, scale, label in (
        (lengths, 1000.0, "µm"), (tilts, 1.0, "mm/m")) if group)


def _params_table(result: RunResult, names: list[str], scale: float, label: str) -> str:
    """``names``' rows, each value times ``scale`` (mm → µm; mrad as mm/m), in
    ``label`` said once in the first header cell."""
    ident, errs = machine_parameters(result), result.std_errors
    ver = result.verification
    v_ident = ver.identified if ver is not None else {}
    v_errs = ver.std_errors if ver is not None else {}
    sim = hidden(result)
    has_truth = any(true_value(sim, n) is not None for n in names)
    dof = num(result.std_errors_dof)
    k = coverage_factor(dof) if dof is not None and dof > 0 else coverage_factor(None)
    head = [f"parameter ({label})", "identified", "σ",
            f"95 % interval (k = {fmt(k, 2)}, {dof_text(dof)} dof)"]
    if has_truth:
        head.append("hidden truth")
    if v_ident:
        head += ["after calibration", "σ after"]

    def show(value: float | None, signed: bool = True) -> str:
        return fmt(None if value is None else value * scale, 1, signed=signed)

    rows = []
    for n in names:
        v, s = at(ident, n), at(errs, n)
        interval = (f"{show(v - k * s)} … {show(v + k * s)}"
                    if v is not None and s is not None else "—")
        row = [param_html(n), show(v), show(s, False), interval]
        if has_truth:
            row.append(show(true_value(sim, n)))
        if v_ident:
            row += [show(at(v_ident, n)), show(at(v_errs, n), False)]
        rows.append(row)
    return table(head, rows)


def model_section(result: RunResult) -> str:
    """Why this model (auto's test), what these measurements can never identify,
    what cannot be written: said, not silently fixed."""
    notes = model_notes(result)
    if not notes:
        return ""
    out = "".join(f"<p>{esc(n)}</p>" for n in notes)
    sel = result.model_selection
    if sel is None or not sel.candidates:
        return out
    rows = [[esc(c.model), "yes" if c.identifiable else "no",
             fmt(c.F, 2), esc(", ".join(f"{d:g}" for d in c.dof)
                              if c.dof is not None else "—"),
             (f"{c.p_value:.2g}" if num(c.p_value) is not None else "—"),
             um(c.residual_rms_mm, 2),
             "chosen" if c.model == result.model else
             ("rejected" if c.F is not None else esc(c.note or ""))]
            for c in sel.candidates]
    return out + table(["candidate", "identifiable", "F", "dof", "p", "residual RMS (µm)",
                        "verdict"], rows, caption=(
        f"Lack-of-fit F test of each candidate against the noise measured in this run "
        f"(σ = {um(sel.noise_sigma_mm, 2)} µm per deviation, "
        f"{esc(sel.noise_source)}); the first with p ≥ {esc(sel.level)} "
        "is used."))


def correlation_table(result: RunResult) -> str:
    corr = result.correlation
    if corr is None or not corr.names:
        return ""
    names, matrix = corr.names, corr.matrix
    head = "".join(f"<th>{param_html(n) if n in PARAM_NAMES else esc(n)}</th>"
                   for n in names)
    rows = []
    for i, n in enumerate(names):
        row = matrix[i] if i < len(matrix) else []
        cells = []
        for j in range(len(names)):
            r = num(row[j]) if j < len(row) else None
            # Shade by |r|: strongly correlated pairs (|r| near 1) are the ones the
            # measurement cannot tell apart, and should jump out at the reader.
            shade = "" if r is None or i == j else (
                f' style="background:rgba(192,57,43,{min(abs(r), 1.0) * 0.55:.2f})"')
            # 0.9997 would print as "1.00", which reads as "identical" rather than
            # "almost inseparable"; give such values their digits.
            digits = 4 if r is not None and i != j and abs(r) >= 0.995 else 2
            cells.append(f'<td class="num"{shade}>{fmt(r, digits)}</td>')
        label = param_html(n) if n in PARAM_NAMES else esc(n)
        rows.append(f'<tr><th class="l">{label}</th>{"".join(cells)}</tr>')
    return (f'<h3>Correlation of the estimates</h3><table><thead><tr><th></th>{head}</tr>'
            f'</thead><tbody>{"".join(rows)}</tbody></table>'
            '<p class="small">Values near ±1 mean the measurement cannot separate the two '
            "parameters: an error in one is absorbed by the other.</p>")


def deviations_table(result: RunResult) -> str:
    before: dict[str, Deviation] = dict(result.deviations or {})
    after: dict[str, Deviation] = dict(result.verification.deviations
                                       if result.verification is not None else {})
    keys = dev_keys(before, after)
    if not keys:
        return "<p>No deviations were measured.</p>"
    head = ["deviation (µm)", "measured", "std", "n", "model", "residual"]
    if after:
        head += ["after: measured", "after: std"]
    rows = []
    for k in keys:
        b, a = before.get(k), after.get(k)
        m, f = (num(b.mean), num(b.model)) if b is not None else (None, None)
        resid = m - f if m is not None and f is not None else None
        row = [dev_html(k), um_signed(m), um(b.std if b is not None else None),
               esc(b.n) if b is not None else "—", um_signed(f), um_signed(resid)]
        if after:
            row += [um_signed(a.mean if a is not None else None),
                    um(a.std if a is not None else None)]
        rows.append(row)
    return table(head, rows, caption=(
        "Π<sub>i</sub><sup>±</sup> along j: reading of the indicator touching leg i in "
        "direction j, in test posture Π<sub>i</sub><sup>±</sup>, minus its reading in "
        "Π<sub>0</sub>. std: spread over the measurement cycles; n: number of cycles."))


def setups_table(result: RunResult) -> str:
    if not result.setups:
        return "<p>No setup was measured.</p>"
    rows = []
    for s in result.setups:
        inds = ", ".join(f"{esc(k)} → {esc(v)}" for k, v in s.indicators.items())
        rows.append([
            f"leg {esc(s.leg)}", inds or "—", f"{esc(s.cycles_used)} of {esc(s.cycles_max)}",
            esc(s.repeats), um(s.spread_mm),
            "<b>yes</b> — spread above the repeatability limit" if s.flagged else "no",
        ])
    return table(["setup", "indicators (name → direction)", "cycles used", "repeats",
                  "spread (µm)", "flagged"], rows, left=2)
