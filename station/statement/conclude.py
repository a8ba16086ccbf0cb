"""The end of a run, in one place (docs/design.md, "The statement of the machine"): from
the snapshot of its rounds (station.statement.snapshot.Rounds) the statement of the
machine, the advice, and what reads them (the loop's verdict, the uncertainty budget,
the accuracy section, the acceptance, model.json). Each is computed once, here."""

from __future__ import annotations

import math
from dataclasses import dataclass

from orthocal.budget import STEEL_ALPHA
from orthocal.numbers import finite
from station.analysis import acceptance as accept
from station.analysis import reversal
from station.analysis.run_budget import inputs, largest_first, stated_inputs
from station.record.model import MachineModel
from station.record.result import Loop, Remaining
from station.record.result_acceptance import Acceptance
from station.record.result_accuracy import Accuracy
from station.record.result_base import NotStated
from station.record.result_sections import BudgetSource, UncertaintyBudget
from station.record.result_statement import AdviceItem, Quantity
from station.statement import decisions as rule
from station.statement import quantities as qty
from station.statement.accuracy_section import accuracy_section, machine_model
from station.statement.advice import advice
from station.statement.known_machine import DRHO, KnownMachine, known_machine
from station.statement.snapshot import Rounds
from station.statement.tool_figures import tool_figures


@dataclass(frozen=True)
class Conclusion:
    """What the end of a run states: ``statement`` and ``advice`` (the record's), and
    the sections that read them. ``converged``: every joint's Δρ as left shown within
    the loop's limit (the statement's decisions)."""

    statement: list[Quantity]
    advice: list[AdviceItem]
    converged: bool
    loop: Loop
    remaining: Remaining | None
    uncertainty_budget: UncertaintyBudget | NotStated | None
    accuracy: Accuracy | NotStated | None
    acceptance: Acceptance | None
    model: MachineModel | None


def _remaining(rounds: Rounds, machine: KnownMachine) -> Remaining | None:
    """What the rounds joined say is left of Δρ now, and the machine at the start."""
    if not rounds.verified:
        return None
    n = len(rounds.idents) - 1
    se = rounds.joined[n].std_errors
    dof = rounds.last.std_error_dof
    m = {d: machine.drho.marginal(d) for d in machine.now}
    return Remaining(phase=rounds.iterations[-1].phase, round=len(rounds.iterations),
                     estimate=dict(machine.now), total=dict(machine.start),
                     std_errors={d: finite(se.get(d)) for d in machine.now},
                     std_errors_dof=finite(dof),
                     coverage_factor_95=finite(m[DRHO[0]].k) if m else None)


def _budget(rounds: Rounds, machine: KnownMachine) -> UncertaintyBudget:
    """The budget of Δρ (as found and as left alike), from the statement's own joint
    distribution: its sources, combined, and U at 95 %."""
    m = {d: machine.drho.marginal(d) for d in machine.now}
    sources: dict[str, dict[str, float | None]] = {}
    for d, mm in m.items():
        for src, u in mm.contributions.items():
            sources.setdefault(src, {})[d] = u
    first = "repeatability"
    rows = [BudgetSource(source=first, type="A", distribution="normal", value_mm=None,
                         u_mm=None, contributions_mm=sources.pop(first, {}),
                         dof=finite(next(iter(m.values())).dof_a) if m else None)]
    half = _half_widths(rounds)
    rows += sorted((BudgetSource(source=s, type="B", distribution="rectangular",
                                 value_mm=(h := half.get(s)),
                                 u_mm=None if h is None else h / math.sqrt(3.0),
                                 contributions_mm=c)
                    for s, c in sources.items()),
                   key=largest_first)
    given, assumed, instruments = stated_inputs(rounds.config)
    return UncertaintyBudget(
        statement="remaining.total" if rounds.verified else "identified", sources=rows,
        combined_mm={d: x.u_c for d, x in m.items()},
        effective_dof={d: finite(x.dof) for d, x in m.items()},
        coverage_factor={d: x.k for d, x in m.items()},
        expanded_95_mm={d: x.expanded for d, x in m.items()}, inputs=given,
        assumed=assumed, instruments=instruments,
        method=("GUM (JCGM 100:2008): the rounds' scatter joined (Type A) and each stated "
                "input (Type B, uniform within its bound) through the sensitivity of the "
                "round's identification (stands and model included), combined in "
                "quadrature, Welch-Satterthwaite dof, Student's k for 95 %; Δρ as found and "
                "as left carry the same uncertainty (the offsets written between them were "
                "read back); each gauge plane's bow within the stated straightness, half of "
                "it common to every plane (docs/model.md, \"The statement's uncertainty\")"))


def _half_widths(rounds: Rounds) -> dict[str, float | None]:
    """Each Type B source's bound on what it puts on one deviation (mm), as the budget
    names it: the legs' straightness (the largest stated), the temperature step's
    α·ΔT·L/2, each gauge's MPE; the plunger angle is a relative error (none)."""
    given = inputs(rounds.config)
    straight = given.leg_straightness_mm.value
    out: dict[str, float | None] = {
        "leg straightness": float(max(straight) if isinstance(straight, list) else straight),
        "temperature": STEEL_ALPHA * float(given.temperature_change_c.value)  # type: ignore[arg-type]
        * rounds.config.machine.leg_length / 2.0,
        "plunger angle": None}
    for sp in rounds.config.setups:
        for name, d in sp.indicators.items():
            out[f"gauge MPE {name} (leg {sp.leg}, along {d.lstrip('-')})"] = \
                float(given.mpe_mm[name].value)  # type: ignore[arg-type]
    return out


def _undecided_by_inputs(quantities: list[Quantity], machine: KnownMachine) -> list[str]:
    """The quantities the stated inputs, not the data, keep from a decision: a tilt,
    gap or squareness acted on were its Type B part zero, a Δρ shown within were it."""
    out = []
    for q in quantities:
        if q.decision == rule.NONE and q.name.startswith(("tilt_", "gap_")) \
                and machine.layout_u is not None and q.value is not None:
            if rule.act_on_type_a(q.value, machine.layout_u.marginal(q.name)):
                out.append(q.name)
        elif q.decision == rule.NOT_SHOWN and q.name.endswith(".as_left"):
            d = q.name.split(".")[0]
            m = machine.drho.marginal(d)
            if m.u_b > m.u_a:
                out.append(q.name)
    return out


def conclude(rounds: Rounds, stopped: Loop, remedy: str | None) -> Conclusion:
    """The end of a run that identified Δρ (its loop's ``stopped`` as the closed loop
    ended it; ``remedy``: the verdict's words where it did not converge)."""
    machine = known_machine(rounds)
    tool = tool_figures(rounds, machine)
    basis = machine.joint().source_names()
    quantities = (qty.drho_quantities(rounds, machine) + qty.layout_quantities(rounds, machine)
                  + qty.squareness_quantities(rounds, machine)
                  + qty.reversal_quantities(rounds.reversal)
                  + qty.lead_quantities(rounds.joints)
                  + qty.tool_quantities(tool, basis))
    acceptance = accept.judge_statement(rounds.config.acceptance, quantities)
    if acceptance is not None:
        outcome: dict[str, str] = {c.figure: c.outcome for c in acceptance.checks}
        quantities = [q.model_copy(update={"decision": outcome[q.name.rsplit(".", 1)[1]]})
                      if q.name.startswith("tool.after.") and q.name.rsplit(".", 1)[1]
                      in outcome else q for q in quantities]
    left = [q for q in quantities if q.name.endswith(".as_left")]
    converged = bool(left) and all(q.decision == rule.WITHIN for q in left) \
        and stopped.stopped == "converged"
    loop = stopped if converged or stopped.stopped != "converged" else \
        stopped.model_copy(update={"stopped": "not-converged"})
    acc = accuracy_section(rounds, machine, tool, {q.name: q for q in quantities})
    said = advice(rounds.config, quantities, _undecided_by_inputs(quantities, machine),
                  converged, remedy, joints_share=tool.assumed_share,
                  assumed_joints=[] if tool.joints is None else tool.joints.assumed,
                  drive_count=acc.drive_count)
    _advice_into(acc, rounds, said)
    return Conclusion(
        statement=quantities,
        advice=said,
        converged=converged, loop=loop, remaining=_remaining(rounds, machine),
        uncertainty_budget=_budget(rounds, machine), accuracy=acc, acceptance=acceptance,
        model=machine_model(rounds, machine))


def _advice_into(acc: Accuracy, rounds: Rounds, said: list[AdviceItem]) -> None:
    """The accuracy section's advice lists are the advice's own texts (one decision each):
    the rails', and the joints' play with what it leaves at the tool."""
    acc.squareness_advice = [a.text for a in said if a.id.startswith(("shim.", "undecided."))]
    acc.gap_advice = [a.text for a in said if a.id.startswith(("rail.", "undecided."))]
    if rounds.reversal is not None:
        tool = reversal.at_the_tool(rounds.config, rounds.reversal, rounds.points)
        plays = [a.text for a in said if a.id in ("backlash", "repair")]
        acc.reversal = tool.model_copy(update={"advice": "; ".join(plays) or (
            "nothing to compensate: no joint's reversal lies beyond its uncertainty "
            "(the decision table's rule)")})
