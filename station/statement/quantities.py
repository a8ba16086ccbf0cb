"""The statement's quantities (docs/design.md, "The statement of the machine"): each
joint's Δρ as found and as left, the tilts, the gaps, the squareness of the tool's
motions, the leg lengths where identified, the joints' reversal and lead, and the
tool's error, each with one value and one 95 % uncertainty from the machine's one joint
distribution (station.statement.known_machine), and the decision table's word on it
(station.statement.decisions)."""

from __future__ import annotations

import numpy as np

from orthocal import AXES, GAP_NAMES, PARAM_NAMES, TILT_NAMES
from orthocal.accuracy import squareness
from orthocal.joint_error import lead_um_per_m
from orthocal.lost_motion import Reversal
from orthocal.uncertainty import Marginal, type_a
from station.analysis.joints import JointKnowledge
from station.analysis.reversal import REPAIR_ABOVE_MM
from station.analysis.verdict import converge_limit
from station.record.result_base import Interval
from station.record.result_statement import Quantity, Unit
from station.statement import decisions as rule
from station.statement.joints_at_tool import route_words
from station.statement.known_machine import DL, DRHO, KnownMachine
from station.statement.snapshot import Rounds
from station.statement.tool_figures import Figure, ToolFigures

#: Squareness of the tool's motions (ISO 230-1) and the tilt it equals to first order.
PAIRS: tuple[tuple[str, str], ...] = (("xy", "tilt_yx"), ("xz", "tilt_zx"), ("yz", "tilt_zy"))
#: The names the statement gives the tool's figures.
TOOL = {"before": "tool.before", "after": "tool.after", "compensated": "tool.compensated"}


#: A source below this share of a quantity's combined uncertainty is not named in its
#: basis (it is in the budget): a part a thousand times smaller says nothing and would
#: differ in its last digits from one CPU to the next.
NEGLIGIBLE = 1e-3


def _basis(m: Marginal, extra: float = 0.0, extra_why: str = "") -> list[str]:
    """The sources of a marginal that matter, largest first (their sizes are the
    budget's): the Type A part with its dof, each Type B source by name."""
    parts = sorted(((name, u) for name, u in m.contributions.items()
                    if u >= NEGLIGIBLE * m.u_c), key=lambda kv: (-round(kv[1], 9), kv[0]))
    out = [("repeatability (Type A" + (f", {m.dof_a:.0f} dof)" if m.dof_a else ")"))
           if name == "repeatability" else f"{name} (Type B)" for name, _ in parts]
    if extra > 0.0:
        out.append(f"{extra_why} (added whole)")
    return out


def linear(name: str, value: float, unit: Unit, m: Marginal, decision: str | None = None,
           extra: float = 0.0, extra_why: str = "") -> Quantity:
    """A quantity linear in the parameters: value ± (k·u_c + ``extra``), ``extra`` a
    bound the data cannot shrink (another explanation as good), added whole."""
    expanded = m.expanded + extra
    return Quantity(name=name, value=float(value), unit=unit, expanded=float(expanded),
                    interval_95=(float(value - expanded), float(value + expanded)),
                    k=float(m.k), dof=None if m.dof is None else float(m.dof),
                    decision=decision, basis=_basis(m, extra, extra_why),
                    contributions={n: float(u) for n, u in m.contributions.items()})


def bounded(name: str, figure: Figure, basis: list[str], decision: str | None = None
            ) -> Quantity:
    """A figure never negative (an RMS, a max): its interval from the draws."""
    lo, hi = figure.interval
    iv: Interval = (lo, hi)
    return Quantity(name=name, value=figure.value, unit="mm", expanded=(hi - lo) / 2.0,
                    interval_95=iv, k=None, dof=None, decision=decision, basis=basis)


AMBIGUOUS = "the legs' bows explain the data as well as the axes' tilts (model.md, " \
    "\"Tilts or bows\")"


def drho_quantities(rounds: Rounds, machine: KnownMachine) -> list[Quantity]:
    """Each joint's Δρ at the start of the run and as the run leaves it: one
    uncertainty for both (the offsets written between them are known exactly)."""
    limit = converge_limit(rounds.config.procedure.converge_mm, rounds.offset_count_mm)
    out = []
    corrected = {f"drho_{a}" for w in rounds.written for a in AXES
                 if w.before is not None and w.written is not None
                 and abs(float(w.written[a]) - float(w.before[a])) > 0.0}
    for name in DRHO:
        if name not in machine.now:
            continue
        m = machine.drho.marginal(name)
        extra = machine.apart.get(name, 0.0)
        found = linear(f"{name}.as_found", machine.start[name], "mm", m,
                       rule.CORRECTED if name in corrected else rule.LEFT, extra, AMBIGUOUS)
        left = linear(f"{name}.as_left", machine.now[name], "mm", m, extra=extra,
                      extra_why=AMBIGUOUS)
        left = left.model_copy(update={"decision": rule.within(
            machine.now[name], machine.aim[name], float(left.expanded or 0.0), limit)
            if machine.measured_now else rule.NOT_VERIFIED})
        out += [found, left]
    return out


def layout_quantities(rounds: Rounds, machine: KnownMachine) -> list[Quantity]:
    """The pooled tilts (mrad) and gaps (mm), and the leg lengths where identified."""
    undecided = bool(machine.apart)
    out = []
    if machine.layout_u is not None:
        for name in (*TILT_NAMES, *GAP_NAMES):
            if name not in machine.layout:
                continue
            m = machine.layout_u.marginal(name)
            value = machine.layout[name]
            unit: Unit = "mrad" if name in TILT_NAMES else "mm"
            out.append(linear(name, value, unit, m, rule.act(value, m, undecided)))
    if machine.dl_u is not None:
        for name in DL:
            if name in machine.dl:
                out.append(linear(f"dl_{name[-1]}", machine.dl[name], "mm",
                                  machine.dl_u.marginal(name)))
    return out


def squareness_quantities(rounds: Rounds, machine: KnownMachine) -> list[Quantity]:
    """The squareness of the tool's motions XY, XZ, YZ at Π0 (mm/m): to first order
    the tilts, plus the shear the gaps and the offsets give the motions; linear in the
    parameters, so its uncertainty is the joint distribution's through its gradient."""
    if machine.layout_u is None:
        return []
    geometry = rounds.config.machine.geometry()
    theta = machine.params("now")
    zero = np.zeros(3)
    base = np.array(list(squareness(theta, geometry, offsets=zero).as_dict().values()))
    joint = machine.joint()
    grad = np.zeros((3, len(PARAM_NAMES)))
    step = 1e-4
    for c in range(len(PARAM_NAMES)):
        d = np.zeros(len(PARAM_NAMES))
        d[c] = step
        up = np.array(list(squareness(theta + d, geometry, offsets=zero).as_dict().values()))
        dn = np.array(list(squareness(theta - d, geometry, offsets=zero).as_dict().values()))
        grad[:, c] = (up - dn) / (2 * step)
    # what of it is the axes' own tilt, and what the gaps and the offsets written shear
    tilts_only = np.zeros(len(PARAM_NAMES))
    for n in TILT_NAMES:
        tilts_only[PARAM_NAMES.index(n)] = theta[PARAM_NAMES.index(n)]
    own = np.array(list(squareness(tilts_only, geometry, offsets=zero).as_dict().values()))
    undecided = bool(machine.apart)
    out = []
    for i, (pair, tilt) in enumerate(PAIRS):
        m = joint.linear_marginal(grad[i])
        value = float(base[i])
        q = linear(f"squareness_{pair}", value, "mm/m", m, rule.square(value, m, undecided))
        parts = (f"of the value, the axes' own tilt ({tilt}) {_part(own[i])} and the "
                 f"shear the gaps and the offsets give the motions {_part(value - own[i])}")
        out.append(q.model_copy(update={"basis": [*q.basis, parts]}))
    return out


def _part(mm_per_m: float) -> str:
    """A part of a squareness at the value's own precision (0.001 mm/m); one that
    rounds to nothing is said so, not as a signed zero."""
    if abs(mm_per_m) < 0.0005:
        return "under 0.0005 mm/m"
    return f"{mm_per_m:+.3f} mm/m"


def reversal_quantities(rev: Reversal | None) -> list[Quantity]:
    """Each joint's reversal (ISO 230-2), its scatter alone (Type A)."""
    if rev is None:
        return []
    out = []
    for a in AXES:
        v, se = rev.value.get(a), rev.std_errors.get(a)
        if v is None or se is None:
            continue
        m = type_a((a,), np.array([[se * se]]), rev.dof).marginal(a)
        out.append(linear(f"reversal_{a}", v, "mm", m, rule.play(v, m, REPAIR_ABOVE_MM)))
    return out


def lead_quantities(knowledge: JointKnowledge | None) -> list[Quantity]:
    """Each tabled joint's lead (µm/m, docs/model.md (J3)): the table's least-squares
    slope with its 95 % interval (its points' uncertainty, taken as correlated in the
    worst way, and the residual scatter about the line), decided "compensate" beyond
    k_act. A joint without a table has no lead known: its bound is an input of the
    budget and of the tool (result.json's ``joints`` states it), not a quantity."""
    out: list[Quantity] = []
    for j in () if knowledge is None else knowledge.joints:
        if j.table is None:
            continue
        lo, hi = j.lead_interval_95_um_per_m
        lead = lead_um_per_m(j.table)
        u_c = float(np.hypot(lead.points_um_per_m / 2.0, lead.scatter_um_per_m))
        dof = float(lead.dof) if lead.scatter_um_per_m > 0 and lead.dof > 0 else None
        where = f"{j.source}: {j.file or 'the station' + chr(39) + 's own test'}"
        basis = [f"the table ({where})",
                 "its points' expanded uncertainty, taken as correlated in the worst way "
                 "(Type B)",
                 f"the residual scatter about the line (Type A, {lead.dof} dof)"]
        out.append(Quantity(
            name=f"lead_{j.axis}", value=j.lead_um_per_m, unit="µm/m",
            expanded=(hi - lo) / 2.0, interval_95=(lo, hi), k=None, dof=dof,
            decision=rule.lead(j.lead_um_per_m, u_c, dof), basis=basis))
    return out


def tool_quantities(tool: ToolFigures, basis: list[str],
                    acceptance: dict[str, str] | None = None) -> list[Quantity]:
    """The tool's figures: before, after, with the geometry in the controller (RMS
    and max of |E| over the workspace, mm; the last by ``tool.route``, with the joint
    tables where the run has them); ``acceptance``: the after-figures' outcome per
    figure ("rms", "max") where the config sets a limit."""
    gain = rule.gain(tool.after.rms.draws, tool.compensated.rms.draws)
    joints = tool.joints
    out = []
    for key, fig in (("before", tool.before), ("after", tool.after),
                     ("compensated", tool.compensated)):
        route = tool.route if key == "compensated" else "offsets"
        said = [*basis, *([] if joints is None else joints.basis(route))]
        if key == "compensated":
            said.append(f"route: {route_words(route)}")
        for stat in ("rms", "max"):
            decision = (acceptance or {}).get(stat) if key == "after" else \
                gain if (key, stat) == ("compensated", "rms") else None
            out.append(bounded(f"{TOOL[key]}.{stat}", getattr(fig, stat), said, decision))
    return out


def by_name(quantities: list[Quantity]) -> dict[str, Quantity]:
    return {q.name: q for q in quantities}
