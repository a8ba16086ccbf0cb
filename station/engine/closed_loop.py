"""The run's flow as one small state machine: measure → identify → write →
verify → (write → verify)… → finish (design.md, "Closed loop").

:func:`next_step` is a pure function from what has happened so far
(:class:`LoopState`) to what to do next. The executor (station.engine.procedure)
performs that step — or, on resume, replays it from the journal: a measurement
whose cycles are journaled is rebuilt without motion, a write-back whose
outcome is journaled is not redone — feeds the outcome back with
:meth:`LoopState.measured` / :meth:`LoopState.wrote`, and asks again. Because
replayed outcomes are the recorded ones, a resumed run walks the same states
and lands where the kill left it, and each correction is written exactly once.

States (``len(measurements)``, ``len(writes)``):

    (0, 0)          → measure "m"
    (k, k-1)        → the k-th measurement is decided:
                        k = 1: write round 1 (the first correction is always written)
                        k > 1 and significant and k-1 < max_iterations → write round k
                        k > 1 and significant, max reached → finish "max_iterations"
                        k > 1 and not significant → finish "converged"
    (k, k)          → the k-th write's outcome:
                        written and verify → measure the verification of round k
                        written, no verify → finish "not verified"
                        refused/declined/failed/skipped → finish with that reason

Extension points: a new kind of step (say, homing after a power cut) is one
more ``Step.kind`` and one more branch here, where the whole flow is visible.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

StepKind = Literal["measure", "write", "finish"]

#: Why the loop stopped (the run JSON's ``loop.stopped``): the first is success; the
#: report says each in words (station.report.rounds.STOP_TEXT).
STOP_REASONS: tuple[str, ...] = ("converged", "max_iterations", "refused", "declined",
                                 "failed", "skipped", "not-verified")


def phase_of(measurement: int) -> str:
    """Journal phase of the n-th measurement (0-based): "m", then "v" for the
    verification of round 1 (as before the loop existed), "v2", "v3"… after."""
    if measurement == 0:
        return "m"
    return "v" if measurement == 1 else f"v{measurement}"


@dataclass(frozen=True)
class Step:
    kind: StepKind
    phase: str | None = None  # measure: which phase
    round: int = 0  # write: the write-back number (1-based)
    reason: str | None = None  # finish: a key of STOP_REASONS


@dataclass
class LoopState:
    """What happened so far: one entry per measurement (was its correction
    significant?) and one per write-back (its outcome status)."""

    max_iterations: int
    verify: bool
    significant: list[bool] = field(default_factory=list)
    writes: list[str] = field(default_factory=list)  # WritebackOutcome.status

    def measured(self, significant: bool) -> None:
        self.significant.append(bool(significant))

    def wrote(self, status: str) -> None:
        self.writes.append(status)

    @property
    def written(self) -> int:
        return sum(1 for s in self.writes if s == "written")


def next_step(state: LoopState) -> Step:
    """The next step of the run from what has happened (see the module's table)."""
    k, w = len(state.significant), len(state.writes)
    if k == 0:
        return Step("measure", phase=phase_of(0))
    if w == k - 1:  # the last measurement waits for its decision
        if k == 1:
            return Step("write", round=1)
        if not state.significant[-1]:
            return Step("finish", reason="converged")
        if state.written >= state.max_iterations:
            return Step("finish", reason="max_iterations")
        return Step("write", round=w + 1)
    if w == k:  # the last write-back waits for its verification
        status = state.writes[-1]
        if status == "written":
            if not state.verify:
                return Step("finish", reason="not-verified")
            return Step("measure", phase=phase_of(k))
        return Step("finish", reason={"failed-restored": "failed"}.get(status, status))
    raise AssertionError(f"inconsistent loop state: {k} measurements, {w} write-backs")
