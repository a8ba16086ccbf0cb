"""station.engine.recovery on journal records alone: which setup a power cut interrupted,
and how a setup-redo voids that setup's earlier cycles (and only those)."""

from __future__ import annotations

from station.engine.recovery import drop_redone, interrupted_setup
from station.rundir.journal import replay


def _records() -> list[dict]:
    return [
        {"type": "header"},
        {"type": "setup", "phase": "m", "setup": 0, "indicators": {"A": "y", "B": "z"}},
        {"type": "cycle", "phase": "m", "setup": 0, "cycle": 1},
        {"type": "setup_done", "phase": "m", "setup": 0},
        {"type": "setup", "phase": "m", "setup": 1, "indicators": {"A": "x", "B": "z"}},
        {"type": "cycle", "phase": "m", "setup": 1, "cycle": 1},
        {"type": "repeat", "phase": "m", "setup": 1},
        {"type": "cycle", "phase": "m", "setup": 1, "cycle": 2},
    ]


def test_the_interrupted_setup_is_the_last_mounted_and_unfinished() -> None:
    records = _records()
    assert interrupted_setup(records) == ("m", 1, {"A": "x", "B": "z"})
    done = [*records, {"type": "setup_done", "phase": "m", "setup": 1}]
    assert interrupted_setup(done) is None


def test_a_redo_drops_that_setups_earlier_cycles_only() -> None:
    records = [*_records(), {"type": "setup-redo", "phase": "m", "setup": 1},
               {"type": "setup", "phase": "m", "setup": 1, "indicators": {"A": "x"}},
               {"type": "cycle", "phase": "m", "setup": 1, "cycle": 1}]
    kept = drop_redone(records)
    cycles = [(r["setup"], r["cycle"]) for r in kept if r["type"] == "cycle"]
    assert cycles == [(0, 1), (1, 1)]  # setup 0 kept; setup 1 only its new cycle
    assert kept[-1] is records[-1] and not [r for r in kept if r["type"] == "repeat"]
    assert drop_redone(_records()) == _records()
    assert replay(kept).header == {"type": "header"}
