"""The page's story: what the run did and what it found, in words, at the top of
report.html (station.report.html lays out the rest)."""

from __future__ import annotations

from collections.abc import Sequence

from orthocal import coverage_factor
from station.record.result import RunResult, Setup
from station.report.format import (
    MODEL_TEXT,
    at,
    esc,
    fmt,
    hidden,
    machine_parameters,
    max_abs,
    num,
    param_html,
    params_of,
    true_value,
    um,
    unit,
    writeback_text,
)
from station.report.statement_table import said, stated, symbol_html
from station.report.tool import statement, tool_clause


def what_was_done(result: RunResult) -> str:
    setups = result.setups or []
    cycles = sorted({s.cycles_used for s in setups})
    cyc = ""
    if cycles:
        cyc = (f" ({cycles[0]} cycle{'s' if cycles[0] != 1 else ''} per leg)"
               if len(cycles) == 1 else f" ({cycles[0]}–{cycles[-1]} cycles per leg)")
    # "auto" before its selection (a run stopped before it): the candidates, not a name
    model = MODEL_TEXT.get(result.model) or (
        "smallest model the data support (auto: joint offsets Δρ, and the tilts or gaps "
        "of the actuator axes only where the data show them)" if result.model == "auto"
        else result.model)
    method = {"linear": "the linearised calibration equations",
              "nonlinear": "the exact kinematic model (iterative least squares)"}[result.method]
    # [procedure] strokes: intermediate stops Π_i(s) beside or instead of Π_i^±.
    kinds = {k[:-2] for k in result.deviations or {}} or {"+", "-"}
    n_post = len(kinds)
    count = 3 * n_post * 2
    postures = ("the two test postures Π<sub>i</sub><sup>+</sup> and Π<sub>i</sub><sup>−</sup> "
                "(leg i pushed to the end of its stroke each way)") if kinds == {"+", "-"} else (
        f"{n_post} test postures Π<sub>i</sub>(s) along leg i's axis, at the strokes s of "
        "<code>[procedure] strokes</code>")
    stopped = ""
    if result.status in ("failed", "aborted"):
        # The paragraph below describes the whole procedure; say plainly that this
        # run did not get through it, or a reader takes it for a completed calibration.
        stopped = f"<p><b>This run stopped early</b>, {measured_so_far(setups)}; see the " \
                  "result below.</p>"
    return stopped + (
        "<p>Two dial indicators were mounted against each leg of the machine in turn. "
        "For each leg the station moved the machine from the <i>mechanical zero</i> "
        f"posture Π<sub>0</sub> to {postures} and "
        f"back, repeatedly{esc(cyc)}, reading the indicators at every stop. On a perfectly "
        "calibrated machine each leg moves parallel to itself in these postures, so the "
        f"indicators read the same everywhere; the {count} differences "
        f"(3 legs × {n_post} postures × 2 indicators), called <i>deviations</i>, show how far the "
        "legs tilt. From them the station estimated, by least squares on "
        f"{esc(method)}, the {esc(model)}.</p>"
        '<p class="small">Δρ<sub>i</sub> (joint offset): how far axis i really is from '
        "where its controller believes it is — an error of the encoder zero. "
        "ΔL<sub>i</sub> (leg-length error): how much leg i is longer than nominal. "
        "tilt<sub>yx</sub>, tilt<sub>zx</sub>, tilt<sub>zy</sub> (mrad): how far actuator "
        "axis y leans toward x, and axis z toward x and toward y, off square. "
        f"{_PM_STATED if result.statement else _PM_LEGACY}</p>"
    )


#: What a ± means on a page with a statement, and on one from before it.
_PM_STATED = ("Every ± and every interval on this page is the run's statement of the "
              "machine (its table below): a 95 % expanded uncertainty, the scatter (Type "
              "A) and every stated or assumed input (Type B) combined as the GUM combines "
              "them, k from Student's t on the quantity's effective dof (Welch–Satterthwaite).")
_PM_LEGACY = ("± values are 95 % expanded uncertainties, k·u: u the standard uncertainty "
              "from the noise measured in this run, k from Student's t on that noise's "
              "degrees of freedom (GUM), so that few cycles do not claim more than they "
              "show.")


def measured_so_far(setups: Sequence[Setup]) -> str:
    """What a run that stopped early had measured: "after measuring 1 setup (leg x,
    2 cycles)", or "before any setup was measured"."""
    if not setups:
        return "before any setup was measured"
    each = ", ".join(f"leg {s.leg}, {s.cycles_used} cycle{'s' if s.cycles_used != 1 else ''}"
                     for s in setups)
    return f"after measuring {len(setups)} setup{'s' if len(setups) != 1 else ''} ({each})"


def result_paragraph(result: RunResult) -> str:
    parts = [*_found(result), *_written(result), *_verified(result)]
    if not parts:
        parts.append("No measurement results were recorded.")
    return "<p>" + " ".join(parts) + "</p>"


def _found(result: RunResult) -> list[str]:
    """Whether the run completed, and what it identified."""
    parts: list[str] = []
    names = params_of(result)
    ident = machine_parameters(result)
    if result.status in ("failed", "aborted"):
        msg = result.message or "no reason recorded"
        parts.append(f"<b>The run did not complete</b>: {esc(msg)}. "
                     "Everything measured up to that point is kept in the run directory; "
                     "the controller's offsets were only changed if stated below.")
    if not names:
        return parts
    if result.statement:
        return parts + _stated(result)
    k = coverage_factor(num(result.std_errors_dof))
    vals = "; ".join(
        f"{param_html(n)} = {fmt(at(ident, n), signed=True)}"
        + ("" if (se := at(result.std_errors, n)) is None else f" ± {fmt(k * se)}")
        + f" {unit(n)}" for n in names
    )
    what = "joint offsets" if all(n.startswith("drho") for n in names) else "parameters"
    parts.append(f"The {what} were identified as {vals} (95 %, k = {k:.2f}).")
    parts += _reproduced(result, "The fitted model")
    sim = hidden(result)
    found = [(n, at(ident, n), true_value(sim, n)) for n in names]
    diffs = {u: [abs(v - t) for n, v, t in found if unit(n) == u
                 and t is not None and v is not None]
             for u in ("mm", "mrad")}
    if diffs["mm"] or diffs["mrad"]:
        parts.append("This was a simulated run; the identified values differ from the "
                     "virtual machine's hidden ones by at most " + " and ".join(
                         (f"{um(max(d))} µm" if u == "mm" else f"{fmt(max(d), 4)} mm/m")
                         for u, d in diffs.items() if d) + ".")
    return parts


def _reproduced(result: RunResult, fit: str) -> list[str]:
    """How closely ``fit`` reproduces the measured deviations, beside the noise."""
    resid, noise = num(result.residual_rms_mm), num(result.noise_mm)
    if resid is None:
        return []
    s = f"{fit} reproduces the measured deviations to {um(resid, 2)} µm RMS"
    if noise is not None:
        s += f" (indicator noise: {um(noise, 2)} µm)"
    return [s + "."]


def _stated(result: RunResult) -> list[str]:
    """What the run found, as its statement says it: each joint's Δρ as found, the
    tilts, gaps and leg lengths (the statement's table holds the rest)."""
    q = stated(result)
    found = [(f"{param_html(n.split('.')[0])}", said(x)) for n, x in q.items()
             if n.endswith(".as_found")]
    layout = [(symbol_html(n), said(x)) for n, x in q.items()
              if n.startswith(("tilt_", "gap_", "dl_"))]
    parts = []
    if found:
        parts.append("The run states the joint offsets as found as "
                     + "; ".join(f"{n} = {esc(v)}" for n, v in found) + " (95 %).")
    if layout:
        parts.append("It states " + "; ".join(f"{n} = {esc(v)}" for n, v in layout)
                     + " (95 %; what to do with them: the statement's advice, below).")
    parts += _reproduced(result, "The first fit")
    return parts


def _written(result: RunResult) -> list[str]:
    wb = result.writeback
    if wb is None:
        return []
    text = writeback_text(result, wb.status)
    reason = f" ({esc(wb.reason)})" if wb.reason else ""
    return [f"{esc(text[0].upper() + text[1:])}{reason}."]


def _verified(result: RunResult) -> list[str]:
    """The verification, and beside it what the tool does (or that it is not stated)."""
    # Parallel legs are the method's means, not the tool's accuracy: whatever the
    # verification shows, the same sentence says what the tool does (or that the
    # run does not state it), so that one is never read for the other.
    tool = tool_clause(result)
    _, why_not = statement(result)
    ver = result.verification
    if ver is None:
        parts = []
        if params_of(result) and result.status == "ok":
            parts.append("No verification measurement was made.")
        if tool:
            parts.append(f"{esc(tool[0].upper() + tool[1:])}.")
        return parts
    worst = max_abs(ver.deviations)
    s = ("A verification measurement shows the legs now parallel to within "
         f"{um(ver.deviations_rms_mm)} µm RMS")
    if worst is not None:
        s += f" (largest deviation {um(worst)} µm)"
    before = num(result.deviations_rms_mm)
    if before is not None:
        s += f", against {um(before)} µm RMS before calibration"
    s += ": that is the legs' parallelism, the method's means, not the tool's accuracy"
    if tool:
        s += f"; {esc(tool)}"
    else:
        s += ("; accuracy at the tool is not stated"
              + (f" ({esc(why_not)})" if why_not else " by this result"))
    return [s + "."]
