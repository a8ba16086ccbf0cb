"""Offsets held by the station (drivers.held_offsets; docs/design.md "Offsets held by
the station"): a drive without a writable zero offset is commanded ρ + o, its
positions and soft limits reported less o, exactly as a drive holding o would;
and the journal says what the station holds after write-backs and rollbacks."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest

from drivers.held_offsets import HELD_BY_STATION, HeldOffsets
from drivers.soft_limits import SoftLimits
from station.record.journal import RECORD
from station.record.state import RunState

TOL = 1e-12  # plain float sums of a few mm: far below a count


class Drive:
    """A drive in its own coordinates: it goes where it is told (0.001 mm counts)
    and knows its soft limits; it has no offset registers."""

    def __init__(self) -> None:
        self.at = np.zeros(3)
        self.commands: list[np.ndarray] = []

    def move(self, targets: Sequence[float], speed_mm_s: float | None = None) -> None:
        self.commands.append(np.asarray(targets, dtype=float))
        self.at = np.round(np.asarray(targets, dtype=float) * 1000) / 1000

    def move_and_wait(self, targets, speed_mm_s=None, timeout_s=None, start=None, watch=None):
        self.move(targets)
        return self.at.copy()

    def wait_in_position(self, targets, timeout_s, tolerance_mm=0.002, expected_s=None,
                         watch=None):
        assert np.all(np.abs(self.at - np.asarray(targets)) <= tolerance_mm)
        return self.at.copy()

    def read_positions(self) -> np.ndarray:
        return self.at.copy()

    def soft_limits(self) -> SoftLimits:
        return SoftLimits(np.array([-10.0, -20.0, -30.0]), np.array([10.0, 20.0, 30.0]))

    def offset_resolution_mm(self) -> float:
        return 0.001

    def target_resolution_mm(self) -> np.ndarray:
        return np.full(3, 0.001)

    def stop(self) -> str:
        return "stopped"


def test_the_carriage_goes_where_a_drive_holding_o_would_put_it() -> None:
    drive = Drive()
    held = HeldOffsets(drive, [0.5, -0.25, 0.125])
    assert held.held_by == HELD_BY_STATION
    arrived = held.move_and_wait([1.0, 2.0, 3.0])
    # "commanded ρ puts the carriage at ρ + o": the drive is told ρ + o ...
    np.testing.assert_allclose(drive.commands[-1], [1.5, 1.75, 3.125], atol=TOL)
    # ... and the station sees ρ, as from a drive that holds o.
    np.testing.assert_allclose(arrived, [1.0, 2.0, 3.0], atol=TOL)
    np.testing.assert_allclose(held.read_positions(), [1.0, 2.0, 3.0], atol=TOL)
    np.testing.assert_allclose(held.wait_in_position([1.0, 2.0, 3.0], 1.0),
                               [1.0, 2.0, 3.0], atol=TOL)


def test_soft_limits_are_the_drives_less_o() -> None:
    held = HeldOffsets(Drive(), [0.5, -0.25, 0.0])
    lo, hi = held.soft_limits()
    np.testing.assert_allclose(lo, [-10.5, -19.75, -30.0], atol=TOL)
    np.testing.assert_allclose(hi, [9.5, 20.25, 30.0], atol=TOL)


def test_written_offsets_are_held_at_the_drives_count_and_move_the_carriage() -> None:
    drive = Drive()
    held = HeldOffsets(drive)
    np.testing.assert_allclose(held.read_offsets(), 0.0, atol=TOL)
    back = held.write_offsets([0.01234, -0.0006, 0.2])
    np.testing.assert_allclose(back, [0.012, -0.001, 0.2], atol=TOL)  # rounded to counts
    np.testing.assert_allclose(held.read_offsets(), back, atol=TOL)
    held.move([0.0, 0.0, 0.0])
    np.testing.assert_allclose(drive.commands[-1], back, atol=TOL)
    assert held.stop() == "stopped"  # everything else is the drive's
    with pytest.raises(ValueError, match="offsets"):
        held.write_offsets([0.0, float("nan"), 0.0])


def _wb(stage: str, **fields: dict[str, float]) -> dict:
    return {"type": "writeback", "stage": stage, **fields}


def held_after(records: list[dict], start: list[float] | None) -> list[float] | None:
    """What the run state of ``records`` says the station holds (station.record.state)."""
    state = RunState.of(RECORD.validate_python({"t": 0.0, **r}) for r in records)
    return state.held_offsets(start)


def test_the_journal_says_what_the_station_holds() -> None:
    before = {"x": 0.1, "y": 0.2, "z": 0.3}
    first = {"x": 0.11, "y": 0.19, "z": 0.31}
    second = {"x": 0.12, "y": 0.18, "z": 0.32}
    assert held_after([], None) is None
    assert held_after([], [0.1, 0.2, 0.3]) == [0.1, 0.2, 0.3]
    records = [_wb("intent", before=before, written=first),
               _wb("done", before=before, written=first)]
    assert held_after(records, [0.1, 0.2, 0.3]) == [0.11, 0.19, 0.31]
    records += [_wb("done", before=first, written=second)]
    assert held_after(records, None) == [0.12, 0.18, 0.32]
    # a write-back cut and restored, or a rollback, leaves the backed-up offsets
    assert held_after([*records, _wb("interrupted-restored", before=first)], None) == \
        [0.11, 0.19, 0.31]
    rollback = {"type": "rollback", "stage": "done", "restored": before}
    assert held_after([*records, rollback], None) == [0.1, 0.2, 0.3]
