"""How ModbusAxisController waits for a move: no redundant reads, faster polls
only around the expected arrival, alarms still noticed mid-move."""

from __future__ import annotations

import numpy as np
import pytest

import orthocal
from drivers.axes import ModbusAxisController
from drivers.device_errors import AlarmError
from drivers.sim.controller import SimController
from drivers.sim.machine import VirtualOrthoglide

GEOMETRY = orthocal.Geometry()
PI0 = orthocal.posture("0", None, GEOMETRY)


def _pair(speed: float = 400.0) -> tuple[SimController, ModbusAxisController]:
    machine = VirtualOrthoglide(GEOMETRY, speed_mm_s=speed, accel_mm_s2=20000.0)
    sim = SimController(machine).start()
    ctl = ModbusAxisController(port=sim.port, timeout_s=0.5, acceleration_mm_s2=20000.0)
    return sim, ctl.connect()


def test_known_start_saves_the_position_read() -> None:
    sim, ctl = _pair()
    reads: list[int] = []
    read_positions = ctl.read_positions

    def counting() -> np.ndarray:
        reads.append(1)
        return read_positions()

    ctl.read_positions = counting  # type: ignore[method-assign]
    try:
        target = PI0 + np.array([5.0, -3.0, 2.0])
        ctl.move_and_wait(target, speed_mm_s=400.0)
        assert len(reads) == 2  # where it starts, where it arrived
        reads.clear()
        actual = ctl.move_and_wait(PI0, speed_mm_s=400.0, start=target)
        assert len(reads) == 1  # only where it arrived
        assert np.allclose(actual, PI0, atol=0.002)
    finally:
        ctl.close()
        sim.close()


def test_slow_polls_until_the_expected_arrival() -> None:
    sim, ctl = _pair(speed=200.0)
    try:
        ctl.poll_interval_s = 0.02
        target = PI0 + np.array([20.0, 0.0, 0.0])  # ~0.1 s
        before = sim.stats.requests
        ctl.move_and_wait(target, speed_mm_s=200.0, start=PI0)
        # Fast polls would have been ~100 requests; slow ones until the arrival few.
        assert sim.stats.requests - before < 40
    finally:
        ctl.close()
        sim.close()


def test_an_alarm_mid_move_is_still_reported() -> None:
    sim, ctl = _pair(speed=100.0)
    try:
        sim.faults.alarm_after_moves = 0
        with pytest.raises(AlarmError):
            ctl.move_and_wait(PI0 + np.array([30.0, 0.0, 0.0]), speed_mm_s=100.0, start=PI0)
    finally:
        ctl.close()
        sim.close()
