"""What the run state (station.record.state) keeps for station.engine.recovery, from
journal records alone: which setup a power cut interrupted (with its readings), and
how a setup-redo voids that setup's earlier cycles (and only those)."""

from __future__ import annotations

from typing import Any

from builders import journal_header

from station.record.journal import RECORD, JournalRecord
from station.record.state import RunState

HEADER = journal_header(started="now")


def _typed(records: list[dict[str, Any]]) -> list[JournalRecord]:
    return [RECORD.validate_python({"t": 0.0, **r}) for r in records]


def _setup(setup: int, indicators: dict[str, str]) -> dict[str, Any]:
    return {"type": "setup", "phase": "m", "setup": setup, "leg": "x",
            "indicators": indicators}


def _cycle(setup: int, cycle: int) -> dict[str, Any]:
    return {"type": "cycle", "phase": "m", "setup": setup, "cycle": cycle,
            "deviations": {"+xy": 0.1 * cycle}}


def _reading(stop: str, value: float) -> dict[str, Any]:
    return {"type": "reading", "stop": stop, "indicator": "A", "values": [value]}


def _records() -> list[dict[str, Any]]:
    return [
        HEADER,
        _setup(0, {"A": "y", "B": "z"}), _reading("m:0:0:0", 0.5), _cycle(0, 1),
        {"type": "setup_done", "phase": "m", "setup": 0, "cycles": [1]},
        _setup(1, {"A": "x", "B": "z"}), _reading("m:1:0:0", 1.0), _cycle(1, 1),
        {"type": "repeat", "phase": "m", "setup": 1, "repeat": 1},
        _cycle(1, 2),
    ]


def test_the_interrupted_setup_is_the_last_mounted_and_unfinished() -> None:
    state = RunState.of(_typed(_records()))
    assert state.live is not None
    assert (state.live.phase, state.live.setup, state.live.indicators) == \
        ("m", 1, {"A": "x", "B": "z"})
    # its own readings only: setup 0's are not its stops
    assert state.live.readings == {("m:1:0:0", "A"): [1.0]}
    done = RunState.of(_typed([*_records(), {"type": "setup_done", "phase": "m", "setup": 1,
                                             "cycles": [1, 2]}]))
    assert done.live is None


def test_a_remounted_setup_keeps_the_readings_of_its_mountings() -> None:
    # a resume remounts the interrupted setup: its Π0 readings from before stand
    state = RunState.of(_typed([*_records(), {"type": "resumed"}, _setup(1, {"A": "x"}),
                                _reading("m:1:2:0", 2.0)]))
    assert state.live is not None and state.live.indicators == {"A": "x"}
    assert state.live.readings == {("m:1:0:0", "A"): [1.0], ("m:1:2:0", "A"): [2.0]}
    assert state.mountings == 3 and state.resumes == 1


def test_a_redo_drops_that_setups_earlier_cycles_only() -> None:
    again = {**_cycle(1, 1), "deviations": {"+xy": 0.9}}
    records = [*_records(), {"type": "setup-redo", "phase": "m", "setup": 1},
               _setup(1, {"A": "x"}), again]
    state = RunState.of(_typed(records))
    assert sorted(state.cycles) == [("m", 0, 1), ("m", 1, 1)]  # setup 1: its new cycle
    assert state.cycles[("m", 1, 1)].deviations == {"+xy": 0.9} and not state.repeats
    assert ("m", 0) in state.setups_done  # setup 0 untouched
    kept = RunState.of(_typed(_records()))
    assert sorted(kept.cycles) == [("m", 0, 1), ("m", 1, 1), ("m", 1, 2)]
    assert list(kept.repeats) == [("m", 1, 1)]
    assert state.header is not None and state.header.started == "now"
