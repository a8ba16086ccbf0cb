"""A shop's acceptance limit judged at 95 % (docs/design.md, "Acceptance"): the
config's ``[acceptance]`` against the run's tool error after calibration
(``accuracy.after``, the machine as the run leaves it), into result.json's
``acceptance`` (station.record.result_acceptance).

The rule is ISO 14253-1's for proving conformance: PASS only where the whole 95 %
interval of the figure lies within the limit, FAIL where its lower end already
exceeds it, and otherwise the measurement cannot decide at 95 %. A completed run
that does not PASS exits with its own status (station.commands.cli,
EXIT_OUT_OF_TOLERANCE): a shop must not ship a machine the run could not show
within its limit."""

from __future__ import annotations

from typing import Literal

from station.config import AcceptanceConfig
from station.record.result import RunResult
from station.record.result_acceptance import Acceptance, AcceptanceCheck, Outcome
from station.record.result_accuracy import Accuracy
from station.record.result_base import Interval
from station.record.result_statement import Quantity

RULE = ("at 95 %: pass where the figure's whole 95 % interval lies within the limit, "
        "fail where its lower end exceeds it, else undecided (ISO 14253-1); the run "
        "passes only if every limit passes")


def _check(figure: Literal["rms", "max"], limit_um: float, value_mm: float | None,
           interval_mm: Interval | None) -> AcceptanceCheck:
    """One limit against the figure (mm) and its 95 % interval (mm, [lo, hi])."""
    interval = None if interval_mm is None else (1000.0 * interval_mm[0],
                                                 1000.0 * interval_mm[1])
    outcome: Outcome = ("undecided" if interval is None else
                        "pass" if interval[1] <= limit_um else
                        "fail" if interval[0] > limit_um else "undecided")
    return AcceptanceCheck(figure=figure, limit_um=limit_um,
                           value_um=None if value_mm is None else 1000.0 * value_mm,
                           interval_95_um=interval, outcome=outcome)


def judge(limits: AcceptanceConfig, result: RunResult) -> Acceptance | None:
    """result.json's ``acceptance`` for the run's ``result`` (``accuracy`` stated or
    not); None when the config sets no limit."""
    given: list[tuple[Literal["rms", "max"], float | None]] = [
        ("rms", limits.tool_rms_um), ("max", limits.tool_max_um)]
    wanted = [(name, limit) for name, limit in given if limit is not None]
    if not wanted:
        return None
    acc = result.accuracy
    note = None
    if isinstance(acc, Accuracy):
        after = acc.after
        figures = {"rms": (after.rms_mm, after.rms_interval_95_mm),
                   "max": (after.max_mm, after.max_interval_95_mm)}
    else:
        figures = {}
        note = ("the run states no tool error after calibration"
                + (f" ({acc.error})" if acc is not None else ""))
    checks = [_check(name, limit, *figures.get(name, (None, None))) for name, limit in wanted]
    outcomes = {c.outcome for c in checks}
    outcome: Outcome = "fail" if "fail" in outcomes else \
        "pass" if outcomes == {"pass"} else "undecided"
    return Acceptance(outcome=outcome, rule=RULE, checks=checks, note=note)


def judge_statement(limits: AcceptanceConfig, quantities: list[Quantity]) -> Acceptance | None:
    """result.json's ``acceptance`` from the statement's ``tool.after.rms`` and
    ``tool.after.max`` (the figure and its 95 % interval, mm); None when the config
    sets no limit."""
    given: list[tuple[Literal["rms", "max"], float | None]] = [
        ("rms", limits.tool_rms_um), ("max", limits.tool_max_um)]
    wanted = [(name, limit) for name, limit in given if limit is not None]
    if not wanted:
        return None
    stated = {q.name.rsplit(".", 1)[1]: q for q in quantities
              if q.name in ("tool.after.rms", "tool.after.max")}
    checks = [_check(name, limit, stated[name].value if name in stated else None,
                     stated[name].interval_95 if name in stated else None)
              for name, limit in wanted]
    outcomes = {c.outcome for c in checks}
    outcome: Outcome = "fail" if "fail" in outcomes else \
        "pass" if outcomes == {"pass"} else "undecided"
    note = None if stated else "the run states no tool error after calibration"
    return Acceptance(outcome=outcome, rule=RULE, checks=checks, note=note)
