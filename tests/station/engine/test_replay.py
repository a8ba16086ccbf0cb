"""station.engine.replay: one executor of journaled steps, which the sequencer
(cycles, repeats, setups), the flow (identifications) and write-back (rounds and
stages) all resume through: a step whose record the journal holds is not taken
again, its record stands for it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from station.engine.replay import (
    CycleStep,
    RepeatStep,
    RoundFit,
    SetupEnd,
    Steps,
    WritebackRound,
    WritebackStage,
)
from station.record.journal_file import Journal
from station.record.state import RunState

ZERO = {"x": 0.0, "y": 0.0, "z": 0.0}


def _cycle(phase: str, setup: int, cycle: int) -> dict[str, Any]:
    return {"type": "cycle", "phase": phase, "setup": setup, "cycle": cycle,
            "deviations": {"+xy": 0.1 * cycle}}


def _done(setup: int) -> dict[str, Any]:
    return {"type": "setup_done", "phase": "m", "setup": setup, "cycles": [1, 2]}


def _journal(tmp_path: Path, records: list[dict[str, Any]]) -> Journal:
    journal = Journal(tmp_path / "journal.jsonl")
    for record in records:
        journal.append(record)
    return journal


def test_each_step_is_found_by_its_identity(tmp_path: Path) -> None:
    with _journal(tmp_path, [
        _cycle("m", 0, 1), _cycle("m", 0, 2), _done(0), _cycle("m", 1, 1),
        {"type": "writeback", "stage": "backup", "before": ZERO},  # before rounds: round 1
        {"type": "writeback", "round": 2, "stage": "intent", "before": ZERO, "written": ZERO},
        {"type": "writeback", "round": 2, "stage": "declined", "reason": "declined",
         "before": ZERO},
        {"type": "identification", "model": "rho", "parameters": {}, "std_errors": {}},
    ]) as journal:
        state = journal.state
    assert CycleStep("m", 0, 2).find(state) is state.cycles[("m", 0, 2)]
    assert CycleStep("m", 0, 2).find(state).deviations == {"+xy": 0.2}  # type: ignore[union-attr]
    assert CycleStep("m", 1, 2).find(state) is None and CycleStep("v", 0, 1).find(state) is None
    assert SetupEnd("m", 0).find(state) is not None and SetupEnd("m", 1).find(state) is None
    assert WritebackStage(1, "backup").find(state) is not None
    assert WritebackStage(2, "intent").find(state) is not None
    assert WritebackStage(3, "backup").find(state) is None
    assert WritebackRound(1).find(state) is None  # backed up, not ended
    final = WritebackRound(2).find(state)
    assert final is not None and final.stage == "declined"
    # one pass journaled: a round pooling two is identified (and journaled) again
    assert RoundFit(0, 1).find(state) is not None and RoundFit(0, 2).find(state) is None
    assert RoundFit(1, 1).find(state) is None


def test_a_step_journaled_is_not_taken_again(tmp_path: Path) -> None:
    taken: list[str] = []
    replayed: list[Any] = []

    def measure(cycle: int) -> None:
        taken.append(f"cycle {cycle}")
        journal.append(_cycle("m", 0, cycle))

    with _journal(tmp_path, [_cycle("m", 0, 1)]) as journal:
        steps = Steps(journal)
        first = steps.take(CycleStep("m", 0, 1), lambda: measure(1), replayed.append)
        second = steps.take(CycleStep("m", 0, 2), lambda: measure(2), replayed.append)
        assert taken == ["cycle 2"] and replayed == [first]
        assert second is journal.state.cycles[("m", 0, 2)]  # the record the step journaled
        # a record journaled once, whoever asks again
        steps.once(RepeatStep("m", 0, 1), {"type": "repeat", "phase": "m", "setup": 0,
                                           "repeat": 1})
        steps.once(RepeatStep("m", 0, 1), {"type": "repeat", "phase": "m", "setup": 0,
                                           "repeat": 1})
        assert list(journal.state.repeats) == [("m", 0, 1)]
        # a step that journals nothing (an intent declined) has no record
        assert steps.take(WritebackStage(1, "intent"), lambda: None) is None
    # and a later session of the run skips what this one did
    with Journal(tmp_path / "journal.jsonl") as again:
        assert Steps(again).take(CycleStep("m", 0, 2), lambda: measure(2)) is not None
    assert taken == ["cycle 2"]


def test_a_setup_redone_is_measured_again_from_its_first_cycle(tmp_path: Path) -> None:
    with _journal(tmp_path, [_cycle("m", 0, 1), _cycle("m", 0, 2), _done(0),
                             _cycle("m", 1, 1),
                             {"type": "setup-redo", "phase": "m", "setup": 0},
                             _cycle("m", 0, 1)]) as journal:
        state = journal.state
    redone = CycleStep("m", 0, 1).find(state)
    assert redone is not None and redone.t == max(c.t for c in state.cycles.values())
    assert CycleStep("m", 0, 2).find(state) is None and SetupEnd("m", 0).find(state) is None
    assert CycleStep("m", 1, 1).find(state) is not None  # another setup is untouched


def test_an_empty_journal_replays_nothing() -> None:
    state = RunState()
    assert CycleStep("m", 0, 1).find(state) is None and SetupEnd("m", 0).find(state) is None
    assert WritebackStage(1, "backup").find(state) is None
    assert WritebackRound(1).find(state) is None
