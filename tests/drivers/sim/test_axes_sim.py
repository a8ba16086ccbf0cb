"""ModbusAxisController against the simulated controller: a real pymodbus server
on loopback TCP (ephemeral port) and on a pseudo-terminal null-modem (RTU).

Where a test needs to look at the machine mid-move it gives the virtual machine
a manual clock, so nothing depends on how fast the test host is.
"""

from __future__ import annotations

import contextlib
import gc
import os
import socket
import struct
import time
from collections.abc import Iterator

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient

import orthocal
from drivers.axes import ModbusAxisController
from drivers.base import AxisController
from drivers.device_errors import (
    AlarmError,
    ControllerBusy,
    ControllerConnectionError,
    ControllerTimeout,
    EStopError,
    ExceptionResponse,
    MoveTimeout,
    TargetRefused,
)
from drivers.sim.controller import SimController
from drivers.sim.faults import Faults
from drivers.sim.machine import ALARM_NOT_HOMED, VirtualOrthoglide

GEOMETRY = orthocal.Geometry()
PI0 = orthocal.posture("0", None, GEOMETRY)
TIMEOUT_S = 0.25
#: Where a test asserts that a clean line needs no retry: long enough that a reply late
#: on a loaded test machine is none.
CLEAN_TIMEOUT_S = 1.0


class ManualClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def fast_machine(**kw: object) -> VirtualOrthoglide:
    options: dict = {"speed_mm_s": 400.0, "accel_mm_s2": 20000.0, **kw}
    return VirtualOrthoglide(GEOMETRY, **options)


@contextlib.contextmanager
def station(transport: str, machine: VirtualOrthoglide | None = None,
            faults: Faults | None = None, **ctl_kw: object
            ) -> Iterator[tuple[SimController, ModbusAxisController, list[dict]]]:
    events: list[dict] = []
    options: dict = {"timeout_s": TIMEOUT_S, "retries": 2, "acceleration_mm_s2": 20000.0,
                     "busy_backoff_s": 0.0, "on_event": events.append, **ctl_kw}
    with SimController(machine or fast_machine(), transport=transport, faults=faults,
                       seed=1) as sim, \
            ModbusAxisController(**(sim.client_kwargs() | options)) as ctl:
        yield sim, ctl, events


@pytest.fixture(params=["tcp", "rtu"])
def transport(request: pytest.FixtureRequest) -> str:
    return request.param


# --- motion ------------------------------------------------------------------------------------


def test_move_and_arrive(transport: str) -> None:
    with station(transport, timeout_s=CLEAN_TIMEOUT_S) as (sim, ctl, events):
        assert isinstance(ctl, AxisController)
        target = PI0 + np.array([12.0, -7.5, 3.0004])
        pos = ctl.move_and_wait(target, speed_mm_s=300)
        assert np.all(np.abs(pos - target) <= 0.002)
        assert np.all(np.abs(sim.machine.actual() - target) <= 0.001)
        assert sim.machine.speed_mm_s == 300
        assert events == []


def test_status_bits_follow_the_move(transport: str) -> None:
    clock = ManualClock()
    machine = fast_machine(speed_mm_s=10.0, accel_mm_s2=100.0, clock=clock)
    with station(transport, machine) as (_sim, ctl, _):
        st = ctl.read_status()
        assert (st.homed, st.moving, st.in_position, st.alarm, st.estop) == (
            True, False, True, False, False)
        target = PI0 + np.array([5.0, 0.0, -5.0])
        ctl.move(target)
        st = ctl.read_status()
        assert st.moving and not st.in_position and st.homed
        clock.t += 0.4  # part way
        mid = ctl.read_positions()
        assert PI0[0] < mid[0] < target[0] and target[2] < mid[2] < PI0[2]
        clock.t += 10.0  # long after the move's end
        st = ctl.read_status()
        assert st.in_position and not st.moving
        np.testing.assert_allclose(ctl.wait_in_position(target, 1.0), target, atol=0.002)


def test_soft_limits_read_and_enforced(transport: str) -> None:
    with station(transport) as (sim, ctl, _):
        lo, hi = ctl.soft_limits()
        np.testing.assert_allclose(lo, [200.25] * 3, atol=1e-12)
        np.testing.assert_allclose(hi, [380.25] * 3, atol=1e-12)
        for sign in "+-":
            for leg in "xyz":  # every test posture of docs/design.md fits
                p = orthocal.posture(sign, leg, GEOMETRY)
                assert np.all(p > lo) and np.all(p < hi)
        with pytest.raises(TargetRefused) as info:
            ctl.move([380.26, 310.25, 310.25])
        assert info.value.code == 3
        np.testing.assert_allclose(sim.machine.targets(), PI0, atol=1e-9)
        assert sim.stats.commands == {}  # the command never followed


def test_stop_mid_move(transport: str) -> None:
    clock = ManualClock()
    machine = fast_machine(speed_mm_s=10.0, accel_mm_s2=100.0, clock=clock)
    with station(transport, machine) as (_sim, ctl, _):
        target = PI0 + np.array([20.0, 0.0, 0.0])
        ctl.move(target)
        clock.t += 1.0
        ctl.stop()
        clock.t += 10.0
        st = ctl.read_status()
        assert not st.moving and not st.in_position
        stopped = ctl.read_positions()
        assert PI0[0] + 1.0 < stopped[0] < target[0] - 1.0
        with pytest.raises(MoveTimeout, match="not in position"):
            ctl.wait_in_position(target, timeout_s=0.1)


def test_home(transport: str) -> None:
    machine = fast_machine(homed=False, start=PI0 + np.array([5, 5, 5]))
    with station(transport, machine) as (_sim, ctl, _):
        assert not ctl.read_status().homed
        ctl.move(PI0)  # a move before homing faults the drive
        with pytest.raises(AlarmError) as info:
            ctl.wait_in_position(PI0, 1.0)
        assert info.value.code == ALARM_NOT_HOMED
        ctl.reset_alarm()
        ctl.home(timeout_s=5.0)
        st = ctl.read_status()
        assert st.homed and not st.moving
        np.testing.assert_allclose(ctl.read_positions(), PI0, atol=0.001)


def test_offsets_write_readback_and_effect_on_the_legs(transport: str) -> None:
    true_drho = np.array([1.5, -2.0, 1.0])
    machine = fast_machine(true_drho=true_drho)
    key = ("+", "x", "y")

    def measured_deviation(ctl: ModbusAxisController) -> float:
        ctl.move_and_wait(orthocal.posture("0", None, GEOMETRY), speed_mm_s=400)
        r0 = machine.leg_reading("x", "y")
        ctl.move_and_wait(orthocal.posture("+", "x", GEOMETRY), speed_mm_s=400)
        return machine.leg_reading("x", "y") - r0

    with station(transport, machine) as (sim, ctl, _):
        np.testing.assert_allclose(ctl.read_offsets(), [0, 0, 0], atol=1e-12)
        expected = orthocal.deviation(key, GEOMETRY, [*true_drho, 0, 0, 0])
        before = measured_deviation(ctl)
        assert before == pytest.approx(expected, abs=2e-3)
        assert abs(before) > 0.05  # the error is visible
        # docs/design.md "Writing the offsets back": o ← o − Δρ
        written = ctl.write_offsets(ctl.read_offsets() - true_drho)
        np.testing.assert_allclose(written, -true_drho, atol=1e-12)
        np.testing.assert_allclose(sim.machine.offsets, -true_drho, atol=1e-12)
        after = measured_deviation(ctl)
        assert abs(after) < 2e-3  # nominal up to the µm resolution


def test_offset_beyond_the_drive_range_is_an_exception(transport: str) -> None:
    with station(transport) as (_sim, ctl, _), pytest.raises(ExceptionResponse) as info:
        ctl.write_offsets([0.0, 60.0, 0.0])
    assert info.value.code == 3 and not isinstance(info.value, TargetRefused)


# --- faults ------------------------------------------------------------------------------------


def test_dropped_reply_is_retried(transport: str) -> None:
    with station(transport, faults=Faults(drop_next=1)) as (sim, ctl, events):
        np.testing.assert_allclose(ctl.read_positions(), PI0, atol=1e-9)
        assert sim.stats.dropped == 1
        # answered on a retry: the drive is checked before the answer counts
        assert [(e["event"], e.get("op")) for e in events] == [
            ("retry", "read positions"), ("reference-check", None)]
        assert events[-1]["lost"] is False and ctl.interruptions == 1


def test_random_drops_are_reproducible_and_survived(transport: str) -> None:
    # A reply that is only late (a loaded machine) must not pass for a drop: the
    # timeout here is far above any turnaround, so every retry is one the sim made.
    with station(transport, faults=Faults(drop_rate=0.3), retries=6, timeout_s=1.0) as (
            sim, ctl, events):
        for _ in range(6):
            ctl.read_status()
        assert sim.stats.dropped == len(events) > 0


def test_busy_is_retried_then_given_up(transport: str) -> None:
    with station(transport, faults=Faults(busy_next=2)) as (sim, ctl, events):
        ctl.move_and_wait(PI0 + 1.0, speed_mm_s=300)
        assert [e["error"] for e in events] == ["Modbus exception 6 (server device busy)"] * 2
        sim.faults.busy_next = 3
        with pytest.raises(ControllerBusy, match="read positions"):
            ctl.read_positions()


def test_garbled_reply_is_retried(transport: str) -> None:
    with station(transport, faults=Faults(garble_next=1)) as (sim, ctl, events):
        np.testing.assert_allclose(ctl.read_offsets(), [0, 0, 0], atol=1e-12)
        assert sim.stats.garbled == 1 and len(events) == 1


def test_silent_controller_times_out(transport: str) -> None:
    with station(transport, faults=Faults(silent=True)) as (sim, ctl, events):
        with pytest.raises(ControllerTimeout) as info:
            ctl.read_status()
        assert "read status" in str(info.value) and "3 attempt" in str(info.value)
        assert len(events) == 2 and sim.stats.ignored == 3
        sim.faults.silent = False
        assert ctl.read_status().homed  # and it recovers


def test_late_reply_within_the_timeout_is_fine(transport: str) -> None:
    with station(transport, faults=Faults(delay_s=CLEAN_TIMEOUT_S / 5),
                 timeout_s=CLEAN_TIMEOUT_S) as (sim, ctl, events):
        np.testing.assert_allclose(ctl.read_positions(), PI0, atol=1e-9)
        assert sim.stats.delayed >= 1 and events == []


def test_reply_later_than_the_timeout_is_a_timeout() -> None:
    # TCP only: replies carry a transaction id, so a late reply cannot be
    # mistaken for the answer to the retry. (pymodbus restarts its wait when a
    # stale frame arrives, so the delay must outlast all three attempts.)
    with station("tcp", faults=Faults(delay_s=TIMEOUT_S * 5)) as (_sim, ctl, events):
        with pytest.raises(ControllerTimeout):
            ctl.read_positions()
        assert len(events) == 2


def test_dropped_connection_reconnects() -> None:
    with station("tcp", faults=Faults(disconnect_next=1)) as (sim, ctl, events):
        np.testing.assert_allclose(ctl.read_positions(), PI0, atol=1e-9)
        assert sim.stats.disconnects == 1
        assert [e["event"] for e in events] == ["retry", "reconnected", "reference-check"]
        assert "connection" in events[0]["error"] and not events[2]["lost"]


def test_alarm_after_moves(transport: str) -> None:
    with station(transport, faults=Faults(alarm_after_moves=1, alarm_code=42)) as (
            _sim, ctl, _):
        ctl.move_and_wait(PI0 + 5.0, speed_mm_s=300)
        with pytest.raises(AlarmError) as info:
            ctl.move_and_wait(PI0 - 5.0, speed_mm_s=300)
        assert info.value.code == 42 and "alarm 42" in str(info.value)
        stuck = ctl.read_positions()
        assert np.all(stuck < PI0 + 5.0) and np.all(stuck > PI0 - 5.0)
        ctl.reset_alarm()
        assert not ctl.read_status().alarm
        ctl.move_and_wait(PI0 - 5.0, speed_mm_s=300)


def test_estop(transport: str) -> None:
    clock = ManualClock()
    machine = fast_machine(speed_mm_s=10.0, accel_mm_s2=100.0, clock=clock)
    with station(transport, machine) as (sim, ctl, _):
        ctl.move(PI0 + 10.0)
        clock.t += 0.5
        sim.faults.estop = True
        with pytest.raises(EStopError, match="emergency stop"):
            ctl.wait_in_position(PI0 + 10.0, 1.0)
        clock.t += 10.0
        assert np.all(ctl.read_positions() < PI0 + 9.0)  # it stopped where it was
        sim.faults.estop = False
        assert not ctl.read_status().estop


def test_move_slower_than_its_deadline_is_a_move_timeout(transport: str) -> None:
    # The drive accelerates far more slowly than the station assumes.
    machine = fast_machine(accel_mm_s2=20.0)
    with station(transport, machine, timeout_margin_s=0.05) as (_sim, ctl, _):
        with pytest.raises(MoveTimeout):
            ctl.move_and_wait(PI0 + 10.0, speed_mm_s=100)
        ctl.stop()


def test_wrong_device_id(transport: str) -> None:
    with station(transport, device_id=9) as (_sim, ctl, _):
        if transport == "tcp":
            with pytest.raises(ExceptionResponse) as info:
                ctl.read_status()  # a gateway answers for the missing unit
            assert info.value.code == 11
        else:
            with pytest.raises(ControllerTimeout):
                ctl.read_status()  # on a serial line the other units stay silent


def test_connection_refused_names_host_and_port() -> None:
    with socket.socket() as s:  # find a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    ctl = ModbusAxisController(host="127.0.0.1", port=port, timeout_s=0.5)
    with pytest.raises(ControllerConnectionError) as info:
        ctl.connect()
    assert f"127.0.0.1:{port}" in str(info.value)
    assert info.value.device == f"controller 127.0.0.1:{port}"
    with pytest.raises(ControllerConnectionError, match="/dev/nonexistent-orthocal"):
        ModbusAxisController(transport="rtu", port="/dev/nonexistent-orthocal").connect()


# --- the documented map alone -------------------------------------------------------------------


def _i32(words: list[int]) -> int:
    return struct.unpack(">i", struct.pack(">HH", *words))[0]


def _words(um: int) -> list[int]:
    return list(struct.unpack(">HH", struct.pack(">i", um)))


def test_independent_pymodbus_client_drives_the_simulator() -> None:
    """docs/design.md's table is enough: no code of ours on the client side."""
    with SimController(fast_machine(), transport="tcp") as sim:
        client = ModbusTcpClient("127.0.0.1", port=sim.port, timeout=1.0)
        try:
            assert client.connect()
            rr = client.read_holding_registers(20, count=6, device_id=1)
            assert [_i32(rr.registers[i:i + 2]) for i in (0, 2, 4)] == [310250] * 3
            targets = [320000, 300000, -1 + 310250]
            rr = client.write_registers(10, [w for t in targets for w in _words(t)], device_id=1)
            assert not rr.isError()
            assert not client.write_register(40, 200, device_id=1).isError()  # SPEED mm/s
            assert not client.write_register(0, 1, device_id=1).isError()  # COMMAND move
            assert client.read_holding_registers(0, count=1, device_id=1).registers == [0]
            deadline = time.monotonic() + 5.0
            while True:
                status = client.read_holding_registers(1, count=2, device_id=1).registers
                if status[0] & 0b100 and not status[0] & 0b10:  # IN_POSITION, not MOVING
                    break
                assert time.monotonic() < deadline, f"never in position: {status}"
                time.sleep(0.005)
            assert status == [0b00101, 0]  # HOMED | IN_POSITION, no alarm
            rr = client.read_holding_registers(20, count=6, device_id=1)
            assert [_i32(rr.registers[i:i + 2]) for i in (0, 2, 4)] == targets
            # OFFSET: the carriage stays, the count shifts by −Δo
            client.write_registers(30, _words(500) + _words(0) + _words(-250), device_id=1)
            rr = client.read_holding_registers(20, count=6, device_id=1)
            assert [_i32(rr.registers[i:i + 2]) for i in (0, 2, 4)] == [
                319500, 300000, 310249 + 250]
            # soft limits: readable, and a target beyond them is exception 3
            rr = client.read_holding_registers(50, count=2, device_id=1)
            assert _i32(rr.registers) == 200250
            rr = client.read_holding_registers(60, count=2, device_id=1)
            assert _i32(rr.registers) == 380250
            rr = client.write_registers(12, _words(380251), device_id=1)
            assert rr.isError() and rr.exception_code == 3
            # read-only registers refuse writes; unknown commands are refused
            assert client.write_register(1, 0, device_id=1).isError()
            rr = client.write_register(0, 9, device_id=1)
            assert rr.isError() and rr.exception_code == 3
        finally:
            client.close()


def test_controller_gone_mid_session_is_a_connection_error() -> None:
    sim = SimController(fast_machine(), transport="tcp").start()
    events: list[dict] = []
    try:
        with ModbusAxisController(**sim.client_kwargs(), timeout_s=TIMEOUT_S, retries=1,
                                  on_event=events.append, reconnect_s=0.3) as ctl:
            ctl.read_positions()
            sim.close()
            with pytest.raises(ControllerConnectionError, match="read positions"):
                ctl.read_positions()
            assert events[0]["event"] == "retry"
            assert {e["event"] for e in events[1:]} == {"reconnect"}
    finally:
        sim.close()


# --- the virtual machine on its own ---------------------------------------------------------------


def test_machine_axes_arrive_together_with_a_trapezoid() -> None:
    clock = ManualClock()
    m = VirtualOrthoglide(GEOMETRY, speed_mm_s=50.0, accel_mm_s2=500.0, clock=clock)
    start = m.actual()
    delta = np.array([40.0, -10.0, 20.0])
    duration = m.move_to(start + delta)
    assert duration == pytest.approx(40.0 / 50.0 + 50.0 / 500.0)  # cruise + one ramp
    t0 = clock.t
    previous = start
    for k in range(1, 20):
        clock.t = t0 + duration * k / 20
        pos = m.actual()
        fraction = (pos - start) / delta
        np.testing.assert_allclose(fraction, fraction[0], atol=1e-12)  # in step
        assert np.max(np.abs(pos - previous)) <= 50.0 * duration / 20 + 1e-9  # ≤ speed
        previous = pos
    clock.t = t0 + duration
    np.testing.assert_allclose(m.actual(), start + delta, atol=1e-12)
    assert m.status().in_position


def test_machine_offsets_shift_the_count_not_the_carriage() -> None:
    m = VirtualOrthoglide(GEOMETRY, true_drho=(0.4, -0.3, 0.2))
    q_before = m.joint_values()
    np.testing.assert_allclose(q_before, PI0 + np.array([0.4, -0.3, 0.2]), atol=1e-12)
    m.set_offsets([-0.4, 0.3, -0.2])
    np.testing.assert_allclose(m.joint_values(), q_before, atol=1e-12)  # nothing moved
    np.testing.assert_allclose(m.actual(), PI0 + np.array([0.4, -0.3, 0.2]), atol=1e-12)
    with pytest.raises(ValueError):
        VirtualOrthoglide(GEOMETRY, true_params=[1, 2, 3], true_drho=[0, 0, 0])


def test_a_client_that_came_and_went_just_before_close_leaves_no_socket() -> None:
    # The server accepts it in the same pass of its loop as the stop: its connection,
    # set up after the listener closed, was left for the garbage collector to close
    # (collector held off here, as it may be for a while), a socket behind close().
    def sockets() -> set[str]:
        found = set()
        for fd in os.listdir("/proc/self/fd"):
            with contextlib.suppress(OSError):
                found.add(os.readlink(f"/proc/self/fd/{fd}"))
        return {f for f in found if f.startswith("socket:")}

    machine = fast_machine()
    gc.disable()
    try:
        for _ in range(20):
            before = sockets()
            sim = SimController(machine).start()
            socket.create_connection(("127.0.0.1", sim.port)).close()
            sim.close()
            assert sockets() <= before
    finally:
        gc.enable()
