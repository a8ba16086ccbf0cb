"""Power loss, the driver side of a lost controller: a real pymodbus server on
loopback that loses power (connections reset, new ones refused for a while, then
back unhomed with its count restarted) or only its network.

The driver reconnects on its own within ``reconnect_s`` and reports every
attempt; what a drive that lost its reference says is never returned as a
position (ControllerNotHomed) until it has been homed again.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

import orthocal
from drivers.axes import ModbusAxisController
from drivers.device_errors import ControllerConnectionError, ControllerNotHomed, ControllerTimeout
from drivers.sim.controller import SimController
from drivers.sim.machine import VirtualOrthoglide

GEOMETRY = orthocal.Geometry()
PI0 = orthocal.posture("0", None, GEOMETRY)


def _rig(**kw: float) -> tuple[SimController, ModbusAxisController, list[dict]]:
    sim = SimController(VirtualOrthoglide(GEOMETRY, speed_mm_s=400.0, accel_mm_s2=20000.0))
    sim.start()
    events: list[dict] = []
    ctl = ModbusAxisController(port=sim.port, timeout_s=0.25, retries=2,
                               acceleration_mm_s2=20000.0, on_event=events.append, **kw)
    ctl.connect()
    # The server has taken the connection (a cut before that would leave it unserved).
    ctl.read_status()
    return sim, ctl, events


def _wait_cut(sim: SimController) -> None:
    deadline = time.monotonic() + 5.0
    while sim.powered and time.monotonic() < deadline:
        time.sleep(0.005)
    assert not sim.powered


def test_power_cut_reconnects_then_refuses_positions_until_homed() -> None:
    sim, ctl, events = _rig(reconnect_s=5.0)
    try:
        assert np.allclose(ctl.read_positions(), PI0, atol=1e-3)
        sim.power_cut(0.6, count_mm=0.0)
        _wait_cut(sim)
        t0 = time.monotonic()
        with pytest.raises(ControllerNotHomed, match="must be homed"):
            ctl.read_positions()
        # It waited for the drive to come back rather than failing at once.
        assert time.monotonic() - t0 >= 0.4
        kinds = [e["event"] for e in events]
        assert "reconnect" in kinds and kinds.count("reconnected") == 1
        assert events[-1] == {"event": "reference-check", "device": ctl.device, "lost": True,
                              "why": "HOMED clear after the connection came back (power cut?)"}
        assert ctl.reconnects == 1
        # The drive itself lost the count: what the driver refused to return.
        assert np.allclose(sim.machine.actual(), 0.0, atol=1e-6)
        assert not ctl.read_status().homed  # status stays readable for homing
        with pytest.raises(ControllerNotHomed):
            ctl.move([300.0, 300.0, 300.0], speed_mm_s=100.0)
        ctl.home(timeout_s=5.0)
        assert np.allclose(ctl.read_positions(), PI0, atol=1e-3)
        ctl.move_and_wait(PI0 + 5.0, speed_mm_s=400.0)
    finally:
        ctl.close()
        sim.close()


def test_network_outage_mid_move_reconnects_and_goes_on() -> None:
    sim, ctl, events = _rig(reconnect_s=5.0)
    try:
        target = PI0 + np.array([20.0, -10.0, 5.0])
        ctl.move(target, speed_mm_s=50.0)
        sim.power_cut(0.3, lose_reference=False)
        _wait_cut(sim)
        got = ctl.wait_in_position(target, timeout_s=5.0)
        assert np.allclose(got, target, atol=2e-3)
        checks = [e for e in events if e["event"] == "reference-check"]
        assert checks == [{"event": "reference-check", "device": ctl.device, "lost": False,
                           "why": None}]
    finally:
        ctl.close()
        sim.close()


def test_power_lost_between_the_targets_and_the_command_writes_the_targets_again() -> None:
    # A drive that lost power forgets the targets just written: the move command the
    # driver retries after reconnecting would move to its power-up targets (where the
    # axes stand), and the wait would time out at the start point.
    sim, ctl, events = _rig(reconnect_s=5.0)
    send = ctl.send_command
    cuts: list[str] = []

    def cut_before(command: str) -> None:
        if command == "move" and not cuts:
            cuts.append(command)
            sim.power_cut(0.3, lose_reference=False)
            _wait_cut(sim)
        send(command)

    ctl.send_command = cut_before  # type: ignore[method-assign]
    try:
        target = PI0 + np.array([20.0, -10.0, 5.0])
        got = ctl.move_and_wait(target, speed_mm_s=400.0, timeout_s=3.0)
        assert np.allclose(got, target, atol=2e-3)
        assert cuts == ["move"] and ctl.reconnects == 1
        assert [e["event"] for e in events].count("reconnected") == 1
    finally:
        ctl.close()
        sim.close()


def test_reset_while_waiting_for_a_reply_is_a_connection_fault() -> None:
    # The reply is late; the power goes while the client waits in recv, where
    # pymodbus lets ConnectionResetError through.
    sim, ctl, events = _rig(reconnect_s=0.3)
    try:
        sim.faults.delay_s = 0.2
        sim.power_cut(5.0, delay_s=0.05)
        with pytest.raises(ControllerConnectionError, match=r"not back within 0\.3 s"):
            ctl.read_positions()
        assert events[0]["event"] == "retry"
        assert "connection lost" in events[0]["error"]
    finally:
        ctl.close()
        sim.close()


def test_a_controller_that_stays_away_fails_within_the_budget() -> None:
    sim, ctl, events = _rig(reconnect_s=0.5)
    try:
        sim.power_cut(30.0)
        _wait_cut(sim)
        t0 = time.monotonic()
        with pytest.raises(ControllerConnectionError, match=r"not back within 0\.5 s") as info:
            ctl.read_positions()
        assert time.monotonic() - t0 < 3.0
        assert info.value.device == ctl.device
        attempts = [e for e in events if e["event"] == "reconnect"]
        assert len(attempts) >= 2 and all(e["device"] == ctl.device for e in attempts)
    finally:
        ctl.close()
        sim.close()


def test_positions_that_jump_while_homed_are_refused() -> None:
    sim, ctl, _ = _rig(reconnect_s=5.0)
    try:
        ctl.read_positions()
        sim.power_cut(0.2, lose_reference=False)
        _wait_cut(sim)
        # A drive that came back homed but counting from elsewhere.
        sim.machine.count_shift = np.array([0.0, 3.0, 0.0])
        with pytest.raises(ControllerNotHomed, match="positions jumped"):
            ctl.read_positions()
    finally:
        ctl.close()
        sim.close()


def test_rtu_power_cut_is_silence_then_a_drive_that_must_be_homed() -> None:
    sim = SimController(VirtualOrthoglide(GEOMETRY, speed_mm_s=400.0, accel_mm_s2=20000.0),
                        transport="rtu")
    sim.start()
    ctl = ModbusAxisController(**sim.client_kwargs(), timeout_s=0.1, retries=1)
    try:
        ctl.connect()
        assert np.allclose(ctl.read_positions(), PI0, atol=1e-3)
        sim.power_cut(1.0, count_mm=0.0)
        _wait_cut(sim)
        with pytest.raises(ControllerTimeout):
            ctl.read_positions()  # a serial drive without power is only silent
        deadline = time.monotonic() + 5.0
        while not sim.powered and time.monotonic() < deadline:
            time.sleep(0.02)
        # Back, answering again: what it counts from the lost reference is refused.
        with pytest.raises(ControllerNotHomed, match="HOMED clear"):
            ctl.read_positions()
        ctl.home(timeout_s=5.0)
        assert np.allclose(ctl.read_positions(), PI0, atol=1e-3)
    finally:
        ctl.close()
        sim.close()


def test_rtu_power_blip_answered_by_a_retry_is_still_a_drive_that_must_be_homed() -> None:
    # Off for less than the retries last: the request is only late, answered on a
    # retry, by a drive that restarted counting from zero. That answer must not be
    # returned as a position: the reference is checked first.
    sim = SimController(VirtualOrthoglide(GEOMETRY, speed_mm_s=400.0, accel_mm_s2=20000.0),
                        transport="rtu")
    sim.start()
    events: list[dict] = []
    ctl = ModbusAxisController(**sim.client_kwargs(), timeout_s=0.2, retries=8,
                               on_event=events.append)
    try:
        ctl.connect()
        assert np.allclose(ctl.read_positions(), PI0, atol=1e-3)
        sim.power_cut(0.3, count_mm=0.0)
        _wait_cut(sim)
        with pytest.raises(ControllerNotHomed, match="HOMED clear"):
            ctl.read_positions()
        assert any(e["event"] == "retry" for e in events)
        assert events[-1]["event"] == "reference-check" and events[-1]["lost"] is True
        assert ctl.interruptions == 1 and ctl.reconnects == 0
        ctl.home(timeout_s=5.0)
        assert np.allclose(ctl.read_positions(), PI0, atol=1e-3)
    finally:
        ctl.close()
        sim.close()


def test_a_reply_lost_once_is_retried_and_the_drive_checked_before_it_counts() -> None:
    sim, ctl, events = _rig(reconnect_s=5.0)
    try:
        sim.faults.drop_next = 1
        assert np.allclose(ctl.read_positions(), PI0, atol=1e-3)
        kinds = [e["event"] for e in events]
        assert kinds[-2:] == ["retry", "reference-check"] and events[-1]["lost"] is False
        target = PI0 + np.array([5.0, 0.0, -5.0])
        sim.faults.drop_next = 1  # the targets' reply: the move is sent again, whole
        got = ctl.move_and_wait(target, speed_mm_s=400.0, timeout_s=3.0)
        assert np.allclose(got, target, atol=2e-3) and ctl.interruptions == 2
    finally:
        ctl.close()
        sim.close()
