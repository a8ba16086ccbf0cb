"""The simulated controller driven as an integrator would drive a drive: pymodbus's
own client used raw (no orthocal driver, no register-map code), registers by
address from docs/design.md's table. The simulator must be as strict as a drive:
targets start where the axes stand, a move to stored targets outside the soft
limits is refused with exception 3, and addresses outside the map answer
exception 2."""

from __future__ import annotations

import time

import pytest
from pymodbus.client import ModbusTcpClient

from drivers.sim.controller import SimController

COMMAND, STATUS, TARGET_X, ACTUAL_X, SPEED = 0, 1, 10, 20, 40
IN_POSITION, MOVING = 1 << 2, 1 << 1
DEV = {"device_id": 1}


def _i32(words: list[int]) -> int:
    value = words[0] << 16 | words[1]
    return value - (1 << 32) if value & 0x80000000 else value


def _words(value: int) -> list[int]:
    value &= 0xFFFFFFFF
    return [value >> 16, value & 0xFFFF]


def _mm(client: ModbusTcpClient, address: int) -> list[float]:
    rr = client.read_holding_registers(address, count=6, **DEV)
    assert not rr.isError(), rr
    return [_i32(rr.registers[i:i + 2]) / 1000.0 for i in (0, 2, 4)]


def _wait_still(client: ModbusTcpClient, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        status = client.read_holding_registers(STATUS, count=1, **DEV).registers[0]
        if status & IN_POSITION and not status & MOVING:
            return
        time.sleep(0.01)
    raise AssertionError("axes not in position in time")


@pytest.fixture
def client():
    with SimController() as sim:
        c = ModbusTcpClient("127.0.0.1", port=sim.port, timeout=2.0)
        assert c.connect()
        try:
            yield sim, c
        finally:
            c.close()


def test_one_target_then_command_1_moves_one_axis(client) -> None:
    _sim, c = client
    start = _mm(c, ACTUAL_X)
    assert _mm(c, TARGET_X) == pytest.approx(start)  # not 0: where the axes stand
    assert not c.write_register(SPEED, 500, **DEV).isError()
    assert not c.write_registers(TARGET_X, _words(350_000), **DEV).isError()
    assert not c.write_register(COMMAND, 1, **DEV).isError()
    _wait_still(c)
    x, y, z = _mm(c, ACTUAL_X)
    assert x == pytest.approx(350.0, abs=0.002)
    assert (y, z) == pytest.approx(start[1:], abs=0.002)  # untouched, not driven to 0
    assert c.read_holding_registers(COMMAND, count=1, **DEV).registers[0] == 0  # taken


def test_targets_persist_across_connections(client) -> None:
    # mbpoll connects once per request: a target written by one connection must
    # still be there for the COMMAND 1 of the next.
    sim, c = client
    c.write_registers(TARGET_X + 2, _words(330_000), **DEV)
    c.close()
    other = ModbusTcpClient("127.0.0.1", port=sim.port, timeout=2.0)
    assert other.connect()
    try:
        assert not other.write_register(COMMAND, 1, **DEV).isError()
        _wait_still(other)
        assert _mm(other, ACTUAL_X)[1] == pytest.approx(330.0, abs=0.002)
    finally:
        other.close()


def test_a_target_outside_the_limits_is_refused_exception_3(client) -> None:
    sim, c = client
    rr = c.write_registers(TARGET_X, _words(0), **DEV)  # ρ = 0: far below 200.25
    assert rr.isError() and rr.exception_code == 3
    before = _mm(c, ACTUAL_X)
    # Targets stored while legal, then the limits shrink (a drive reconfigured):
    # COMMAND 1 checks the stored targets again and refuses; nothing moves.
    assert not c.write_registers(TARGET_X, _words(370_000), **DEV).isError()
    sim.soft_max = sim.soft_max - 60.0
    rr = c.write_register(COMMAND, 1, **DEV)
    assert rr.isError() and rr.exception_code == 3
    time.sleep(0.05)
    assert _mm(c, ACTUAL_X) == pytest.approx(before, abs=1e-6)
    assert sim.stats.commands.get(1, 0) == 0


@pytest.mark.parametrize("request_", [
    ("read_holding_registers", 5, {"count": 1}),     # a gap in the map
    ("read_holding_registers", 100, {"count": 2}),   # beyond its end
    ("read_holding_registers", 2, {"count": 10}),    # a block running into a gap
    ("write_register", 70, {"value": 1}),
    ("read_input_registers", 0, {"count": 1}),       # the map has no input registers
    ("read_coils", 0, {"count": 1}),
    ("write_coil", 0, {"value": True}),
], ids=lambda r: f"{r[0]}@{r[1]}")
def test_addresses_outside_the_map_answer_exception_2(client, request_) -> None:
    _sim, c = client
    name, address, kwargs = request_
    rr = getattr(c, name)(address, **kwargs, **DEV)
    assert rr.isError() and rr.exception_code == 2
