"""The statement in the text summary's details (``--verbose``): every quantity the run
states, printed as the record holds it (station.record.quantity_text), with the
decision table's word on it; nothing computed here."""

from __future__ import annotations

from station.record.quantity_text import figure, plus_minus
from station.record.result import RunResult
from station.record.result_statement import Quantity

#: The groups of the details, in order: their label and the names they print.
GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("tilts", ("tilt_yx", "tilt_zx", "tilt_zy")),
    ("squareness", ("squareness_xy", "squareness_xz", "squareness_yz")),
    ("axes' gaps", ("gap_xy", "gap_xz", "gap_yz")),
    ("leg lengths", ("dl_x", "dl_y", "dl_z")),
    ("lost motion", ("reversal_x", "reversal_y", "reversal_z")),
    ("joints' lead", ("lead_x", "lead_y", "lead_z")),
)
#: The decision table's words, as the details print them.
DECIDED = {"act": "beyond its uncertainty: act", "none": "not beyond its uncertainty",
           "undecided": "not decided (tilts or bows)", "compensate": "compensate",
           "repair": "repair", "gain": "clearly lower", "no gain": "not clearly lower",
           "pass": "PASS", "fail": "FAIL", "out of square": "out of square",
           "square": "square within its uncertainty"}


def _one(q: Quantity, label: str) -> str:
    said = DECIDED.get(q.decision or "", q.decision or "")
    return f"{label} {plus_minus(q)}" + (f" ({said})" if said else "")


def detail_lines(result: RunResult) -> list[str]:
    """The statement's quantities beyond the first screen's (its joints and tool
    figures), each once, and how they are stated."""
    q = {x.name: x for x in result.statement or []}
    if not q:
        return []
    lines = []
    for label, names in GROUPS:
        held = [q[n] for n in names if n in q]
        if held:
            text = ", ".join(_one(x, x.name.split("_", 1)[1].upper()) for x in held)
            what = "reversal (ISO 230-2) " if label == "lost motion" else ""
            lines.append(f"  {label:<13} {what}{text} (95 %)")
            if label == "squareness":
                lines += [f"    {x.name[-2:].upper()}: {x.basis[-1]}" for x in held]
    comp = q.get("tool.compensated.rms")
    if comp is not None:
        lines.append(f"  in the controller  {figure(comp, 'RMS')}: "
                     f"{DECIDED.get(comp.decision or '', '')} than the offsets' alone")
    if lines:
        lines.append("  stated        each ± and interval at 95 %, Type A and B (GUM); "
                     "tilts, squareness and gaps act only beyond k_act uncertainties "
                     "(docs/design.md, \"The decision table\")")
    return lines
