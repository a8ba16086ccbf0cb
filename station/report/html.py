"""report.html: one self-contained page (plots inline as SVG) from the result."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from drivers.files import write_atomic
from station.record.result import RunResult
from station.report import budget_table as budget
from station.report import first_screen, rounds, since, statement_table
from station.report import reversal_table as reversal
from station.report.boundary import ResultLike, as_result
from station.report.field_plot import plot_field
from station.report.format import (
    AXES,
    MODEL_TEXT,
    STATE_TEXT,
    at,
    esc,
    fmt,
    format_duration,
    format_when,
    held_by_station,
    minus_signs_html,
    mountings_text,
    run_state,
    um,
    writeback_text,
)
from station.report.header import header_boxes, run_facts
from station.report.mounting_files import figures_html, pictures_in
from station.report.plots import plot_deviations, plot_parameters, release_fonts
from station.report.stand_table import stands_html
from station.report.statement_figure import plot_statement
from station.report.story import result_paragraph, what_was_done
from station.report.style import CSS
from station.report.tables import (
    correlation_table,
    deviations_table,
    model_section,
    params_table,
    setups_table,
    table,
)
from station.report.tool import html_section as tool_section
from station.report.tool import statement


def _fit_box(result: RunResult) -> str:
    if result.residual_rms_mm is None and not result.fit_note:
        return ""
    rows = [
        ("residual RMS (measured − model)", f"{um(result.residual_rms_mm, 2)} µm"),
        ("σ = √(RSS / (n − p))", f"{um(result.sigma_mm, 2)} µm"),
        ("indicator noise (spread of readings at a stop)", f"{um(result.noise_mm, 2)} µm"),
        ("condition number (sensitivity of the fit to noise)",
         fmt(result.condition_number, 2)),
        ("deviations RMS before calibration", f"{um(result.deviations_rms_mm)} µm"),
    ]
    dl = "".join(f"<dt>{esc(k)}</dt><dd>{esc(v)}</dd>" for k, v in rows)
    ok = result.fit_ok
    cls = "box" if ok is not False else "box warn"
    verdict = ("The model explains the data: the residual is at the level of the indicator "
               "noise." if ok else "Warning: the residual is larger than the indicator noise "
               "explains; the machine may have errors this model does not include."
               if ok is False else "")
    note = (f"<p><b>Fit quality:</b> {esc(result.fit_note)}</p>" if result.fit_note else "")
    return f'<div class="{cls}">{note}<p>{esc(verdict)}</p><dl class="kv">{dl}</dl></div>'


def _writeback_box(result: RunResult) -> str:
    """What became of the correction: written, held by the station, or why not."""
    wb = result.writeback
    if wb is None:
        return ""
    held = held_by_station(result)
    back = result.rolled_back
    cls = "box" if wb.status == "written" and not held and back is None else "box warn"
    label = "held by the station" if held and wb.status == "written" else wb.status
    reason = f"<br>Reason: {esc(wb.reason)}" if wb.reason else ""
    if back is not None:  # what was written is no longer there: said before the table
        return (f'<div class="{cls}"><b>Write-back: {esc(label)}, then rolled back</b> — '
                f"on {esc(back.at)} <code>orthocal rollback</code> restored the offsets "
                "saved before the run: the machine is back as found, and the table below "
                f"shows the offsets it holds now.{reason}</div>")
    return (f'<div class="{cls}"><b>Write-back: {esc(label)}</b> — '
            f"{esc(writeback_text(result, wb.status))}.{reason}</div>")


def _offsets_section(result: RunResult) -> str:
    """The operator's result, first on the page: each joint's zero offset as found
    (read before the run) and as left (the last write-back or rollback, else as
    found), in mm, with what became of the correction above it; for a rolled-back run
    also what was written, so that the page never shows a write-back above offsets
    that merely came back."""
    before, written = result.offsets_before or {}, result.offsets_written or {}
    left = result.offsets_final or written or before
    held = held_by_station(result)
    back = result.rolled_back
    out = [_writeback_box(result)]
    if before or left:
        rows = []
        for a in AXES:
            if a not in before and a not in left:
                continue
            b, w = at(before, a), at(left, a)
            change = fmt(w - b, 4, signed=True) if b is not None and w is not None else "—"
            shown = [fmt(b, 4, signed=True), fmt(w, 4, signed=True), change]
            if back is not None:
                shown.insert(1, fmt(at(written, a), 4, signed=True))
            rows.append([f"joint {a}", *shown])
        whose = ("The joint zero offset o<sub>i</sub> the station holds (the drive takes "
                 "none over Modbus)" if held else
                 "The controller's joint zero offset o<sub>i</sub>")
        how = (f"written by the run, then restored by <code>orthocal rollback</code> on "
               f"{esc(back.at)}" if back is not None else
               f"{'held' if held else 'written and read back'} at its end "
               "(o<sub>i</sub> ← o<sub>i</sub> − Δρ<sub>i</sub>)")
        heads = ["joint (offsets in mm)", "as found", "as left", "change"]
        if back is not None:
            heads.insert(2, "written, rolled back")
        out.append(table(heads, rows, caption=(
            f"{whose}: as found, read before the run; as left, {how}. The old values are "
            "saved in the run directory, so <code>orthocal rollback</code> can restore "
            "them.")))
    # where the station holds them, the box at the top (header_boxes) says where to
    # enter them, just above
    return "".join(out) or "<p>The controller's offsets were not read.</p>"


def _machine_text(result: RunResult) -> str:
    m = result.machine
    return ((f"{m.id}: " if m.id else "")
            + f"leg length L = {fmt(m.leg_length, 2)} mm, strokes from Π0 "
            f"rho_min = {fmt(m.rho_min, 1)} mm … rho_max = {fmt(m.rho_max, 1)} mm")


def _where_text(result: RunResult) -> tuple[str, str]:
    """(what ran, on what): the virtual machine of a simulated run, else the devices."""
    if not result.simulated:
        return "devices", "as configured in the station config (config.toml)"
    desc = "virtual machine (no hardware)"
    if (sim := result.simulation) is not None:
        desc += (f"; seed {sim.seed if sim.seed is not None else 'random'}"
                 f", indicator noise σ = {um(sim.noise_mm, 2)} µm")
    return "simulation", esc(desc)


def _timing_text(result: RunResult) -> str:
    """The last session's work (the whole run's time is "duration")."""
    t = result.timing
    mountings = mountings_text(result)
    return (f"{t.moves} moves, {t.readings} readings, retries: {t.retries}, in "
            f"{format_duration(t.wall_s)} (its last session)"
            + (f"; mountings {mountings}" if mountings is not None else ""))


def _info_list(result: RunResult) -> str:
    rows = [
        *run_facts(result),
        ("run directory", f"<code>{esc(result.run_dir)}</code>"),
        ("started", esc(format_when(result.started))),
        ("finished", esc(format_when(result.finished))),
        ("duration", esc(format_duration(result.duration_s))),
        ("machine", esc(_machine_text(result))),
        ("model", esc(f"{MODEL_TEXT.get(result.model, result.model)} ({result.method})")),
        _where_text(result),
        ("timing", esc(_timing_text(result))),
    ]
    recovered = result.plunger_guard.recovered
    if recovered:
        rows.append(("plunger guard", "<br>".join(esc(
            f"stopped the axes: indicator {r.indicator} on {r.where}, move to "
            f"{r.move}; re-planned from where they stood via {r.waypoints} "
            f"waypoint(s) at {fmt(r.speed_mm_s, 1)} mm/s, the cycle taken again")
            for r in recovered)))
    return '<dl class="kv">' + "".join(f"<dt>{esc(k)}</dt><dd>{v}</dd>" for k, v in rows) + "</dl>"


def _loop_section(result: RunResult, figures: bool = True) -> str:
    """The closed loop's rounds (station.report.rounds): plot and table."""
    from station.report.plots import pyplot, to_svg

    if not figures:
        return rounds.html_section(result, None)
    try:
        plot = rounds.plot_rounds(result, pyplot, to_svg)
    except Exception:
        plot = None  # the table still tells the rounds
    return rounds.html_section(result, plot)


def _field_plot(result: RunResult) -> str | None:
    """The error field at the tool (field_plot.plot_field), or None: a field the
    figure cannot draw must not cost the operator the rest of the report."""
    acc, _ = statement(result)
    if acc is None:
        return None
    try:
        return plot_field(acc)
    except Exception:
        return None  # the section's tables still state the figures


def _drawn(result: RunResult, figures: bool) -> tuple[str | None, str | None, str | None, str]:
    """The page's figures (the error field at the tool, the deviations, the
    parameters; None each where not drawn) and the closed loop's section."""
    plot_tool = plot_dev = plot_par = None
    try:
        if figures:
            plot_tool = _field_plot(result)
            plot_dev = plot_deviations(result)
            plot_par = plot_statement(result) if result.statement else \
                plot_parameters(result)
        return plot_tool, plot_dev, plot_par, _loop_section(result, figures)
    finally:
        # Only where this page drew: release_fonts ends in a full garbage collection,
        # a tenth of a second in a long-lived process, for fonts a page without
        # figures never opened.
        if figures and "matplotlib" in sys.modules:
            release_fonts()


def _legs_figures(result: RunResult, plot_dev: str | None, plot_par: str | None,
                  first: int) -> str:
    """The deviations' and the parameters' figures, numbered from ``first``."""
    number = iter(range(first, first + 2))
    drawn = []
    if plot_dev:
        drawn.append(
            f"<figure>{plot_dev}<figcaption>Figure {next(number)}. The 12 leg deviations: "
            "how far each indicator's reading in a test posture differs from its reading in "
            "Π<sub>0</sub>, the mean of the cycles (their spread: the table Deviations). "
            "Before calibration: measured (blue) and as the fitted model explains them "
            "(orange). After calibration: the verification measurement (green), which "
            "should be close to zero.</figcaption></figure>")
    if plot_par:
        what = ("The statement of the machine: each joint's Δρ as found (blue) and as left "
                "(green), the tilts, the gaps and ΔL where identified, each bar its 95 % "
                "expanded uncertainty as the table above states it"
                if result.statement else
                "Identified parameters with their 95 % intervals (±k σ, k from Student's t "
                "on the identification's degrees of freedom); after calibration the "
                "re-identified values should be near zero")
        drawn.append(
            f"<figure>{plot_par}<figcaption>Figure {next(number)}. {what}. In a simulated "
            "run the red bar marks the value hidden in the virtual machine."
            "</figcaption></figure>")
    return "".join(drawn)


def _title(result: RunResult, figures: bool) -> str:
    """The page's heading with its badges, the meta line, and how to draw the
    figures of a page drawn without them."""
    state = run_state(result)
    # A loop that did not converge, a rollback, offsets the station holds: the warning
    # colour (st-refused's), never the green of a run that did all it set out to.
    status_cls = ("st-refused st-not-converged" if state == "not-converged" else
                  "st-refused" if state == "ok" and result.rolled_back is not None else
                  f"st-{state}" if state in STATE_TEXT else "st-failed")
    sim_tag = " (simulated)" if result.simulated else ""
    badge = f'<span class="status {status_cls}">{esc(STATE_TEXT[state])}</span>'
    if result.rolled_back is not None:
        badge += '<span class="status st-refused st-rolled-back">Rolled back</span>'
    if held_by_station(result):
        badge += '<span class="status st-refused st-held">Offsets held by the station</span>'
    meta = ("Orthoglide-type parallel machine · leg-parallelism calibration · "
            f"{esc(format_when(result.started))}")
    no_figures = "" if figures else (
        '<p class="small">Drawn without its figures: '
        f"<code>orthocal report {esc(result.run_dir or 'RUN_DIR')}</code> draws "
        "them.</p>")
    return (f"<h1>{esc(_TITLE)}{esc(sim_tag)}{badge}</h1>\n"
            f'<p class="meta">{meta}</p>{no_figures}')


def _identification(result: RunResult) -> str:
    """The first identification's heading: with a statement, the fit's own diagnostics
    follow it (its model test, the stands, the correlation of its estimates; the values
    are the statement's, above); a record from before the statement keeps its table of
    identified parameters."""
    if result.statement:
        return ("<h2>The first identification</h2><p class=\"small\">The fit of the first "
                "measurement, its model test and the correlation of its estimates; what it "
                "found of the machine is in <i>The statement of the machine</i>, "
                "above.</p>")
    return f"<h2>Identified parameters</h2>\n{params_table(result)}"


_TITLE = "Calibration report"
_AS_LEFT = "Controller offsets: as found → as left"
_AS_LEFT_HELD = "Offsets held by the station: as found → as left"


def render_html(result: ResultLike, figures: bool = True,
                pictures: Sequence[tuple[str, str]] = ()) -> str:
    """The whole report as one HTML string (no external resources); ``figures``
    False: without its figures ([report] figures, `orthocal report` draws them).
    ``result``: the record, or a document that becomes it (station.report.boundary);
    ``pictures``: the run's mounting pictures (mounting_files.pictures_in), with or
    without figures."""
    record = as_result(result)
    plot_tool, plot_dev, plot_par, loop_section = _drawn(record, figures)
    # Figures are numbered in page order: the error field at the tool, when the
    # run states it, comes first.
    accuracy = tool_section(record, plot_tool, 1 if plot_tool else None)
    held = held_by_station(record)
    body = minus_signs_html(f"""
{_title(record, figures)}
{first_screen.html_block(record)}
{header_boxes(record)}<h2 id="as-left">{_AS_LEFT_HELD if held else _AS_LEFT}</h2>
{_offsets_section(record)}
{_info_list(record)}
<h2>What was done</h2>
{what_was_done(record)}
<h2>Result</h2>
{result_paragraph(record)}
{statement_table.section_html(record)}
{accuracy}
{reversal.section_html(record)}
{budget.section_html(record)}{since.section_html(record)}
{"<h2>The measurement: the legs' parallelism</h2>" if accuracy else ""}
{_fit_box(record)}
{_legs_figures(record, plot_dev, plot_par, 2 if plot_tool else 1)}
{loop_section}
{_identification(record)}
{model_section(record)}
{stands_html(record)}
{correlation_table(record)}
<h2>Deviations</h2>
{deviations_table(record)}
<h2>Setups</h2>
{setups_table(record)}
{figures_html(pictures)}
<p class="small">Generated by orthocal. Each table states its unit in its header: µm for
the small errors, mm for lengths, positions and offsets, mm/m for squareness; the
statement's quantities carry theirs, each printed the one way every view prints it (a
length below 0.1 mm in µm, above in mm with its ± in µm).</p>
""")
    when = format_when(record.started)
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{esc(_TITLE)} — {esc(when)}</title><style>{CSS}</style></head>"
            f"<body>{body}</body></html>\n")


def write_html(result: ResultLike, run_dir: Path, figures: bool = True) -> Path:
    """Write ``run_dir/report.html``: self-contained, plots inline as SVG (none
    when ``figures`` is False); ``result`` as :func:`render_html` takes it."""
    path = Path(run_dir) / "report.html"
    write_atomic(path, render_html(result, figures, pictures_in(run_dir)))
    return path
