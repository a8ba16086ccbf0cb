"""The closed loop's decisions, a small pure state machine: measure → identify →
write → verify → (write → verify)… → finish (docs/design.md, "Closed loop").

:func:`next_step` is a pure function from what has happened so far
(:class:`LoopState`) to what to do next. The executor (station.engine.procedure)
performs that step — or, on resume, replays it from the journal: a measurement
whose cycles are journaled is rebuilt without motion, a write-back whose
outcome is journaled is not redone — feeds the outcome back with
:meth:`LoopState.measured` / :meth:`LoopState.extended` / :meth:`LoopState.wrote`,
and asks again. Because replayed outcomes are the recorded ones, a resumed run
walks the same states and lands where the kill left it, and each correction is
written exactly once.

A measurement ends in a verdict: "significant" (a correction beyond the noise of
both rounds and beyond converge_mm: write it), "converged" (the remaining Δρ is
shown within ±converge_mm at 95 % on every axis: orthocal.loop.shown_within), or
neither: "suspected" (a correction the round sees at 95 % that is not written: a
first measurement's under converge_mm, or one on an axis already shown within the
limit) or "unproven" (the round's noise hides whatever is left), "form-limited"
(what is left hides in the bows carried from a second gauge plane), or "ambiguous"
(what keeps it undecided is not noise: the axes' tilts and the legs' bows explain
its deviations alike, station.analysis.model_choice.measured_form). Each
setup of a verification has already taken more cycles on its mounted gauges where
its own scatter said the verdict needed them ([procedure] max_cycles_in_mounting,
station.engine.sequencer). After a write-back, a leftover under converge_mm that the
rounds joined see at 95 % where it keeps "converged" out of reach is written (the
joined Δρ̂, station.analysis.verdict.judge): a write and its verification cost the
mountings a further pass would, and leave the machine closer. Where nothing is seen,
the round is measured again, a further pass of the same verification pooled with it
(phase "v+1", "v2+1"…), up to ``max_extra_passes``: what is left beyond the noise
then shows as significant and is written, a machine within converge_mm shows as
converged. Still undecided, the loop ends "not-converged", saying why.

A first measurement that finds nothing to write is itself the verification of a
machine already calibrated (a recheck), and is sized like one: its further passes
("m+1", "m+2"…) take more cycles on the mounted gauges as a verification's do, and it
may take the passes the rounds it did not need would have taken
(:func:`extra_passes_allowed`), never more mountings than the run's "most"
(:func:`mountings_expected`). On a tilted machine with stands set by eye one pass
cannot show a joint within converge_mm at 95 % (the stands' placement alone makes
about a micrometre of each Δρ's standard error, and only another mounting averages
it): ending there "not converged" would call a good machine bad.

States (``len(verdicts)``, ``len(writes)``):

    (0, 0)          → measure "m"
    (k, k-1)        → the k-th round is decided:
                        significant, k-1 < max_iterations → write round k
                          (the first measurement's too: a machine within
                          tolerance is not written to, a recheck moves nothing)
                        significant, max reached → finish "max_iterations"
                        converged → finish "converged"
                        suspected/unproven, passes left → the round's next pass
                          (extra_passes_allowed: the first round's are more)
                        suspected/unproven, none left → finish "not-converged"
                        ambiguous → finish "not-converged" (no pass can decide it)
                        form-limited → finish "not-converged" (the bows carried
                          from the second gauge plane hold Δρ's error; no pass
                          at the middles shrinks it)
                        budget-limited → finish "not-converged" (the stated
                          inputs' Type B part alone keeps a joint from being
                          shown within the limit; no pass shrinks it)
    (k, k)          → the k-th write's outcome:
                        written and verify → measure the verification of round k
                        written, no verify → finish "not verified"
                        refused/declined/failed/skipped → finish with that reason

Extension points: a new kind of step (say, homing after a power cut) is one
more ``LoopStep.kind`` and one more branch here, where the whole flow is visible.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from station.record.phase import Phase, phase_of

StepKind = Literal["measure", "write", "finish"]

#: Why the loop stopped (the run JSON's ``loop.stopped``): the first is success; the
#: report says each in words (station.report.rounds.STOP_TEXT).
STOP_REASONS: tuple[str, ...] = ("converged", "max_iterations", "not-converged", "refused",
                                 "declined", "failed", "skipped", "not-verified")


def round_phase(phase: str) -> str:
    """The phase of the round a pass belongs to ("v2+1" → "v2"; station.record.phase)."""
    return str(Phase.parse(phase).first_pass)


@dataclass(frozen=True)
class LoopStep:
    kind: StepKind
    phase: str | None = None  # measure: which phase
    round: int = 0  # write: the write-back number (1-based)
    reason: str | None = None  # finish: a key of STOP_REASONS
    extra: int = 0  # measure: a further pass of the last round (1, 2…), 0: a new round


@dataclass
class LoopState:
    """What happened so far: one verdict per measured round (its last pass decides)
    with the further passes it took, and one entry per write-back (its status)."""

    max_iterations: int
    verify: bool
    max_extra_passes: int = 0
    verdicts: list[str] = field(default_factory=list)  # Verdict
    extra: list[int] = field(default_factory=list)
    writes: list[str] = field(default_factory=list)  # WritebackOutcome.status

    def measured(self, verdict: str | bool) -> None:
        """A new round's first pass (a bool: significant or not, and then shown)."""
        if isinstance(verdict, bool):
            verdict = "significant" if verdict else "converged"
        self.verdicts.append(verdict)
        self.extra.append(0)

    def extended(self, verdict: str) -> None:
        """A further pass of the last round: its verdict on all passes pooled."""
        self.verdicts[-1] = verdict
        self.extra[-1] += 1

    def wrote(self, status: str) -> None:
        self.writes.append(status)

    @property
    def written(self) -> int:
        return sum(1 for s in self.writes if s == "written")


def next_step(state: LoopState) -> LoopStep:
    """The next step of the run from what has happened (see the module's table)."""
    k, w = len(state.verdicts), len(state.writes)
    if k == 0:
        return LoopStep("measure", phase=phase_of(0))
    if w == k - 1:  # the last measurement waits for its decision
        verdict = state.verdicts[-1]
        if verdict == "converged":
            return LoopStep("finish", reason="converged")
        if verdict in ("ambiguous", "form-limited", "budget-limited"):
            # not noise: a pass cannot help
            return LoopStep("finish", reason="not-converged")
        if verdict in ("suspected", "unproven"):
            if state.extra[-1] < extra_passes_allowed(k - 1, state.max_extra_passes,
                                                      state.max_iterations, state.verify):
                extra = state.extra[-1] + 1
                return LoopStep("measure", phase=phase_of(k - 1, extra), extra=extra)
            return LoopStep("finish", reason="not-converged")
        if state.written >= state.max_iterations:
            return LoopStep("finish", reason="max_iterations")
        return LoopStep("write", round=w + 1)
    if w == k:  # the last write-back waits for its verification
        status = state.writes[-1]
        if status == "written":
            if not state.verify:
                return LoopStep("finish", reason="not-verified")
            return LoopStep("measure", phase=phase_of(k))
        return LoopStep("finish", reason={"failed-restored": "failed"}.get(status, status))
    raise AssertionError(f"inconsistent loop state: {k} measurements, {w} write-backs")


def extra_passes_allowed(measurement: int, max_extra_passes: int, max_iterations: int,
                         verify: bool = True) -> int:
    """How many further passes the ``measurement``-th round (0-based) may take while
    undecided: ``max_extra_passes`` for a verification; for the first measurement,
    which has written nothing, also the passes of the verifications it did not need,
    ``(1 + max_extra_passes) · (1 + max_iterations) − 1`` (verify off: no
    verifications, ``max_extra_passes``): the mountings stay within
    :func:`mountings_expected`'s ``most``, and a recheck of a calibrated machine has
    the data a calibration's verifications would have had to show it converged."""
    if measurement > 0 or not verify:
        return max_extra_passes
    return (1 + max_extra_passes) * (1 + max_iterations) - 1


def mountings_expected(setups: int, max_iterations: int, max_extra_passes: int,
                       verify: bool = True, second: int | None = None,
                       later: int | None = None) -> dict[str, int]:
    """How many times the operator mounts the gauges, from the flow above: the run's
    first pass mounts each of its ``setups``, its second pass each of ``second`` and
    every later pass each of ``later`` (station.plan.steps.Plan.setups_of: a second
    gauge plane is read in the second pass alone; None: ``setups``), but every pass
    after the very first starts with the gauges its pass before ended with, still on
    (station.engine.kept).

    ``fewest``: the first measurement alone, decided in one pass (a machine within
    tolerance, nothing written; a recheck that needs further passes to show it takes
    their mountings too). ``usual``: one write-back and its verification, each decided
    in one pass. ``per_write_back``: what each further write-back and its verification
    add. ``most``: every round up to ``max_iterations`` write-backs, each measurement
    taking all its ``max_extra_passes``; as many as a first measurement that writes
    nothing may take in passes (:func:`extra_passes_allowed`). A retake, a resume (it
    mounts afresh) or a kept mounting the plan check refuses after a write-back adds its
    own beyond these."""
    total = (1 + max_extra_passes) * (1 + (max_iterations if verify else 0))
    two = max((setups if second is None else second) - 1, 0)
    each = max((setups if later is None else later) - 1, 0)
    return {"fewest": setups, "usual": setups + (two if verify else 0),
            "per_write_back": each,
            "most": setups + (two if total > 1 else 0) + max(total - 2, 0) * each}
