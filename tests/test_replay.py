"""station.engine.replay: one index of the journal's step records, which the
sequencer (cycles, setups) and write-back (stages) both resume from."""

from __future__ import annotations

from station.engine.recovery import drop_redone
from station.engine.replay import Replay


def _cycle(phase: str, setup: int, cycle: int) -> dict:
    return {"type": "cycle", "phase": phase, "setup": setup, "cycle": cycle,
            "deviations": {"+xy": 0.1 * cycle}}


def test_each_step_is_found_by_its_identity() -> None:
    records = [
        {"type": "header"},
        _cycle("m", 0, 1), _cycle("m", 0, 2),
        {"type": "setup_done", "phase": "m", "setup": 0},
        _cycle("m", 1, 1),
        {"type": "writeback", "stage": "backup", "before": {}},  # before rounds: round 1
        {"type": "writeback", "round": 2, "stage": "intent", "written": {}},
    ]
    replay = Replay.of(records)
    assert replay.cycle("m", 0, 2) is records[2]
    assert replay.cycle("m", 1, 2) is None and replay.cycle("v", 0, 1) is None
    assert replay.setup_done("m", 0) and not replay.setup_done("m", 1)
    assert set(replay.stages(1)) == {"backup"} and set(replay.stages(2)) == {"intent"}
    assert replay.stages(3) == {}


def test_a_setup_redone_is_measured_again_from_its_first_cycle() -> None:
    records = [_cycle("m", 0, 1), _cycle("m", 0, 2),
               {"type": "setup_done", "phase": "m", "setup": 0},
               _cycle("m", 1, 1),
               {"type": "setup-redo", "phase": "m", "setup": 0},
               _cycle("m", 0, 1)]
    replay = Replay.of(drop_redone(records))
    assert replay.cycle("m", 0, 1) is records[-1]  # the redo's own first cycle
    assert replay.cycle("m", 0, 2) is None and not replay.setup_done("m", 0)
    assert replay.cycle("m", 1, 1) is records[3]  # another setup is untouched


def test_an_empty_journal_replays_nothing() -> None:
    replay = Replay.of([])
    assert replay.cycle("m", 0, 1) is None and not replay.setup_done("m", 0)
    assert replay.stages(1) == {}
