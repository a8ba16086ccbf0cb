"""The virtual drive serving register maps other than the generic one:
the real ModbusAxisController against the real pymodbus server on 127.0.0.1
(ephemeral ports) or on a pseudo-terminal null-modem (RTU), for IAI's PCON map and
for a map never seen before, built here: three single-axis drives behind one
gateway. One request/response pair of that map is checked byte for byte against
the Modbus spec. (The generic map's own tests, test_axes_sim.py and
test_sim_integrator.py, run unchanged against the same drive.)

Where a test looks at the machine mid-move it gives it a manual clock.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import time
from collections.abc import Iterator

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient

import orthocal
from drivers.axes import ModbusAxisController
from drivers.device_errors import AlarmError, ControllerError, MoveTimeout, TargetRefused
from drivers.map_files import builtin_maps
from drivers.registers import (
    AXES,
    GENERIC,
    CommandStep,
    Register,
    RegisterMap,
    StatusBit,
)
from drivers.sim.controller import SimController
from drivers.sim.faults import Faults
from drivers.sim.machine import VirtualOrthoglide
from drivers.sim.specs import DriveSpec, GaugeSpec
from station.commands.simulate.station_setups import SimulatedStation

IAI_PCON = builtin_maps()["iai-pcon-direct"]
GEOMETRY = orthocal.Geometry()
PI0 = orthocal.posture("0", None, GEOMETRY)
LIMITS = ([200.25] * 3, [380.25] * 3)  # the drive's default soft limits
#: Long enough that a reply late on a loaded test machine is no retry (a clean line's
#: tests assert none), short enough that the one lost reply below costs little.
TIMEOUT_S = 1.0
QUIET = GaugeSpec(noise_mm=0.0)  # the virtual station's gauges, without noise
COUNTS_PER_MM = 2000.0  # the gateway map's encoders


class ManualClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def fast_machine(**kw: object) -> VirtualOrthoglide:
    options: dict = {"speed_mm_s": 400.0, "accel_mm_s2": 20000.0, **kw}
    return VirtualOrthoglide(GEOMETRY, **options)


def gateway_map(offsets: bool = True) -> RegisterMap:
    """Three single-axis drives behind one gateway, unit ids 1, 2, 3 (X, Y, Z): per
    drive a control word (holding 0: rising edges of bit 0 start, bit 1 stop, bit 2
    home, bit 3 reset), the target (holding 2), a home offset (holding 4) and the
    speed (holding 6) in encoder counts (2000 per mm), i32 low word first; the
    counted position (input 0), a status word (input 2: bit 0 homed, 1 moving,
    2 in position, 3 alarm, 15 EMG circuit closed, i.e. e-stop active low) and the
    alarm code (input 3) in input registers. No soft-limit registers."""
    registers: list[Register] = []
    for unit, ax in enumerate(AXES, start=1):
        counts = {"type": "i32", "word_order": "low_first", "scale": COUNTS_PER_MM,
                  "unit": "mm", "device_id": unit}
        registers += [
            Register(name=f"CONTROL_{ax}", address=0, access="RW", device_id=unit),
            Register(name=f"TARGET_{ax}", address=2, access="RW", **counts),
            Register(name=f"SPEED_{ax}", address=6, type="u32", word_order="low_first",
                     scale=COUNTS_PER_MM, unit="mm/s", access="RW", device_id=unit),
            Register(name=f"ACTUAL_{ax}", address=0, table="input", **counts),
            Register(name=f"STATUS_{ax}", address=2, table="input", device_id=unit),
            Register(name=f"ALARM_{ax}", address=3, table="input", device_id=unit),
        ]
        if offsets:
            registers.append(Register(name=f"OFFSET_{ax}", address=4, access="RW", **counts))

    def edge(bit: int) -> list[CommandStep]:
        return [*(CommandStep(reg=f"CONTROL_{ax}", value=0) for ax in AXES),
                *(CommandStep(reg=f"CONTROL_{ax}", value=bit) for ax in AXES)]

    status = [f"STATUS_{ax}" for ax in AXES]
    return RegisterMap(
        name="test-gateway-3x1" if offsets else "test-gateway-3x1-no-offsets",
        registers=registers,
        status={"homed": StatusBit(registers=status, bit=0, combine="all"),
                "moving": StatusBit(registers=status, bit=1, combine="any"),
                "in_position": StatusBit(registers=status, bit=2, combine="all"),
                "alarm": StatusBit(registers=status, bit=3, combine="any"),
                "estop": StatusBit(registers=status, bit=15, combine="any",
                                   active_high=False)},
        alarm_code=[f"ALARM_{ax}" for ax in AXES],
        commands={"move": edge(1), "stop": edge(2), "home": edge(4), "reset_alarm": edge(8)},
        unsupported={"soft_limits": "kept in the drives' parameters",
                     **({} if offsets else {"offsets": "this gateway has no offsets"})},
    )


GATEWAY = gateway_map()


@contextlib.contextmanager
def served(register_map: RegisterMap, transport: str = "tcp",
           machine: VirtualOrthoglide | None = None, faults: Faults | None = None,
           **ctl_kw: object) -> Iterator[tuple[SimController, ModbusAxisController, list]]:
    events: list[dict] = []
    options: dict = {"timeout_s": TIMEOUT_S, "retries": 2, "acceleration_mm_s2": 20000.0,
                     "busy_backoff_s": 0.0, "on_event": events.append, "soft_limits": LIMITS,
                     **ctl_kw}
    with SimController(machine or fast_machine(), transport=transport, faults=faults,
                       seed=1, register_map=register_map) as sim, \
            ModbusAxisController(**(sim.client_kwargs() | options)) as ctl:
        yield sim, ctl, events


@contextlib.contextmanager
def raw_client(sim: SimController) -> Iterator[ModbusTcpClient]:
    client = ModbusTcpClient("127.0.0.1", port=sim.port, timeout=2.0)
    assert client.connect()
    try:
        yield client
    finally:
        client.close()


@pytest.fixture(params=["tcp", "rtu"])
def transport(request: pytest.FixtureRequest) -> str:
    return request.param


MAPS = {**{n: m for n, m in builtin_maps().items() if n != GENERIC.name}, "gateway": GATEWAY}


@pytest.fixture(params=list(MAPS.values()), ids=list(MAPS))
def a_map(request: pytest.FixtureRequest) -> RegisterMap:
    return request.param


def resolution(register_map: RegisterMap) -> float:
    return 1.0 / register_map["ACTUAL_X"].scale


# --- any map: positions, moves, stop, home, alarms ----------------------------------------------


def test_positions_and_a_move(a_map: RegisterMap, transport: str) -> None:
    with served(a_map, transport) as (sim, ctl, events):
        assert sim.devices == [1, 2, 3]
        np.testing.assert_allclose(ctl.read_positions(), PI0, atol=resolution(a_map))
        st = ctl.read_status()
        assert (st.homed, st.moving, st.in_position, st.alarm, st.estop) == (
            True, False, True, False, False)
        target = PI0 + np.array([12.0, -7.5, 3.01])
        pos = ctl.move_and_wait(target, speed_mm_s=300)
        assert np.all(np.abs(pos - target) <= 0.002)
        np.testing.assert_allclose(sim.machine.actual(), target, atol=0.001)
        assert sim.machine.speed_mm_s == 300
        # every axis's completion of the sequence (IAI: its target write) starts it
        assert sim.stats.commands == {1: 3}
        assert events == []


def test_status_follows_the_move_and_stop_brakes_it(a_map: RegisterMap, transport: str) -> None:
    clock = ManualClock()
    machine = fast_machine(speed_mm_s=10.0, accel_mm_s2=100.0, clock=clock)
    with served(a_map, transport, machine) as (sim, ctl, _):
        target = PI0 + np.array([20.0, 0.0, -20.0])
        ctl.move(target)
        st = ctl.read_status()
        assert st.moving and not st.in_position
        clock.t += 1.0
        ctl.stop()
        assert sim.stats.commands.get(2, 0) >= 1
        clock.t += 10.0
        st = ctl.read_status()
        # A CiA 402 drive (Kinco) has one bit for both: "target reached" is set once a
        # halt has stopped the carriage, short of the target; the station checks the
        # positions before it takes a move as done (below), never that bit alone.
        one_bit = a_map.status["moving"].bit == a_map.status["in_position"].bit
        assert not st.moving and st.in_position is one_bit
        stopped = ctl.read_positions()
        assert PI0[0] + 1.0 < stopped[0] < target[0] - 1.0
        assert target[2] + 1.0 < stopped[2] < PI0[2] - 1.0
        with pytest.raises(MoveTimeout, match="not in position"):
            ctl.wait_in_position(target, timeout_s=0.1)


def test_home_then_alarm_and_its_reset(a_map: RegisterMap, transport: str) -> None:
    machine = fast_machine(homed=False, start=PI0 + np.array([5, 5, 5]))
    with served(a_map, transport, machine, faults=Faults(alarm_after_moves=0, alarm_code=42)
                ) as (sim, ctl, _):
        assert not ctl.read_status().homed
        ctl.home(timeout_s=5.0)
        st = ctl.read_status()
        assert st.homed and not st.moving
        np.testing.assert_allclose(ctl.read_positions(), PI0, atol=resolution(a_map))
        # the first move faults halfway (Faults.alarm_after_moves): ALARM and its code
        with pytest.raises(AlarmError) as info:
            ctl.move_and_wait(PI0 + 5.0, speed_mm_s=300)
        assert info.value.code == 42
        ctl.reset_alarm()
        assert not ctl.read_status().alarm and sim.machine.status().alarm_code == 0
        ctl.move_and_wait(PI0 + 5.0, speed_mm_s=300)


def test_faults_are_injected_on_any_map(a_map: RegisterMap) -> None:
    with served(a_map, faults=Faults(drop_next=1)) as (sim, ctl, events):
        np.testing.assert_allclose(ctl.read_positions(), PI0, atol=resolution(a_map))
        sim.faults.busy_next = 1
        assert ctl.read_status().homed
        assert sim.stats.dropped == 1 and sim.stats.busy == 1
        assert [e["error"] for e in events if e["event"] == "retry"] == [
            f"no reply within {TIMEOUT_S:g} s", "Modbus exception 6 (server device busy)"]
        # the answer after no reply counted only once the drive was checked
        assert [e["lost"] for e in events if e["event"] == "reference-check"] == [False]
        sim.faults.estop = True
        assert ctl.read_status().estop  # the gateway's active-low EMG bit included
        sim.faults.estop = False
        assert not ctl.read_status().estop


def test_a_target_outside_the_soft_limits_is_exception_3(a_map: RegisterMap) -> None:
    # no driver-side limits: the drive itself refuses, as the generic map's does
    with served(a_map, soft_limits=None) as (sim, ctl, _):
        with pytest.raises(TargetRefused) as info:
            ctl.move(PI0 + np.array([80.0, 0.0, 0.0]))
        assert info.value.code == 3
        np.testing.assert_allclose(sim.machine.targets(), PI0, atol=1e-9)
        assert sim.stats.commands == {} and sim.stats.refused == 1


def test_a_second_stop_at_the_same_instant_keeps_braking() -> None:
    # A per-axis map stops each axis in turn: three stops within one instant of a
    # manual clock must brake from where the first one found the carriages.
    clock = ManualClock()
    machine = fast_machine(speed_mm_s=10.0, accel_mm_s2=100.0, clock=clock)
    machine.move_to(PI0 + np.array([20.0, 0.0, -20.0]))
    clock.t += 1.0
    machine.stop()
    braking = machine.actual()
    machine.stop()
    machine.stop()
    np.testing.assert_allclose(machine.actual(), braking, atol=1e-12)
    clock.t += 10.0
    # 10 mm/s braked at 100 mm/s²: 0.5 mm further
    np.testing.assert_allclose(machine.actual(), braking + np.array([0.5, 0.0, -0.5]), atol=1e-9)


# --- IAI PCON ------------------------------------------------------------------------------------


def test_iai_answers_exception_2_outside_its_map() -> None:
    with served(IAI_PCON) as (sim, _ctl, _), raw_client(sim) as c:
        assert not c.read_holding_registers(0x9000, count=2, device_id=2).isError()
        for rr in (c.read_holding_registers(0x9010, count=1, device_id=1),  # no register
                   c.read_holding_registers(0x9000, count=4, device_id=1),  # runs past PNOW
                   c.read_input_registers(0x9000, count=2, device_id=1),  # wrong table
                   c.read_coils(0x0404, count=1, device_id=1),  # between two coils
                   c.read_coils(0x0403, count=2, device_id=1),
                   c.write_registers(0x9000, [0, 0], device_id=3)):  # PNOW is read-only
            assert rr.isError() and rr.exception_code == 2, rr
        assert c.read_holding_registers(0x9000, count=2, device_id=4).exception_code == 11
        assert not c.read_coils(0x0403, count=1, device_id=3).isError()  # SERVO_ON
        assert sim.stats.refused == 0


def test_iai_home_needs_the_rising_edge() -> None:
    machine = fast_machine(homed=False)
    with served(IAI_PCON, machine=machine) as (sim, _ctl, _), raw_client(sim) as c:
        assert not c.write_coil(0x040B, True, device_id=1).isError()  # HOME_X: 0 -> 1
        assert sim.stats.commands == {3: 1}
        assert not c.write_coil(0x040B, True, device_id=1).isError()  # 1 again: nothing
        assert sim.stats.commands == {3: 1}
        rr = c.read_coils(0x040B, count=1, device_id=1)
        assert rr.bits[0] is True  # plain storage: what was written


def test_virtual_station_serves_the_map_and_says_so() -> None:
    with SimulatedStation(drive=DriveSpec(register_map=IAI_PCON), gauges=QUIET) as vs:
        c = vs.config()["controller"]
        assert (c["profile"], c["device_id"]) == ("iai-pcon-direct", 1)
        assert (c["soft_min"], c["soft_max"]) == LIMITS  # the map has no soft-limit registers
        keys = ("transport", "host", "port", "device_id", "profile")
        with ModbusAxisController(**{k: c[k] for k in keys}, timeout_s=1.0) as ctl:
            np.testing.assert_allclose(ctl.read_positions(), PI0, atol=0.01)
    gateway = DriveSpec(register_map=GATEWAY, profile="bench-gateway")
    with SimulatedStation(drive=gateway, gauges=QUIET) as vs:
        assert vs.config()["controller"]["profile"] == "bench-gateway"
        assert vs.controller.client_kwargs()["profile"] is GATEWAY  # not a built-in
    with SimulatedStation(gauges=QUIET) as vs:
        c = vs.config()["controller"]
        assert c["profile"] == GENERIC.name and "soft_min" not in c


# --- a map never seen before ------------------------------------------------------------------


def test_gateway_offsets_written_read_back_and_shifting_the_count(transport: str) -> None:
    with served(GATEWAY, transport) as (sim, ctl, _):
        np.testing.assert_allclose(ctl.read_offsets(), [0, 0, 0], atol=1e-12)
        written = ctl.write_offsets([0.5, -0.25, 0.1005])
        np.testing.assert_allclose(written, [0.5, -0.25, 0.1005], atol=1e-12)
        np.testing.assert_allclose(sim.machine.offsets, written, atol=1e-12)
        # the carriages stay, the count ρ = m − o shifts
        np.testing.assert_allclose(ctl.read_positions(), PI0 - written, atol=0.0005)
        assert ctl.offset_resolution_mm() == 1 / COUNTS_PER_MM
        target = PI0 + 2.0
        ctl.move_and_wait(target, speed_mm_s=300)
        np.testing.assert_allclose(sim.machine.actual(), target, atol=0.001)


def test_gateway_without_offset_registers_still_moves() -> None:
    no_offsets = gateway_map(offsets=False)
    with served(no_offsets) as (sim, ctl, _):
        with pytest.raises(ControllerError, match="this gateway has no offsets"):
            ctl.read_offsets()
        target = PI0 + np.array([-4.0, 6.0, 1.0])
        ctl.move_and_wait(target, speed_mm_s=300)
        np.testing.assert_allclose(sim.machine.actual(), target, atol=0.001)
        with raw_client(sim) as c:
            assert c.read_holding_registers(4, count=2, device_id=1).exception_code == 2


def test_gateway_start_bit_is_edge_triggered() -> None:
    with served(GATEWAY) as (sim, ctl, _), raw_client(sim) as c:
        ctl.move_and_wait(PI0 + 1.0, speed_mm_s=300)
        assert sim.stats.commands == {1: 3}
        # CONTROL_Y holds 1: a new target then 1 again is no rising edge
        counts = round((PI0[1] + 3.0) * COUNTS_PER_MM)
        words = [counts & 0xFFFF, counts >> 16]  # low word first
        assert not c.write_registers(2, words, device_id=2).isError()
        assert not c.write_register(0, 1, device_id=2).isError()
        assert sim.stats.commands == {1: 3}
        assert c.read_holding_registers(0, count=1, device_id=2).registers == [1]
        assert not c.write_register(0, 0, device_id=2).isError()
        assert not c.write_register(0, 1, device_id=2).isError()  # the edge: it moves
        assert sim.stats.commands == {1: 4}
        deadline = time.monotonic() + 5.0
        while abs(sim.machine.actual()[1] - (PI0[1] + 3.0)) > 0.001:
            assert time.monotonic() < deadline
            time.sleep(0.005)
        np.testing.assert_allclose(ctl.read_positions(), PI0 + np.array([1.0, 3.0, 1.0]),
                                   atol=0.0005)


def _exchange(port: int, request: bytes, reply_length: int) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=2.0) as s:
        s.sendall(request)
        reply = b""
        deadline = time.monotonic() + 2.0
        while len(reply) < reply_length and time.monotonic() < deadline:
            chunk = s.recv(256)
            if not chunk:
                break
            reply += chunk
        return reply


def test_gateway_input_registers_byte_exact_on_tcp() -> None:
    """Modbus Application Protocol v1.1b3 §6.4 (Read Input Registers, function 04)
    in a Modbus/TCP ADU (MBAP: transaction id, protocol id 0, length = unit id +
    PDU bytes, unit id): device 2's ACTUAL_Y, two registers, low word first."""
    machine = fast_machine(start=PI0 + np.array([0.0, -12.3456, 0.0]))
    with SimController(machine, register_map=GATEWAY) as sim:
        counts = round((PI0[1] - 12.3456) * COUNTS_PER_MM)  # 595 809 = 0x0009_1761
        request = struct.pack(">HHHB", 0x0A0B, 0, 6, 2) + struct.pack(">BHH", 0x04, 0, 2)
        expected = struct.pack(">HHHB", 0x0A0B, 0, 7, 2) + struct.pack(
            ">BBHH", 0x04, 4, counts & 0xFFFF, counts >> 16)
        assert _exchange(sim.port, request, len(expected)) == expected
        # outside the map (input 4 of device 2): exception 2, function code | 0x80
        request = struct.pack(">HHHB", 0x0A0C, 0, 6, 2) + struct.pack(">BHH", 0x04, 4, 1)
        expected = struct.pack(">HHHBBB", 0x0A0C, 0, 3, 2, 0x84, 0x02)
        assert _exchange(sim.port, request, len(expected)) == expected
