"""The decision table (docs/design.md, "The decision table"): what each quantity of the
statement says, by one stated rule per kind, and the false-alarm policy behind every
"act" (shim a rail, move a rail, put the geometry into the controller, compensate a
joint's play): act only on a value beyond k_act combined standard uncertainties,
k_act from Student's t on the quantity's effective dof for one false alarm in a
thousand square machines over three quantities (orthocal.loop.FALSE_ALARM, the closed
loop's own rule for writing a correction).

Decisions, by kind (the ``decision`` field of each quantity):

- ``drho_*.as_left``: "within" (|value − aim| + U ≤ the loop's limit, converge_mm and
  half the drive's count), "outside" (|value − aim| − U > the limit), else
  "not shown within"; "not verified" where nothing was measured after the last write
  (its value is then the aim, its uncertainty the written round's);
- ``drho_*.as_found``: "corrected" (an offset was written for the joint) or "left";
- tilts, gaps: "act" (beyond k_act·u_c), "none", or "undecided" where the data
  cannot tell the axes' tilts from the legs' bows;
- squareness: "out of square" (beyond k_act·u_c: what to do is the advice on the
  tilt or the gaps that make it), "square", or "undecided";
- reversal: "repair" (acting, and above the repair threshold), "compensate" (acting),
  "none";
- a joint's lead (``lead_*``): "compensate" where the joint has a table and its lead
  lies beyond k_act combined standard uncertainties (its table then corrects the
  joint in the controller: the exports write it), "none" where it has a table and
  its lead does not; no decision where the joint's error is only assumed (nothing
  measured to act on);
- ``tool.compensated.rms``: "gain" where the geometry in the controller lowers the
  tool's RMS error by more than k_act standard deviations of that gain over the
  draws (the same machines drawn for both), else "no gain";
- ``tool.after.*``: the acceptance check's "pass", "fail" or "undecided", where the
  config sets ``[acceptance]``.
"""

from __future__ import annotations

import math

import numpy as np

from orthocal.loop import FALSE_ALARM
from orthocal.noise import coverage_factor
from orthocal.uncertainty import Marginal

ACT, NONE, UNDECIDED = "act", "none", "undecided"
WITHIN, NOT_SHOWN, OUTSIDE = "within", "not shown within", "outside"
NOT_VERIFIED = "not verified"
CORRECTED, LEFT = "corrected", "left"
REPAIR, COMPENSATE = "repair", "compensate"
GAIN, NO_GAIN = "gain", "no gain"
OUT_OF_SQUARE, SQUARE = "out of square", "square"

#: The rule every "act" rests on, in words (the statement's and the docs').
ACT_RULE = ("act only where the value lies beyond k_act combined standard uncertainties "
            "(Type A and B), k_act from Student's t on its effective dof for one false "
            "alarm in a thousand square machines over three quantities")


def act_k(dof: float | None) -> float:
    """k_act: the coverage factor of a two-sided interval that misses a true zero with
    probability FALSE_ALARM."""
    return coverage_factor(None if dof is None or not math.isfinite(dof) else dof,
                           1.0 - FALSE_ALARM)


def act(value: float, marginal: Marginal, undecided: bool = False) -> str:
    """A tilt's, gap's or squareness's decision."""
    if undecided:
        return UNDECIDED
    return ACT if abs(value) > act_k(marginal.dof) * marginal.u_c else NONE


def square(value: float, marginal: Marginal, undecided: bool = False) -> str:
    """A squareness's decision, by the same rule as :func:`act`."""
    said = act(value, marginal, undecided)
    return {ACT: OUT_OF_SQUARE, NONE: SQUARE}.get(said, said)


def act_on_type_a(value: float, marginal: Marginal) -> bool:
    """Whether the value would be acted on were its Type B part zero: the stated
    inputs alone keep it from a decision."""
    return marginal.u_a > 0.0 and abs(value) > act_k(marginal.dof_a) * marginal.u_a


def within(value: float, aim: float, expanded: float, limit: float) -> str:
    """A joint's Δρ as left against the loop's limit."""
    off = abs(value - aim)
    if off + expanded <= limit:
        return WITHIN
    return OUTSIDE if off - expanded > limit else NOT_SHOWN


def play(value: float, marginal: Marginal, repair_above_mm: float) -> str:
    """A joint's reversal: a play, never negative; acted on only beyond k_act."""
    if not value > act_k(marginal.dof) * marginal.u_c:
        return NONE
    return REPAIR if value > repair_above_mm else COMPENSATE


def lead(value: float, u_c: float, dof: float | None) -> str:
    """A tabled joint's lead (µm/m) and its combined standard uncertainty: compensate
    only beyond k_act."""
    return COMPENSATE if abs(value) > act_k(dof) * u_c else NONE


def gain(after_draws: np.ndarray, compensated_draws: np.ndarray) -> str:
    """Whether the geometry in the controller lowers the tool's RMS error: the gain,
    draw by draw (the same machines), beyond k_act of its standard deviation (the
    "act" rule; the draws are too few for the false-alarm quantile itself)."""
    diff = np.asarray(after_draws) - np.asarray(compensated_draws)
    return GAIN if float(diff.mean()) > act_k(None) * float(diff.std()) else NO_GAIN
