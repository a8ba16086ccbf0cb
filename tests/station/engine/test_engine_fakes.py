"""The engine's logic against in-process fakes at the Protocol level (tests/helpers/fakes.py):
a whole run, an alarm and the resume, a write-back that does not read back, each
in well under a second and with no server, pty or thread of a device. The same
behaviours end to end over the wire-level simulators are in test_closed_loop_run,
test_interrupt and test_reliability; these pin down the engine's part alone."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from close import assert_same
from fakes import (
    COUNT_MM,
    FakeAxes,
    FakeGauge,
    FakeRig,
    SteppedClock,
    fake_config,
    resume_on,
    run_on,
)

from drivers.base import AxisController, Indicator, Motion, ZeroOffsets
from drivers.sim.machine import VirtualOrthoglide
from station.errors import RunFailed
from station.record.journal_file import read_journal

TRUE = (0.4, -0.3, 0.2)
# noise 0: every reading is a function of the machine's pose alone, so a resumed run
# reads what the uninterrupted one read
PROCEDURE = {"cycles": 2, "readings": 2, "settle_s": 0.0, "max_extra_passes": 0,
             "model": "rho"}


def journal_of(run_dir: Path) -> list[dict]:
    return read_journal(run_dir / "journal.jsonl")


def records_of_writes(run_dir: Path) -> list[dict]:
    return [r for r in journal_of(run_dir) if r["type"] == "writeback"]


def test_the_fakes_are_the_protocols_and_the_protocol_is_split() -> None:
    axes = FakeAxes(VirtualOrthoglide(), SteppedClock())
    assert isinstance(axes, Motion) and isinstance(axes, ZeroOffsets)
    assert isinstance(axes, AxisController)
    assert isinstance(FakeGauge("A", 0.0, 1), Indicator)
    # the motion a mover needs and the offsets write-back needs are apart: neither
    # protocol names the other's methods
    motion = {m for m in dir(Motion) if not m.startswith("_")}
    offsets = {m for m in dir(ZeroOffsets) if not m.startswith("_")}
    assert not motion & offsets
    assert {"read_offsets", "write_offsets", "offset_resolution_mm"} <= offsets
    assert {"move_and_wait", "read_positions", "stop"} <= motion


def test_a_fake_gauge_with_a_scale_error_shows_that_much_more_of_its_travel() -> None:
    # as the wire-level gauge's scale_error: (1 + S) times the travel from its zero,
    # the stroke's ends in true mm, quantised to the digit after
    where = {"mm": 2.0}
    gauge = FakeGauge("A", 0.0, 1, scale=0.004)
    gauge.mount(lambda: where["mm"])
    for travel, shown in ((0.25, 0.251), (-0.5, -0.502), (0.0, 0.0), (9.0, 6.275)):
        where["mm"] = 2.0 + travel
        assert gauge.read() == pytest.approx(shown, abs=1e-9)
    where["mm"] = 2.0
    true = FakeGauge("B", 0.0, 1)
    true.mount(lambda: where["mm"])
    where["mm"] = 2.25
    assert true.read() == pytest.approx(0.25, abs=1e-9)


def test_a_run_finds_the_hidden_offsets_writes_them_and_verifies(tmp_path: Path) -> None:
    rig = FakeRig(true_drho=TRUE)
    code, result = run_on(rig, tmp_path / "runs", fake_config(**PROCEDURE))
    assert code == 0 and result["status"] == "ok", result.get("message")
    for a, true in zip("xyz", TRUE, strict=True):
        assert abs(result["identified"][f"drho_{a}"] - true) < 0.002
    # o = −Δρ, in the drive's counts, written once, then verified as converged
    np.testing.assert_allclose(rig.machine.offsets, -np.array(TRUE), atol=2 * COUNT_MM)
    assert rig.axes.offset_writes == [[it["offsets_written"][a] for a in "xyz"]
                                      for it in result["iterations"]
                                      if it["offsets_written"] is not None]
    assert result["loop"]["stopped"] == "converged" and result["converged"] is True
    records = journal_of(Path(result["run_dir"]))
    stages = [r["stage"] for r in records if r["type"] == "writeback"]
    assert stages[:3] == ["backup", "intent", "done"]
    cycles = [(r["phase"], r["setup"], r["cycle"]) for r in records if r["type"] == "cycle"]
    assert len(cycles) == len(set(cycles)) == 3 * 2 * len(result["iterations"])
    # every stop a cycle used is on disk as reading records, each gauge's readings
    stops = {r["stop"] for r in records if r["type"] == "reading"}
    for p, s, k in cycles:
        assert {f"{p}:{s}:{k}:+", f"{p}:{s}:{k}:-", f"{p}:{s}:{k}:0"} <= stops
    assert all(len(r["values"]) == PROCEDURE["readings"]
               for r in records if r["type"] == "reading")


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, int]:
    """The run left alone: its result, and how many moves came before its first
    write-back."""
    left_alone = FakeRig(true_drho=TRUE)
    _, whole = run_on(left_alone, tmp_path_factory.mktemp("whole"), fake_config(**PROCEDURE))
    return whole, left_alone.axes.moves_at_writes[0]


@pytest.mark.parametrize("when", ["measuring", "verifying"])
def test_an_alarm_stops_the_run_and_the_resume_gives_the_uninterrupted_result(
        tmp_path: Path, when: str, uninterrupted: tuple[dict, int]) -> None:
    config = fake_config(**PROCEDURE)
    whole, moves_before_write = uninterrupted
    # the 7th move, or the 5th after the first write-back
    alarm_on_move = 7 if when == "measuring" else moves_before_write + 5

    rig = FakeRig(true_drho=TRUE)
    rig.axes.alarm_on_move = alarm_on_move
    with pytest.raises(RunFailed, match="alarm"):
        run_on(rig, tmp_path / "cut", config)
    (run_dir,) = (tmp_path / "cut").glob("run-*")
    before = (run_dir / "journal.jsonl").read_bytes()
    assert journal_of(run_dir)[-1]["type"] == "fault"
    written_before = [r for r in records_of_writes(run_dir) if r["stage"] == "done"]
    assert len(written_before) == (when == "verifying")  # cut after the write, or before
    moves_before = rig.axes.moves
    rig.axes.reset_alarm()  # the operator clears the drive's alarm
    code, result = resume_on(rig, run_dir, config)
    assert code == 0 and result["status"] == "ok", result.get("message")
    assert rig.axes.moves > moves_before
    done = [r for r in records_of_writes(run_dir) if r["stage"] == "done"]
    assert len(done) == len(rig.axes.offset_writes)  # each write journaled once
    # nothing rewritten, nothing measured twice, the correction applied once
    assert (run_dir / "journal.jsonl").read_bytes().startswith(before)
    records = journal_of(run_dir)
    cycles = [(r["phase"], r["setup"], r["cycle"]) for r in records if r["type"] == "cycle"]
    assert len(cycles) == len(set(cycles))
    assert [r["type"] for r in records].count("resumed") == 1
    if when == "measuring":
        assert_same(result["identified"], whole["identified"], "identified")
        assert result["offsets_written"] == whole["offsets_written"]
        assert result["loop"] == whole["loop"]
        np.testing.assert_allclose(rig.machine.offsets,
                                   [whole["offsets_written"][a] for a in "xyz"], atol=1e-12)
        return
    # Cut in the verification's first setup, whose gauges the run left alone kept on
    # from the measurement (station.engine.kept): after a fault the resume mounts them
    # afresh, at the leg's middle of the corrected pose, where the kept ones touch the
    # leg where the write-back moved it. So the two verifications are two mountings:
    # noise-free, their Δρ̂ differ by what the contact point's shift makes (about
    # 1 µm here), never by a reading lost or counted twice.
    for n, v in whole["identified"].items():
        assert abs(result["identified"][n] - v) < 0.002, n
    assert result["loop"]["stopped"] == whole["loop"]["stopped"]


def test_offsets_that_do_not_read_back_are_restored_from_the_backup(tmp_path: Path) -> None:
    rig = FakeRig(true_drho=TRUE)
    rig.axes.bad_readbacks = 1  # the write's read-back is off; the restore's is not
    code, result = run_on(rig, tmp_path / "runs", fake_config(**PROCEDURE))
    assert code == 1 and result["status"] == "failed"
    assert result["writeback"]["status"] == "failed-restored"
    assert "read back" in result["writeback"]["reason"]
    assert result["offsets_written"] is None and result["verification"] is None
    np.testing.assert_allclose(rig.machine.offsets, [0.0, 0.0, 0.0], atol=1e-12)
    run_dir = Path(result["run_dir"])
    stages = [r["stage"] for r in journal_of(run_dir) if r["type"] == "writeback"]
    assert stages == ["backup", "intent", "failed-restored"]
    backup = json.loads((run_dir / "offsets_backup.json").read_text())
    assert backup["controller"] == "fake axes"
    assert backup["offsets_mm"] == {"x": 0.0, "y": 0.0, "z": 0.0}


def test_a_calibrated_machine_is_measured_and_left_alone(tmp_path: Path) -> None:
    rig = FakeRig(true_drho=TRUE)
    rig.machine.set_offsets([-v for v in TRUE])  # already corrected
    code, result = run_on(rig, tmp_path / "runs", fake_config(**PROCEDURE))
    assert code == 0 and result["status"] == "ok", result.get("message")
    assert rig.axes.offset_writes == [] and result["loop"]["write_backs"] == 0
    assert all(abs(result["identified"][f"drho_{a}"]) < 0.002 for a in "xyz")
