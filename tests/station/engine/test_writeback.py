"""Write-back against the simulated controller (real Modbus server, real driver):
backup first, refusal beyond the limit, a failed write or read-back restores the
backup, rollback, and a resumed write-back never applies Δρ twice."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from drivers.axes import ModbusAxisController
from drivers.device_errors import ReadbackMismatch
from drivers.sim.specs import GaugeSpec
from drivers.sim.station import VirtualStation
from station.engine.writeback import BACKUP_NAME, rollback, write_back
from station.record.journal_file import Journal, read_journal

START = (0.25, -0.5, 1.0)


class Operator:
    def __init__(self, answer: bool = True) -> None:
        self.answer = answer
        self.asked: list[str] = []

    def mount(self, *args: object) -> None:
        raise AssertionError("write-back never asks for a mounting")

    def confirm(self, question: str) -> bool:
        self.asked.append(question)
        return self.answer


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[tuple[VirtualStation, ModbusAxisController, Journal]]:
    station = VirtualStation(gauges=GaugeSpec(noise_mm=0.0), seed=1)
    controller = ModbusAxisController(port=station.controller.port, timeout_s=1.0).connect()
    journal = Journal(tmp_path / "journal.jsonl")
    try:
        controller.write_offsets(START)
        yield station, controller, journal
    finally:
        journal.close()
        controller.close()
        station.close()


def test_writes_corrected_offsets_after_a_backup(tmp_path: Path, rig) -> None:
    station, controller, journal = rig
    op = Operator()
    out = write_back(controller=controller, identified={"drho_x": 0.1, "drho_y": -0.2,
                                                        "drho_z": 0.05},
                     max_abs_offset_mm=3.0, run_dir=tmp_path, journal=journal, operator=op)
    assert out.status == "written" and len(op.asked) == 1
    np.testing.assert_allclose(station.offsets, [0.15, -0.3, 0.95], atol=1e-9)
    backup = json.loads((tmp_path / BACKUP_NAME).read_text())["offsets_mm"]
    assert backup == dict(zip("xyz", START, strict=True))
    stages = [r["stage"] for r in read_journal(tmp_path / "journal.jsonl")]
    assert stages == ["backup", "intent", "done"]


def test_refuses_beyond_the_limit_and_writes_nothing(tmp_path: Path, rig) -> None:
    station, controller, journal = rig
    op = Operator()
    out = write_back(controller=controller, identified={"drho_x": 0.1, "drho_y": -3.5,
                                                        "drho_z": 0.0},
                     max_abs_offset_mm=3.0, run_dir=tmp_path, journal=journal, operator=op)
    assert out.status == "refused" and "Δρ_y = -3.5000" in out.reason
    assert op.asked == []  # refused before asking anyone
    np.testing.assert_allclose(station.offsets, START, atol=1e-9)
    assert (tmp_path / BACKUP_NAME).is_file()


def test_declined_writes_nothing(tmp_path: Path, rig) -> None:
    station, controller, journal = rig
    out = write_back(controller=controller, identified={"drho_x": 0.1, "drho_y": 0.1,
                                                        "drho_z": 0.1},
                     max_abs_offset_mm=3.0, run_dir=tmp_path, journal=journal,
                     operator=Operator(answer=False))
    assert out.status == "declined"
    np.testing.assert_allclose(station.offsets, START, atol=1e-9)


def test_write_refused_by_the_controller_restores_the_backup(tmp_path: Path, rig) -> None:
    station, controller, journal = rig
    station.controller.max_offset_mm = 1.2  # the drive refuses |o| > 1.2 (exception 3)
    out = write_back(controller=controller, identified={"drho_x": 0.0, "drho_y": 0.0,
                                                        "drho_z": -0.5},
                     max_abs_offset_mm=3.0, run_dir=tmp_path, journal=journal,
                     operator=Operator())
    assert out.status == "failed-restored" and "restored" in out.reason
    np.testing.assert_allclose(station.offsets, START, atol=1e-9)


class MismatchOnce:
    """The real controller, except that the first write's read-back disagrees: the
    simulator stores exactly what it is sent, so a corrupted read-back (a flaky
    drive) cannot be produced otherwise. The write itself does reach the drive."""

    def __init__(self, real: ModbusAxisController) -> None:
        self.real = real
        self.name, self.held_by = real.name, real.held_by
        self.failed = False

    def read_offsets(self) -> np.ndarray:
        return self.real.read_offsets()

    def write_offsets(self, offsets) -> np.ndarray:
        got = self.real.write_offsets(offsets)
        if not self.failed:
            self.failed = True
            raise ReadbackMismatch(self.real.device, f"read back {got[0] + 0.01} for {got[0]}")
        return got


def test_readback_mismatch_restores_the_backup(tmp_path: Path, rig) -> None:
    station, controller, journal = rig
    out = write_back(controller=MismatchOnce(controller),
                     identified={"drho_x": 0.3, "drho_y": 0.3, "drho_z": 0.3},
                     max_abs_offset_mm=3.0, run_dir=tmp_path, journal=journal,
                     operator=Operator())
    assert out.status == "failed-restored"
    np.testing.assert_allclose(station.offsets, START, atol=1e-9)
    assert [r["stage"] for r in read_journal(tmp_path / "journal.jsonl")][-1] == \
        "failed-restored"


def test_resumed_write_back_does_not_apply_twice(tmp_path: Path, rig) -> None:
    station, controller, journal = rig
    identified = {"drho_x": 0.2, "drho_y": 0.2, "drho_z": 0.2}
    write_back(controller=controller, identified=identified, max_abs_offset_mm=3.0,
               run_dir=tmp_path, journal=journal, operator=Operator())
    # killed after the write, before "done" was journaled: drop that record
    path = tmp_path / "journal.jsonl"
    path.write_text("".join(path.read_text().splitlines(keepends=True)[:-1]))
    op = Operator()
    with Journal(path) as resumed:  # the resumed run's: what the file says, folded
        out = write_back(controller=controller, identified=identified,
                         max_abs_offset_mm=3.0, run_dir=tmp_path, journal=resumed,
                         operator=op)
    assert out.status == "written" and op.asked == []  # the intent was already confirmed
    np.testing.assert_allclose(station.offsets, np.array(START) - 0.2, atol=1e-9)


def test_rollback_restores_the_backup(tmp_path: Path, rig) -> None:
    station, controller, journal = rig
    write_back(controller=controller, identified={"drho_x": 1.0, "drho_y": 1.0,
                                                  "drho_z": 1.0},
               max_abs_offset_mm=3.0, run_dir=tmp_path, journal=journal, operator=Operator())
    assert not np.allclose(station.offsets, START)
    restored = rollback(controller, tmp_path, journal)
    np.testing.assert_allclose(station.offsets, START, atol=1e-9)
    assert restored == dict(zip("xyz", START, strict=True))


def test_ctrl_c_between_offset_writes_restores_the_backup(tmp_path: Path, rig) -> None:
    """Ctrl-C cannot be timed between two register writes from outside, so the
    driver's write is wrapped: it really writes OFFSET_X alone (as a map with
    scattered offset registers would, one request each), then the interrupt
    arrives. The controller must end with the backup, whole, and resume must
    then write the whole correction."""
    station, controller, journal = rig
    real_write = controller.write_offsets
    interrupted = {"done": False}

    def write_x_then_interrupt(offsets):
        if not interrupted["done"]:
            interrupted["done"] = True
            real_write([offsets[0], START[1], START[2]])  # the first register lands
            raise KeyboardInterrupt
        return real_write(offsets)

    controller.write_offsets = write_x_then_interrupt  # type: ignore[method-assign]
    identified = {"drho_x": 0.1, "drho_y": -0.2, "drho_z": 0.05}
    with pytest.raises(KeyboardInterrupt):
        write_back(controller=controller, identified=identified, max_abs_offset_mm=3.0,
                   run_dir=tmp_path, journal=journal, operator=Operator())
    np.testing.assert_allclose(station.offsets, START, atol=1e-9)  # not half-corrected
    records = read_journal(tmp_path / "journal.jsonl")
    assert [r["stage"] for r in records] == ["backup", "intent", "interrupted-restored"]

    with Journal(tmp_path / "journal.jsonl") as resumed:
        out = write_back(controller=controller, identified=identified,
                         max_abs_offset_mm=3.0, run_dir=tmp_path, journal=resumed,
                         operator=Operator())
    assert out.status == "written"
    np.testing.assert_allclose(station.offsets, [0.15, -0.3, 0.95], atol=1e-9)


def test_a_second_round_keeps_the_first_backup_and_checks_the_total(tmp_path: Path,
                                                                     rig) -> None:
    station, controller, journal = rig
    start = dict(zip("xyz", START, strict=True))
    first = write_back(controller=controller, identified={"drho_x": 2.0, "drho_y": 0.0,
                                                          "drho_z": 0.0},
                       max_abs_offset_mm=2.5, run_dir=tmp_path, journal=journal,
                       operator=Operator())
    assert first.status == "written" and first.before == start
    # Round 2: 0.4 mm alone is fine, but 2.4 + 0.4 since the run started is not.
    op = Operator()
    refused = write_back(controller=controller, identified={"drho_x": 0.6, "drho_y": 0.0,
                                                            "drho_z": 0.0},
                         max_abs_offset_mm=2.5, run_dir=tmp_path, journal=journal,
                         operator=op, round=2, offsets_at_start=first.before)
    assert refused.status == "refused" and "total" in (refused.reason or "")
    assert op.asked == []  # nothing to confirm: refused before asking
    np.testing.assert_allclose(station.offsets, [START[0] - 2.0, START[1], START[2]],
                               atol=1e-9)
    second = write_back(controller=controller, identified={"drho_x": 0.03, "drho_y": 0.0,
                                                           "drho_z": 0.0},
                        max_abs_offset_mm=2.5, run_dir=tmp_path, journal=journal,
                        operator=op, round=3, offsets_at_start=first.before)
    assert second.status == "written" and "round 3" in op.asked[0]
    np.testing.assert_allclose(station.offsets, [START[0] - 2.03, START[1], START[2]],
                               atol=1e-9)
    # The backup file still holds the offsets from before the first round ...
    assert json.loads((tmp_path / BACKUP_NAME).read_text())["offsets_mm"] == start
    state = journal.state
    assert sorted(state.writebacks) == [1, 2, 3] and "done" in state.writebacks[3]
    # ... so rollback undoes every round at once.
    rollback(controller, tmp_path, journal)
    np.testing.assert_allclose(station.offsets, START, atol=1e-9)


def test_a_resumed_round_two_writes_its_journaled_intent_once(tmp_path: Path, rig) -> None:
    station, controller, journal = rig
    ident = {"drho_x": 0.1, "drho_y": 0.0, "drho_z": 0.0}
    write_back(controller=controller, identified=ident, max_abs_offset_mm=3.0,
               run_dir=tmp_path, journal=journal, operator=Operator())
    before2 = dict(zip("xyz", controller.read_offsets(), strict=True))
    new2 = {**before2, "x": before2["x"] - 0.02}
    # Killed in round 2 after the write reached the drive, before "done" was journaled.
    journal.append({"type": "writeback", "round": 2, "stage": "backup", "before": before2})
    journal.append({"type": "writeback", "round": 2, "stage": "intent", "before": before2,
                    "written": new2})
    controller.write_offsets([new2[a] for a in "xyz"])
    with Journal(tmp_path / "journal.jsonl") as resumed:
        again = write_back(controller=controller, identified={**ident, "drho_x": 0.02},
                           max_abs_offset_mm=3.0, run_dir=tmp_path, journal=resumed,
                           operator=Operator(), round=2)
        assert again.status == "written"
        np.testing.assert_allclose(station.offsets, [new2[a] for a in "xyz"], atol=1e-9)
        # round 1, replayed, is not redone either
        done = write_back(controller=controller, identified=ident, max_abs_offset_mm=3.0,
                          run_dir=tmp_path, journal=resumed, operator=Operator(), round=1)
    assert done.status == "written"
    np.testing.assert_allclose(station.offsets, [new2[a] for a in "xyz"], atol=1e-9)
