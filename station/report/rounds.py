"""The closed loop in the report: the rounds' summary lines, a plot and a table.

Reads the result's ``iterations`` (one entry per measurement: the first
measurement, then each verification), ``converged`` and ``loop``; a run stopped
halfway has fewer entries, or none. Kept apart from station.report so the two can
change independently.
"""

from __future__ import annotations

import html
from collections.abc import Callable, Mapping
from typing import Any

from orthocal.loop import WRITABLE
from station.record.quantity_text import plus_minus
from station.record.result import Iteration, RunResult
from station.record.result_accuracy import Accuracy
from station.report.format import at, num, um, um_signed
from station.report.tool import objective

#: What each of the closed loop's stop reasons (the run JSON's ``loop.stopped``)
#: says: the first is success; the others say plainly what happened.
STOP_TEXT = {
    "converged": "the last verification shows every joint offset within ±converge_mm "
                 "(and half the drive's count) at 95 %",
    "max_iterations": "max_iterations write-backs done and the last verification still "
                      "finds a significant correction",
    "not-converged": "the last verification could not show every joint offset within "
                     "±converge_mm (and half the drive's count) at 95 %, even measured "
                     "again, nor a correction beyond its noise",
    "refused": "a correction was refused",
    "declined": "the operator declined a correction",
    "failed": "a write-back failed (the previous offsets were restored)",
    "skipped": "the model has no joint offsets to write",
    "not-verified": "verification is off ([procedure] verify = false)",
}


#: A verification's verdict (the iterations' ``verdict``, station.engine.closed_loop).
VERDICT_TEXT = {
    "significant": "significant",
    "converged": "shown converged",
    "suspected": "seen at 95 %, not beyond the noise of both rounds",
    "unproven": "hidden in its noise",
    "ambiguous": "undecided: the axes' tilts and the legs' bows explain it alike",
    "form-limited": "undecided: the legs' bows, measured once, are known too loosely",
    "budget-limited": "undecided: the stated inputs alone keep it from the limit",
}


def _um(value: float | None) -> str:
    v = num(value)
    return "—" if v is None else f"{v * 1000:.2f} µm"


def aim_of(result: RunResult, n: int) -> dict[str, float]:
    """The Δρ the loop aimed at in measurement ``n`` (mm): 0 for objective joints;
    for objective tool the round's ``target_drho``, and for a last round that
    wrote nothing the aim the run states (``accuracy.objectives``). Without it a
    tool run's intended Δρ of tens of µm would read as a correction left undone."""
    iterations = result.iterations or []
    target = iterations[n].target_drho if 0 <= n < len(iterations) else None
    acc = result.accuracy
    if target is None and n == len(iterations) - 1 and isinstance(acc, Accuracy):
        target = objective(acc, acc.objective).target_drho_mm
    return {k: v for k in WRITABLE if (v := at(target, k)) is not None}


def correction_mm(entry: Iteration, aim: Mapping[str, float] | None = None) -> float | None:
    """The largest |Δρ − aim| an identification asks to write (mm); the aim is 0
    unless objective tool set one (aim_of). A verification's Δρ is the one joined
    with the rounds before it (its ``joined``): what its verdict rests on and what a
    write-back after it writes, not its own look alone."""
    ident = (entry.joined.drho_mm if entry.joined is not None else None) or entry.identified
    aim = aim or {}
    values = [abs(v - aim.get(n, 0.0)) for n in WRITABLE if (v := at(ident, n)) is not None]
    return max(values) if values else None


def _label(n: int, entry: Iteration) -> str:
    return "measurement" if n == 0 else f"verification {n}"


def stop_text(result: RunResult) -> str:
    loop = result.loop
    if loop is None:
        return "—"
    text = STOP_TEXT[loop.stopped]
    if loop.detail:
        text += f" ({loop.detail})"
    return text


def judged_line(result: RunResult) -> str | None:
    """With ΔL or tilts in the model the verification cannot go to zero: say what it
    was judged against (the model's prediction after writing Δρ)."""
    ver = result.verification
    expected = num(ver.expected_rms_mm) if ver is not None else None
    if ver is None or expected is None or expected < 1e-4:
        return None
    return (f"verification judged against the model after correction: deviations RMS "
            f"{_um(ver.deviations_rms_mm)}, predicted {_um(expected)} (ΔL, tilts "
            f"and the joints' lost motion cannot be written), measured − predicted "
            f"{_um(ver.vs_expected_rms_mm)}")


def remaining_text(result: RunResult) -> str | None:
    """What the last verification found left of Δρ, not written, with its 95 %
    uncertainty: the statement's Δρ as left where the record has one, else (legacy)
    the remaining estimate with k from Student's t on the noise's dof. None before
    any write-back or without a measurement after it."""
    rem = result.remaining
    iterations = result.iterations or []
    if rem is None or not any(e.offsets_written for e in iterations):
        return None
    q = {x.name: x for x in result.statement or []}
    left = [q[f"{n}.as_left"] for n in WRITABLE if f"{n}.as_left" in q]
    if left:
        aim = aim_of(result, len(iterations) - 1)
        text = ", ".join(f"Δρ_{x.name[5]} {plus_minus(x)}" for x in left) + " (95 %)"
        if any(abs(a) > 0 for a in aim.values()):
            text += (" against the aim of objective tool (Δρ "
                     + ", ".join(f"{n[-1]} {1000 * a:+.2f}" for n, a in aim.items()) + " µm)")
        return text
    k = num(rem.coverage_factor_95)
    aim = aim_of(result, len(iterations) - 1)
    parts = []
    for n in WRITABLE:
        v, se = at(rem.estimate, n), at(rem.std_errors, n)
        if v is None:
            continue
        band = f" ± {1000 * k * se:.2f}" if k is not None and se is not None else ""
        parts.append(f"Δρ_{n[-1]} {1000 * (v - aim.get(n, 0.0)):+.2f}{band}")
    if not parts:
        return None
    dof = num(rem.std_errors_dof)
    how = (f" µm (95 %, k = {k:.2f} on {dof:.3g} dof)" if k is not None and dof is not None
           else " µm")
    if any(abs(a) > 0 for a in aim.values()):
        how += (" from the aim of objective tool (Δρ "
                + ", ".join(f"{n[-1]} {1000 * a:+.2f}" for n, a in aim.items()) + " µm)")
    return ", ".join(parts) + how


def summary_lines(result: RunResult) -> list[str]:
    """The rounds for the text summary: the verdict, then one line per measurement."""
    judged = judged_line(result)
    lines = [f"  {judged}"] if judged else []
    # what is left of Δρ is the first screen's "as left" (station.report.first_screen)
    return lines + _round_lines(result)


def _looped(result: RunResult) -> bool:
    """Whether the run has rounds to tell: two measurements, or a loop that stopped."""
    return len(result.iterations or []) >= 2 or result.loop is not None


def _round_lines(result: RunResult) -> list[str]:
    iterations = result.iterations or []
    loop = result.loop
    if not _looped(result):
        return []
    if loop is not None and loop.stopped in ("not-verified", "skipped"):
        return [f"  closed loop   off: {stop_text(result)}"]
    writes = sum(1 for e in iterations if e.offsets_written)
    head = f"  closed loop   {writes} write-back(s), {len(iterations)} measurement(s): "
    if result.converged:
        head += "converged — " + stop_text(result)
    else:
        head += "NOT CONVERGED — " + stop_text(result)
    lines = [head] + [_round_line(result, n, e) for n, e in enumerate(iterations)]
    if loop is not None:
        lines.append(f"    (at most {loop.max_iterations} write-backs, a correction counts "
                     f"beyond k σ, k from Student's t on the noise's dof for one false alarm "
                     f"in a thousand runs, and beyond {_um(loop.converge_mm)}; "
                     f"converged: every axis shown within "
                     f"{_um(loop.converged_within_mm or loop.converge_mm)} at "
                     f"95 %, a verification measured again up to "
                     f"{loop.max_extra_passes} more time(s) to show it)")
    return lines


def _round_line(result: RunResult, n: int, e: Iteration) -> str:
    """One measurement of the loop: what it found, its verdict, what was written."""
    sig = e.significant
    if not n:
        verdict = "first identification"
    elif e.verdict is not None:
        verdict = VERDICT_TEXT[e.verdict]
    else:
        verdict = "significant" if sig else "noise"
    action = "written" if e.offsets_written else (e.writeback or "not written")
    shown = list((e.shown_within_95_mm or {}).values())
    within = ""
    if n and not sig and shown:
        bound = [v for v in shown if v is not None]
        within = (", within " + ("an unknown bound" if len(bound) < len(shown)
                                 else _um(max(bound))) + " at 95 %")
    passes = e.passes or []
    again = f", {len(passes)} passes pooled" if len(passes) > 1 else ""
    return (f"    {_label(n, e):<15} deviations RMS {_um(e.deviations_rms_mm)}"
            f" (floor {_um(e.noise_floor_mm)}{again}), correction max "
            f"{_um(correction_mm(e, aim_of(result, n)))}"
            f"{', rounds joined' if n and e.joined else ''} ({verdict}{within}) → "
            f"{action}")


def plot_rounds(result: RunResult, pyplot: Callable[[], Any],
                svg: Callable[[Any], str]) -> str | None:
    """Deviations RMS, correction and noise floor per measurement, log scale (µm).
    None after a single write-back: the deviations' figure already shows before and
    after, and a figure costs ~0.2 s with the operator waiting at the end of the run."""
    iterations = result.iterations or []
    if sum(1 for e in iterations if e.offsets_written) < 2:
        return None
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 3.8))
    xs = list(range(len(iterations)))

    def series(values: list[float | None]) -> tuple[list[int], list[float]]:
        pts = [(x, v * 1000) for x, v in zip(xs, values, strict=True)
               if v is not None and v > 0]
        return [p[0] for p in pts], [p[1] for p in pts]

    dev = series([num(e.deviations_rms_mm) for e in iterations])
    cor = series([correction_mm(e, aim_of(result, n)) for n, e in enumerate(iterations)])
    floor = series([num(e.noise_floor_mm) for e in iterations])
    ax.plot(*dev, "o-", color="#1f5fa8", label="deviations RMS")
    aimed = any(any(abs(a) > 0 for a in aim_of(result, n).values()) for n in xs)
    ax.plot(*cor, "s-", color="#e08a00",
            label="correction max |Δρ − aim|" if aimed else "correction max |Δρ|")
    ax.plot(*floor, "--", color="#777777", label="noise floor (scatter)")
    converge = num(result.loop.converge_mm) if result.loop is not None else None
    if converge:
        ax.axhline(converge * 1000, color="#c0392b", lw=0.8, ls=":",
                   label="converge_mm")
    ax.set_yscale("log")
    ax.set_xticks(xs, [_label(n, e) for n, e in enumerate(iterations)], fontsize=8)
    ax.set_ylabel("µm")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return svg(fig)


def html_section(result: RunResult, plot: str | None) -> str:
    """The "Closed loop" section of report.html (empty when there was one measurement)."""
    if not _looped(result):
        return ""
    e = html.escape
    if result.loop is not None and result.loop.stopped in ("not-verified", "skipped"):
        return f"<h2>Closed loop</h2><p>Off: {e(stop_text(result))}.</p>"
    verdict = ("converged" if result.converged else "<b>did not converge</b>")
    parts = [f"<h2>Closed loop</h2><p>The loop {verdict}: {e(stop_text(result))}.</p>"]
    judged = judged_line(result)
    if judged:
        parts.append(f"<p>The {e(judged)}.</p>")
    if plot:
        parts.append(f"<figure>{plot}<figcaption>Each round: the deviations' RMS, the "
                     "largest correction the identification asks for, and the noise floor "
                     "from the cycle-to-cycle scatter. A correction within k standard errors "
                     "(Student's t on the noise's degrees of freedom, so "
                     "that a machine already fixed is rewritten in one run of a thousand) "
                     "or below converge_mm is not written.</figcaption></figure>")
    left = remaining_text(result)
    if left:
        aimed = "from the aim" in left or "against the aim" in left
        parts.append(f"<p>Left over after the last write-back, as the last verification "
                     f"measured it and the loop did not write it (too small to be worth a "
                     f"round, or the loop stopped as said above): {e(left)}. The machine's "
                     f"offsets are off {'from their aim ' if aimed else ''}"
                     f"by this much; its Δρ is the correction applied plus what the last "
                     f"verification measured (the JSON's remaining.total).</p>")
    parts.append(_rounds_table(result))
    return "\n".join(parts)


def _rounds_table(result: RunResult) -> str:
    """One row per measurement, every figure in µm: the offsets a round wrote are
    said as the change it made (the as found / as left table at the top holds the
    offsets themselves, in mm)."""
    e = html.escape
    # where the station holds the offsets, none of them reached the drive
    held = "held" if result.offsets_held_by == "station" else "written"
    prev = dict(result.offsets_before or {})
    rows = []
    for n, it in enumerate(result.iterations or []):
        written = it.offsets_written
        rows.append(
            "<tr>" + "".join(f"<td>{c}</td>" for c in (
                e(_label(n, it)), um(it.deviations_rms_mm, 2),
                um(it.residual_rms_mm, 2), um(it.noise_floor_mm, 2),
                um(correction_mm(it, aim_of(result, n)), 2),
                e(", ".join(it.significant) or "—"),
                e(_changes(prev, written)) if written else e(str(it.writeback or "—")),
            )) + "</tr>")
        prev.update({a: v for a, v in (written or {}).items() if v is not None})
    return ("<table><thead><tr><th>measurement (µm)</th><th>deviations RMS</th>"
            "<th>residual RMS</th><th>noise floor</th>"
            "<th>correction max (a verification's: joined with the rounds before)</th>"
            f"<th>significant</th><th>change of the offsets {held}</th></tr></thead><tbody>"
            + "".join(rows) + "</tbody></table>"
            '<p class="small">Each round\'s own estimates, as the loop decided on them '
            "round by round: its fit's residual and noise floor, the largest correction it "
            "asked for. What the run states of the machine is the statement's, above.</p>")


def _changes(before: Mapping[str, float | None], written: Mapping[str, float | None]) -> str:
    """"x −1101.0, y +698.0, z −401.0": what a round's write-back changed, in µm (the
    offset written where the one before is not known)."""
    def change(a: str, v: float | None) -> str:
        b = at(before, a)
        return "—" if v is None else um_signed(v - b if b is not None else v)
    return ", ".join(f"{a} {change(a, v)}" for a, v in written.items())
