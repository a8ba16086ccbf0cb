"""result.json's ``acceptance``: the shop's limit on the tool's error after
calibration, judged at 95 % (docs/design.md, "Acceptance"; built by
station.analysis.acceptance from the config's ``[acceptance]`` and the run's
``accuracy.after``)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from station.record.result_base import Closed, Interval

Outcome = Literal["pass", "fail", "undecided"]


class AcceptanceCheck(Closed):
    """One limit against its figure: PASS where the figure's whole 95 % interval lies
    within the limit, FAIL where its lower end exceeds it, else undecided."""

    figure: Literal["rms", "max"] = Field(description="the tool's RMS or max |E| after "
                                                      "calibration (accuracy.after)")
    limit_um: float
    value_um: float | None = Field(description="the figure (null: not stated)")
    interval_95_um: Interval | None = Field(description="its 95 % interval (null: not "
                                                        "stated)")
    outcome: Outcome


class Acceptance(Closed):
    """acceptance: the run's outcome against ``[acceptance]``; absent without it."""

    outcome: Outcome = Field(description="fail if any check fails, pass if every one "
                                         "passes, else undecided")
    rule: str
    checks: list[AcceptanceCheck]
    note: str | None = Field(description="why a check could not be judged (null: none)")
