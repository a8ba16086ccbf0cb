"""Whether a run's record may leave the station as a calibration, and what it carries
(docs/design.md, "Machine history", export; "The geometry in the controller").

One decision for every route out of the station (``orthocal export --to
linuxcnc|twincat|csv``, ``--kinematics``; ``orthocal compensate`` takes its ambiguity
part): a run that did not complete, whose closed loop did not converge, or whose
last round could not tell the axes' tilts from the legs' bows, is no calibration to
put into a controller as it stands. An export needs ``--force`` for it, and then
says so in its file's header, in the run's own words. Every export's header names
the run, the machine and the verdict (:func:`header_lines`)."""

from __future__ import annotations

import textwrap

from station.record.quantity_text import plus_minus
from station.record.result import RunResult
from station.record.result_statement import Quantity

#: The width of a header's comment lines (HEADER before each not counted).
WIDTH = 76


def _as_left(result: RunResult) -> list[Quantity]:
    """The statement's Δρ as left, x, y, z (empty for a record from before it)."""
    q = {x.name: x for x in result.statement or []}
    return [q[n] for a in "xyz" if (n := f"drho_{a}.as_left") in q]


def _worst_off(result: RunResult) -> str | None:
    """How far the joints not shown within the loop's limit may be off at 95 %: the
    statement's Δρ as left ("Δρ_x as left +3.1 ± 14.2 µm (95 %, not shown within)");
    a record from before the statement, the last round's ``shown_within_95_mm`` ("Δρ_x
    may still be off by up to 17.3 µm at 95 %")."""
    left = _as_left(result)
    if left:
        off = [x for x in left if x.decision != "within"]
        return "; ".join(f"Δρ_{x.name[5]} as left {plus_minus(x)} (95 %, {x.decision})"
                         for x in off) or None
    last = result.iterations[-1] if result.iterations else None
    shown = {k: v for k, v in ((last.shown_within_95_mm or {}) if last else {}).items()
             if k.startswith("drho_") and v is not None}
    if not shown:
        return None
    worst = max(shown, key=lambda k: shown[k] or 0.0)
    return f"Δρ_{worst[-1]} may still be off by up to {1000 * (shown[worst] or 0.0):.1f} µm " \
        "at 95 %"


def budget_limited(result: RunResult) -> bool:
    """Whether the run's loop ended where the stated inputs alone (Type B) keep its
    joints from being shown within converge_mm: it corrected all the data can see, and
    its statement carries what the inputs leave (docs/design.md, "Closed loop"). Such a
    run is resolved as far as any measurement can take it: exported without --force,
    its verdict said in the header."""
    last = result.iterations[-1] if result.iterations else None
    return last is not None and last.verdict == "budget-limited"


def not_converged(result: RunResult) -> str | None:
    """Why the run is not shown converged, briefly (None: it is, it ended
    budget-limited, or it did not complete, which :func:`unresolved` says first): its
    loop stopped otherwise than "converged", or the record says ``converged`` false."""
    loop = result.loop
    if not ((loop is not None and loop.stopped != "converged") or result.converged is False):
        return None
    if budget_limited(result):
        return None
    how = f" ({loop.stopped})" if loop is not None else ""
    off = _worst_off(result)
    return f"the run did not converge{how}" + (f": {off}" if off else "")


def ambiguous(result: RunResult) -> str | None:
    """Why the run's last round is no geometry to trust (docs/model.md, "Tilts or
    bows"), or None: the legs' bows explained its deviations as well as the axes'
    tilts, so a tilt there may be a bow, which the tool never sees."""
    last = result.iterations[-1] if result.iterations else None
    if last is None or last.ambiguity is None:
        return None
    return (f"its last round could not tell the axes' tilts from the legs' bows "
            f"({last.model} or {last.ambiguity.explained_by})")


def unresolved(result: RunResult) -> list[str]:
    """Every reason the run is no calibration to export without ``--force`` ([]:
    none): a run that did not complete, a loop that did not converge, an ambiguous
    last round."""
    if result.status != "ok":
        return [f"the run {result.status} ({result.message or 'no message'})"]
    return [why for why in (not_converged(result), ambiguous(result)) if why is not None]


def refusal(result: RunResult, run_dir: str) -> str | None:
    """The one line an export without ``--force`` refuses with, or None: it may go."""
    reasons = unresolved(result)
    if not reasons:
        return None
    advice = ("; read a second gauge plane ([[setups]] again with at = 0.75) and calibrate "
              "again" if ambiguous(result) else "")
    return (f"{run_dir}: not exported: {' and '.join(reasons)}{advice}; give --force to "
            "export it all the same (its header then says so)")


def verdict(result: RunResult) -> str:
    """The run's verdict in words, for a header: how it ended, how its loop
    stopped, and a rollback since."""
    loop = result.loop
    if result.status != "ok":
        text = f"{result.status.upper()}: {result.message or 'no message'}"
    elif loop is None:
        text = "completed" + ("" if result.converged is None else
                              ", converged" if result.converged else ", NOT CONVERGED")
    elif loop.stopped == "converged":
        within = loop.converged_within_mm
        text = "converged" + ("" if within is None else
                              f": every joint offset shown within ±{1000 * within:.1f} µm "
                              "at 95 %") + f", {loop.write_backs} write-back(s)"
    elif budget_limited(result):
        off = _worst_off(result)
        text = (f"NOT CONVERGED ({loop.stopped}, budget-limited: the stated inputs alone keep "
                f"the joints from being shown within the limit{f'; {off}' if off else ''}), "
                f"{loop.write_backs} write-back(s)")
    else:
        text = f"NOT CONVERGED ({loop.stopped})"
    if ambiguous(result):
        text += "; AMBIGUOUS last round"
    if result.acceptance is not None:
        text += f"; acceptance {result.acceptance.outcome}"
    if result.rolled_back is not None:
        text += (f"; rolled back on {result.rolled_back.at} (the controller holds the "
                 "offsets from before it)")
    return text


def _words(result: RunResult) -> str:
    """What the run itself says of how it ended: its loop's detail, else its message."""
    loop = result.loop
    return (loop.detail if loop is not None and loop.detail else result.message) or ""


#: How every line of an export's header begins: a later export onto the same file
#: (an INI exported before) knows its own lines by it and writes them afresh.
HEADER = "# orthocal export: "


def header_lines(result: RunResult, forced: bool = False) -> list[str]:
    """The comment lines every export's header holds, each beginning with HEADER: the
    run (its directory), the machine, the verdict; with ``forced``, what the run
    carries that made ``--force`` necessary, in its own words."""
    machine = result.machine.id or "no [machine] id"
    text = [f"run {result.run_dir}, machine {machine}", f"verdict: {verdict(result)}"]
    if left := _as_left(result):
        text.append("the run's statement, Δρ as left: " + ", ".join(
            f"{x.name[5]} {plus_minus(x)}" for x in left) + " (95 %)")
    reasons = unresolved(result)
    if forced and reasons:
        said = "; ".join(reasons)
        words = _words(result)
        if words:
            said += f". The run says: {words}"
        text.append(f"EXPORTED WITH --force, NOT A CALIBRATION TO TRUST AS IT STANDS: {said}")
    # a path or a run directory is never broken across lines
    return [HEADER + line for paragraph in text
            for line in textwrap.wrap(paragraph, WIDTH, subsequent_indent="  ",
                                      break_long_words=False, break_on_hyphens=False)]
