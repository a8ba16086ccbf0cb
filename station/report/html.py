"""report.html: one self-contained page (plots inline as SVG) from the result."""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from drivers.files import write_atomic
from orthocal import coverage_factor
from station.report import budget, reversal, since
from station.report.format import (
    AXES,
    MODEL_TEXT,
    PARAM_NAMES,
    STATE_TEXT,
    as_dict,
    dev_html,
    dev_keys,
    esc,
    fmt,
    format_duration,
    format_when,
    held_by_station,
    machine_parameters,
    num,
    param_html,
    params_of,
    run_state,
    true_value,
    unit,
    writeback_text,
)
from station.report.header import header_boxes, held_box
from station.report.plots import plot_deviations, plot_field, plot_parameters, release_fonts
from station.report.story import result_paragraph, what_was_done
from station.report.text import model_notes
from station.report.tool import html_section as tool_section
from station.report.tool import stands_html, statement

_CSS = """
body{font-family:-apple-system,"Segoe UI",Roboto,"Helvetica Neue",Arial,sans-serif;
 color:#1d2330;max-width:60rem;margin:2rem auto;padding:0 1.2rem;line-height:1.5;font-size:15px}
h1{font-size:1.6rem;margin:0 0 .3rem}
h2{font-size:1.2rem;margin:2rem 0 .6rem;border-bottom:1px solid #d0d5dd;padding-bottom:.2rem}
h3{font-size:1rem;margin:1.2rem 0 .4rem}
.meta{color:#555;margin:0 0 1rem}
.status{display:inline-block;padding:.15rem .7rem;border-radius:1rem;font-weight:600;
 font-size:.95rem;vertical-align:middle;margin-left:.6rem;border:1px solid}
.st-ok{background:#e6f4ea;color:#1e6b30;border-color:#9fd3ab}
.st-failed,.st-aborted{background:#fdecea;color:#a52a1a;border-color:#f0a99f}
.st-refused{background:#fff4e0;color:#8a5300;border-color:#f0c97a}
.box{background:#f6f8fa;border:1px solid #d0d5dd;border-radius:6px;padding:.7rem 1rem;
 margin:.8rem 0}
.warn{background:#fff8e6;border-color:#f0c97a}
.bad{background:#fdecea;border-color:#f0a99f}
table{border-collapse:collapse;margin:.4rem 0 1rem;font-size:.9rem}
th,td{border:1px solid #d0d5dd;padding:.25rem .6rem;text-align:right;vertical-align:top}
th{background:#f0f2f5;font-weight:600}
td.l,th.l{text-align:left}
td.num{font-variant-numeric:tabular-nums;white-space:nowrap}
figure{margin:1rem 0;page-break-inside:avoid;break-inside:avoid}
figure svg{width:100%;height:auto;display:block}
figcaption{font-size:.88rem;color:#444;margin-top:.3rem}
dl.kv{display:grid;grid-template-columns:max-content auto;gap:.15rem 1rem;margin:.4rem 0}
dl.kv dt{color:#555}dl.kv dd{margin:0}
.small{font-size:.85rem;color:#555}
code{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:.88em;word-break:break-all}
@media print{body{margin:0;max-width:none;font-size:11pt}h2{page-break-after:avoid}
 table,.box{page-break-inside:avoid}}
"""



def _table(head: list[str], rows: list[list[str]], left: int = 1, caption: str = "") -> str:
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


def _fit_box(result: Mapping[str, Any]) -> str:
    if result.get("residual_rms_mm") is None and not result.get("fit_note"):
        return ""
    rows = [
        ("residual RMS (measured − model)", f"{fmt(result.get('residual_rms_mm'))} mm"),
        ("σ = √(RSS / (n − p))", f"{fmt(result.get('sigma_mm'))} mm"),
        ("indicator noise (spread of readings at a stop)", f"{fmt(result.get('noise_mm'))} mm"),
        ("condition number (sensitivity of the fit to noise)",
         fmt(result.get("condition_number"), 2)),
        ("deviations RMS before calibration", f"{fmt(result.get('deviations_rms_mm'))} mm"),
    ]
    dl = "".join(f"<dt>{esc(k)}</dt><dd>{esc(v)}</dd>" for k, v in rows)
    ok = result.get("fit_ok")
    cls = "box" if ok is not False else "box warn"
    verdict = ("The model explains the data: the residual is at the level of the indicator "
               "noise." if ok else "Warning: the residual is larger than the indicator noise "
               "explains; the machine may have errors this model does not include."
               if ok is False else "")
    note = (f"<p><b>Fit quality:</b> {esc(result['fit_note'])}</p>"
            if result.get("fit_note") else "")
    return f'<div class="{cls}">{note}<p>{esc(verdict)}</p><dl class="kv">{dl}</dl></div>'


def _params_table(result: Mapping[str, Any]) -> str:
    names = params_of(result)
    if not names:
        return "<p>No parameters were identified.</p>"
    ident, errs = machine_parameters(result), as_dict(result.get("std_errors"))
    ver = as_dict(result.get("verification"))
    v_ident, v_errs = as_dict(ver.get("identified")), as_dict(ver.get("std_errors"))
    has_truth = any(true_value(result, n) is not None for n in names)
    dof = num(result.get("std_errors_dof"))
    k = coverage_factor(dof) if dof is not None and dof > 0 else coverage_factor(None)
    head = ["parameter", "unit", "identified", "σ",
            f"95 % interval (k = {k:.2f}" + (f", {dof:g} dof)" if dof is not None else ")")]
    if has_truth:
        head.append("hidden truth")
    if v_ident:
        head += ["after calibration", "σ after"]
    rows = []
    for n in names:
        v, s = num(ident.get(n)), num(errs.get(n))
        interval = (f"{fmt(v - k * s, signed=True)} … {fmt(v + k * s, signed=True)}"
                    if v is not None and s is not None else "—")
        row = [param_html(n), unit(n), fmt(v, signed=True), fmt(s), interval]
        if has_truth:
            row.append(fmt(true_value(result, n), signed=True))
        if v_ident:
            row += [fmt(v_ident.get(n), signed=True), fmt(v_errs.get(n))]
        rows.append(row)
    return _table(head, rows)


def _model_section(result: Mapping[str, Any]) -> str:
    """Why this model (auto's test), what these measurements can never identify,
    what cannot be written: said, not silently fixed."""
    notes = model_notes(result)
    if not notes:
        return ""
    out = "".join(f"<p>{esc(n)}</p>" for n in notes)
    sel = as_dict(result.get("model_selection"))
    cands = [c for c in sel.get("candidates") or [] if isinstance(c, dict)]
    if cands:
        rows = [[esc(c.get("model")), "yes" if c.get("identifiable") else "no",
                 fmt(c.get("F"), 2), esc(", ".join(f"{d:g}" for d in c["dof"])
                                         if isinstance(c.get("dof"), list) else "—"),
                 (f"{c['p_value']:.2g}" if num(c.get("p_value")) is not None else "—"),
                 fmt(c.get("residual_rms_mm"), 4),
                 "chosen" if c.get("model") == result.get("model") else
                 ("rejected" if c.get("F") is not None else esc(c.get("note") or ""))]
                for c in cands]
        out += _table(["candidate", "identifiable", "F", "dof", "p", "residual RMS (mm)",
                       "verdict"], rows, caption=(
            f"Lack-of-fit F test of each candidate against the noise measured in this run "
            f"(σ = {fmt(sel.get('noise_sigma_mm'), 5)} mm per deviation, "
            f"{esc(sel.get('noise_source'))}); the first with p ≥ {esc(sel.get('level'))} "
            "is used."))
    return out


def _correlation_table(result: Mapping[str, Any]) -> str:
    corr = as_dict(result.get("correlation"))
    names, matrix = corr.get("names"), corr.get("matrix")
    if not isinstance(names, list) or not isinstance(matrix, list) or not names:
        return ""
    head = "".join(f"<th>{param_html(str(n)) if str(n) in PARAM_NAMES else esc(n)}</th>"
                   for n in names)
    rows = []
    for i, n in enumerate(names):
        row = matrix[i] if i < len(matrix) and isinstance(matrix[i], list) else []
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
        label = param_html(str(n)) if str(n) in PARAM_NAMES else esc(n)
        rows.append(f'<tr><th class="l">{label}</th>{"".join(cells)}</tr>')
    return (f'<h3>Correlation of the estimates</h3><table><thead><tr><th></th>{head}</tr>'
            f'</thead><tbody>{"".join(rows)}</tbody></table>'
            '<p class="small">Values near ±1 mean the measurement cannot separate the two '
            "parameters: an error in one is absorbed by the other.</p>")


def _deviations_table(result: Mapping[str, Any]) -> str:
    before = as_dict(result.get("deviations"))
    after = as_dict(as_dict(result.get("verification")).get("deviations"))
    keys = dev_keys(before, after)
    if not keys:
        return "<p>No deviations were measured.</p>"
    head = ["deviation", "measured (mm)", "std (mm)", "n", "model (mm)", "residual (mm)"]
    if after:
        head += ["after: measured (mm)", "after: std (mm)"]
    rows = []
    for k in keys:
        b, a = as_dict(before.get(k)), as_dict(after.get(k))
        m, f = num(b.get("mean")), num(b.get("model"))
        resid = m - f if m is not None and f is not None else None
        n = b.get("n")
        row = [dev_html(k), fmt(m, signed=True), fmt(b.get("std")),
               esc(n) if isinstance(n, int) else "—", fmt(f, signed=True),
               fmt(resid, signed=True)]
        if after:
            row += [fmt(a.get("mean"), signed=True), fmt(a.get("std"))]
        rows.append(row)
    return _table(head, rows, caption=(
        "Π<sub>i</sub><sup>±</sup> along j: reading of the indicator touching leg i in "
        "direction j, in test posture Π<sub>i</sub><sup>±</sup>, minus its reading in "
        "Π<sub>0</sub>. std: spread over the measurement cycles; n: number of cycles."))


def _setups_table(result: Mapping[str, Any]) -> str:
    setups = result.get("setups")
    if not isinstance(setups, list) or not setups:
        return "<p>No setup was measured.</p>"
    rows = []
    for s in setups:
        s = as_dict(s)
        inds = ", ".join(f"{esc(k)} → {esc(v)}" for k, v in as_dict(s.get("indicators")).items())
        cu, cm = s.get("cycles_used"), s.get("cycles_max")
        cycles = f"{esc(cu)} of {esc(cm)}" if cm is not None else esc(cu if cu is not None else "—")
        flagged = s.get("flagged")
        rows.append([
            f"leg {esc(s.get('leg', '—'))}", inds or "—", cycles, esc(s.get("repeats", "—")),
            fmt(s.get("spread_mm")),
            "<b>yes</b> — spread above the repeatability limit" if flagged else "no",
        ])
    return _table(["setup", "indicators (name → direction)", "cycles used", "repeats",
                   "spread (mm)", "flagged"], rows, left=2)


def _offsets_section(result: Mapping[str, Any]) -> str:
    before = as_dict(result.get("offsets_before"))
    written = result.get("offsets_written")
    written = written if isinstance(written, dict) else {}
    wb = as_dict(result.get("writeback"))
    held = held_by_station(result)
    out = []
    if wb:
        status = str(wb.get("status", "—"))
        cls = "box" if status == "written" and not held else "box warn"
        text = writeback_text(result, status) if status in (
            "written", "refused", "declined", "skipped", "failed-restored") else status
        label = "held by the station" if held and status == "written" else status
        reason = f"<br>Reason: {esc(wb['reason'])}" if wb.get("reason") else ""
        out.append(f'<div class="{cls}"><b>Write-back: {esc(label)}</b> — {esc(text)}.'
                   f"{reason}</div>")
    if before or written:
        rows = []
        for a in AXES:
            if a not in before and a not in written:
                continue
            b, w = num(before.get(a)), num(written.get(a))
            change = fmt(w - b, signed=True) if b is not None and w is not None else "—"
            rows.append([f"axis {a}", fmt(b, signed=True),
                         fmt(w, signed=True) if written else "not written", change])
        whose = ("The joint zero offset o<sub>i</sub> the station holds (the drive takes "
                 "none over Modbus)" if held else
                 "The controller's joint zero offset o<sub>i</sub>")
        out.append(_table(["axis", "offset before (mm)",
                           "offset held (mm)" if held else "offset written (mm)",
                           "change (mm)"], rows, caption=(
            f"{whose}; the correction is "
            "o<sub>i</sub> ← o<sub>i</sub> − Δρ<sub>i</sub>. The old values are saved in "
            "the run directory, so <code>orthocal rollback</code> can restore them.")))
    if held:
        out.append(held_box(result))
    return "".join(out) or "<p>The controller's offsets were not read.</p>"


def _info_list(result: Mapping[str, Any]) -> str:
    machine = as_dict(result.get("machine"))
    timing = as_dict(result.get("timing"))
    rows = [
        ("run directory", f"<code>{esc(result.get('run_dir', '—'))}</code>"),
        ("started", esc(format_when(result.get("started")))),
        ("finished", esc(format_when(result.get("finished")))),
        ("duration", esc(format_duration(result.get("duration_s", timing.get("wall_s"))))),
        ("machine", esc(
            (f"{machine['id']}: " if machine.get("id") else "")
            + f"leg length L = {fmt(machine.get('leg_length'), 2)} mm, joint stroke "
            f"ρmin = {fmt(machine.get('rho_min'), 1)} mm … ρmax = "
            f"{fmt(machine.get('rho_max'), 1)} mm") if machine else "—"),
        ("model", esc(f"{MODEL_TEXT.get(str(result.get('model')), result.get('model', '—'))}"
                     f" ({result.get('method', '—')})")),
    ]
    if result.get("simulated"):
        sim = as_dict(result.get("simulation"))
        desc = "virtual machine (no hardware)"
        if sim:
            desc += (f"; seed {sim.get('seed') if sim.get('seed') is not None else 'random'}"
                     f", indicator noise σ = {fmt(sim.get('noise_mm'), 4)} mm")
        rows.append(("simulation", esc(desc)))
    else:
        rows.append(("devices", "as configured in the station config (config.toml)"))
    if timing:
        rows.append(("timing", esc(
            f"wall {format_duration(timing.get('wall_s'))}, {timing.get('moves', '—')} moves, "
            f"{timing.get('readings', '—')} readings, retries: {timing.get('retries', '—')}"
            + (f"; {timing['mountings']} mountings, {timing.get('operator_s', 0):.0f} s at the "
               "machine" if isinstance(timing.get("mountings"), int) else ""))))
    guard = as_dict(result.get("plunger_guard"))
    recovered = [r for r in guard.get("recovered") or [] if isinstance(r, dict)]
    if recovered:
        rows.append(("plunger guard", "<br>".join(esc(
            f"stopped the axes: indicator {r.get('indicator')} on {r.get('where')}, move to "
            f"{r.get('move')}; re-planned from where they stood via {r.get('waypoints')} "
            f"waypoint(s) at {fmt(r.get('speed_mm_s'), 1)} mm/s, the cycle taken again")
            for r in recovered)))
    return '<dl class="kv">' + "".join(f"<dt>{esc(k)}</dt><dd>{v}</dd>" for k, v in rows) + "</dl>"


def _loop_section(result: Mapping[str, Any], figures: bool = True) -> str:
    """The closed loop's rounds (station.report.rounds): plot and table."""
    from station.report import rounds
    from station.report.plots import pyplot, to_svg

    if not figures:
        return rounds.html_section(result, None)
    try:
        plot = rounds.plot_rounds(result, pyplot, to_svg)
    except Exception:
        plot = None  # the table still tells the rounds
    return rounds.html_section(result, plot)


def _field_plot(result: Mapping[str, Any]) -> str | None:
    """The error field at the tool (plots.plot_field), or None: a field the
    figure cannot draw must not cost the operator the rest of the report."""
    acc, _ = statement(result)
    if acc is None:
        return None
    try:
        return plot_field(acc)
    except Exception:
        return None  # the section's tables still state the figures


def render_html(result: dict, figures: bool = True) -> str:
    """The whole report as one HTML string (no external resources); ``figures``
    False: without its figures ([report] figures, `orthocal report` draws them)."""
    title = "Calibration report"
    when = format_when(result.get("started"))
    plot_tool = plot_dev = plot_par = None
    try:
        if figures:
            plot_tool = _field_plot(result)
            plot_dev = plot_deviations(result)
            plot_par = plot_parameters(result)
        loop_section = _loop_section(result, figures)
    finally:
        # Only where this page drew: release_fonts ends in a full garbage collection,
        # a tenth of a second in a long-lived process, for fonts a page without
        # figures never opened.
        if figures and "matplotlib" in sys.modules:
            release_fonts()
    # Figures are numbered in page order: the error field at the tool, when the
    # run states it, comes first.
    number = iter(range(1, 4))
    accuracy = tool_section(result, plot_tool, next(number) if plot_tool else None)
    drawn = []
    if plot_dev:
        drawn.append(
            f"<figure>{plot_dev}<figcaption>Figure {next(number)}. The 12 leg deviations: "
            "how far each indicator's reading in a test posture differs from its reading in "
            "Π<sub>0</sub>. Before calibration: measured (blue; error bar = std over the "
            "cycles, often smaller than the marker) and as the fitted model explains them "
            "(orange). After calibration: the verification measurement (green), which "
            "should be close to zero.</figcaption></figure>")
    if plot_par:
        drawn.append(
            f"<figure>{plot_par}<figcaption>Figure {next(number)}. Identified parameters "
            "with ±1σ (thick) and ±3σ (thin) error bars; after calibration the re-identified "
            "values should be near zero. In a simulated run the red bar marks the value "
            "hidden in the virtual machine.</figcaption></figure>")
    state = run_state(result)
    # A loop that did not converge, offsets the station holds: the warning colour
    # (st-refused's), never the green of a run that did all it set out to.
    status_cls = ("st-refused st-not-converged" if state == "not-converged" else
                  f"st-{state}" if state in STATE_TEXT else "st-failed")
    sim_tag = " (simulated)" if result.get("simulated") else ""
    badge = f'<span class="status {status_cls}">{esc(STATE_TEXT.get(state, state))}</span>'
    held = held_by_station(result)
    if held:
        badge += '<span class="status st-refused st-held">Offsets held by the station</span>'
    meta = ("Orthoglide-type parallel machine · leg-parallelism calibration · "
            f"{esc(when)}")
    no_figures = "" if figures else (
        '<p class="small">Drawn without its figures: '
        f"<code>orthocal report {esc(result.get('run_dir') or 'RUN_DIR')}</code> draws "
        "them.</p>")
    body = f"""
<h1>{esc(title)}{esc(sim_tag)}{badge}</h1>
<p class="meta">{meta}</p>{no_figures}
{header_boxes(result)}{_info_list(result)}
<h2>What was done</h2>
{what_was_done(result)}
<h2>Result</h2>
{result_paragraph(result)}
{accuracy}
{reversal.section_html(result)}
{budget.section_html(result)}{since.section_html(result)}
{"<h2>The measurement: the legs' parallelism</h2>" if accuracy else ""}
{_fit_box(result)}
{"".join(drawn)}
{loop_section}
<h2>Identified parameters</h2>
{_params_table(result)}
{_model_section(result)}
{stands_html(result)}
{_correlation_table(result)}
<h2>Deviations</h2>
{_deviations_table(result)}
<h2>Setups</h2>
{_setups_table(result)}
<h2>{"Offsets (held by the station)" if held else "Controller offsets"}</h2>
{_offsets_section(result)}
<p class="small">Generated by orthocal. All lengths in millimetres.</p>
"""
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{esc(title)} — {esc(when)}</title><style>{_CSS}</style></head>"
            f"<body>{body}</body></html>\n")


def write_html(result: dict, run_dir: Path, figures: bool = True) -> Path:
    """Write ``run_dir/report.html``: self-contained, plots inline as SVG (none
    when ``figures`` is False)."""
    path = Path(run_dir) / "report.html"
    write_atomic(path, render_html(result, figures))
    return path
