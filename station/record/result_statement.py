"""result.json's ``statement`` and ``advice`` (docs/design.md, "The statement of the
machine" and "The decision table"): every quantity the run states, once, with one
value and one 95 % uncertainty, and every piece of advice, with the quantities it
rests on. Built once at the end of a run (station.statement); every view renders
them and computes nothing."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from station.record.result_base import Closed, Interval

#: The routes that put the identified geometry into the controller, as the advice and
#: the first screen name them.
CONTROLLER_ROUTES = "orthocal export --kinematics, or orthocal compensate"

#: The units a quantity is stated in (its size decides how a view prints it).
Unit = Literal["mm", "mrad", "mm/m", "µm/m"]


class Quantity(Closed):
    """One quantity of the machine as the run states it."""

    name: str = Field(description='e.g. "drho_x.as_left", "tilt_yx", "tool.after.rms"')
    value: float | None = Field(description="the best estimate (null: not stated)")
    unit: Unit
    expanded: float | None = Field(
        description="the 95 % expanded uncertainty, in ``unit`` (for a bounded quantity "
                    "such as an RMS, half the interval's width)")
    interval_95: Interval | None = Field(
        description="[low, high] at 95 %: value ± expanded, or asymmetric where the "
                    "quantity is bounded (an RMS is never negative)")
    k: float | None = Field(description="the coverage factor (null: not a k·u interval)")
    dof: float | None = Field(description="effective degrees of freedom (null: infinite)")
    decision: str | None = Field(
        description="what the decision table says of it (docs/design.md), or null")
    basis: list[str] = Field(description="the sources in its budget (Type A and B)")
    contributions: dict[str, float] | None = Field(
        None, description="each source's standard uncertainty on the quantity, in "
                          "``unit``, as the budget names it (the Type A part "
                          "\"repeatability\"), combined in quadrature (GUM); null for a "
                          "figure from Monte Carlo draws, or a record from before it "
                          "(the history's compare reads it)")


class AdviceItem(Closed):
    """One piece of advice: its ``text`` is what every view prints, verbatim."""

    id: str = Field(description='e.g. "shim.tilt_yx", "rail.gap_xy", "backlash"')
    text: str
    rests_on: list[str] = Field(description="the statement's quantities it follows from")

