"""What a resumed run does not do again: one executor of journaled steps
(docs/design.md, "Run directory").

A run is small journaled steps; each step's record is fsynced before the next step
starts. A step is known by its identity (the keys below), and the run state
(station.record.state.RunState: the journal folded, every record saved folded in as
it is written) holds each done step's record under it. :meth:`Steps.take` is the
one place that decides: a step whose record is there is not taken again, its record
stands for it; any other is taken, and journals its record. Whether live or
replayed, the caller goes on from the step's record, so a resumed run decides
exactly as the run it continues. The kinds of step:

- a cycle (:class:`CycleStep`): its moves and readings, ending in the plan's
  :class:`~station.plan.steps.Checkpoint`, whose ``cycle`` record holds its
  deviations;
- a setup's end (:class:`SetupEnd`, ``setup_done``) and a repeat of its cycles
  (:class:`RepeatStep`, ``repeat``);
- a round's identification (:class:`RoundFit`: ``identification`` for the
  measurement, round 0; ``verification`` for round n), with the passes it pooled;
- a write-back round (:class:`WritebackRound`, whose record is its final stage) and
  each of its stages (:class:`WritebackStage`: backup, intent);
- the station's own test of a joint (:class:`JointTestStep`, ``joint-test``).

The records a ``setup-redo`` voided are not in the state: a setup measured again is
measured from its first cycle. The sequencer, the flow and write-back never look the
journal up themselves.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TypeVar

from station.record.journal import Cycle, JointTested, Repeat, SetupDone, WritebackRecord
from station.record.journal_file import Journal
from station.record.state import Fit, RunState

R = TypeVar("R")
R_co = TypeVar("R_co", covariant=True)

#: A write-back round's stages that end it, in the order they are looked for.
FINAL_STAGES = ("done", "refused", "declined", "failed-restored", "skipped")


class StepKey(Protocol[R_co]):
    """A step's identity: finds the step's record in the run state (None: not done)."""

    def find(self, state: RunState) -> R_co | None: ...


@dataclass(frozen=True)
class CycleStep:
    phase: str
    setup: int
    cycle: int

    def find(self, state: RunState) -> Cycle | None:
        return state.cycles.get((self.phase, self.setup, self.cycle))


@dataclass(frozen=True)
class SetupEnd:
    phase: str
    setup: int

    def find(self, state: RunState) -> SetupDone | None:
        return state.setups_done.get((self.phase, self.setup))


@dataclass(frozen=True)
class RepeatStep:
    phase: str
    setup: int
    repeat: int  # 1: the setup's first repeat

    def find(self, state: RunState) -> Repeat | None:
        return state.repeats.get((self.phase, self.setup, self.repeat))


@dataclass(frozen=True)
class JointTestStep:
    """The station's own test of ``joint``, whose record (``joint-test``) holds its table:
    a test cut off before it is taken again from its mounting."""

    joint: str

    def find(self, state: RunState) -> JointTested | None:
        return state.joint_tests.get(self.joint)


@dataclass(frozen=True)
class RoundFit:
    """Round ``round``'s identification (0: the measurement's) of ``passes`` passes: a
    record of fewer passes is the round before a further pass was measured, so the
    pooled one is journaled again."""

    round: int
    passes: int

    def find(self, state: RunState) -> Fit | None:
        fit = state.fits.get(self.round)
        pooled = None if fit is None else 1 if fit.passes is None else len(fit.passes)
        return fit if pooled is not None and pooled >= self.passes else None


@dataclass(frozen=True)
class WritebackStage:
    round: int
    stage: str

    def find(self, state: RunState) -> WritebackRecord | None:
        return state.writebacks.get(self.round, {}).get(self.stage)


@dataclass(frozen=True)
class WritebackRound:
    """A write-back round as a whole: done once one of its final stages is journaled."""

    round: int

    def find(self, state: RunState) -> WritebackRecord | None:
        stages = state.writebacks.get(self.round, {})
        return next((stages[s] for s in FINAL_STAGES if s in stages), None)


class Steps:
    """Takes each step once across every session of a run (module docstring)."""

    def __init__(self, journal: Journal) -> None:
        self.journal = journal

    def take(self, step: StepKey[R], act: Callable[[], object],
             replayed: Callable[[R], object] | None = None) -> R | None:
        """The step's record: the journaled one (``replayed`` is told of it), else the
        one ``act`` journals taking the step; None if it journaled none (an intent
        the operator declined)."""
        done = step.find(self.journal.state)
        if done is not None:
            if replayed is not None:
                replayed(done)
            return done
        act()
        return step.find(self.journal.state)

    def once(self, step: StepKey[object], record: dict[str, object]) -> None:
        """Journal ``record`` as ``step``'s, unless the journal holds the step's already."""
        self.take(step, lambda: self.journal.append(record))
