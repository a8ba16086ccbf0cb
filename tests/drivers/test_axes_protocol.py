"""Byte-exact protocol tests of ModbusAxisController (pymeasure ``expected_protocol``
style): the transport under pymodbus is replaced by a scripted fake given
(request bytes, reply bytes) pairs. pymodbus's real framers build and parse the
frames; every pair must be used in order and no byte may be left over.

Frames are written out by hand here (MBAP header / RTU with a CRC computed by an
independent bitwise implementation), not produced by the code under test.
"""

from __future__ import annotations

import contextlib
import struct
from collections.abc import Iterator, Sequence

import numpy as np
import pytest
import wire
from pytest_mock import MockerFixture
from wire import ScriptedSerial, ScriptedSocket

from drivers.axes import ModbusAxisController
from drivers.device_errors import (
    ControllerBusy,
    ControllerError,
    ControllerTimeout,
    ExceptionResponse,
    ReadbackMismatch,
    TargetRefused,
)

Pair = tuple[bytes, bytes | None]  # (request, reply or None = no reply)


# --- frame builders (independent of pymodbus and of drivers.registers) ---------------


def crc16(frame: bytes) -> bytes:
    crc = 0xFFFF
    for byte in frame:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return struct.pack("<H", crc)  # low byte first on the wire


def rtu(unit: int, pdu: bytes) -> bytes:
    body = bytes([unit]) + pdu
    return body + crc16(body)


def mbap(tid: int, unit: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


def i32_words(um: int) -> bytes:
    return struct.pack(">i", um)  # two's complement, high word first


def read_req(address: int, count: int) -> bytes:
    return struct.pack(">BHH", 3, address, count)


def read_rsp(payload: bytes) -> bytes:
    return bytes([3, len(payload)]) + payload


def write_multi_req(address: int, payload: bytes) -> bytes:
    return struct.pack(">BHHB", 16, address, len(payload) // 2, len(payload)) + payload


def write_multi_rsp(address: int, count: int) -> bytes:
    return struct.pack(">BHH", 16, address, count)


def write_single(address: int, value: int) -> bytes:
    return struct.pack(">BHH", 6, address, value)  # request and echo are identical


def write_coil(address: int, on: bool) -> bytes:
    return struct.pack(">BHH", 5, address, 0xFF00 if on else 0)


def exception(fc: int, code: int) -> bytes:
    return bytes([fc | 0x80, code])


# --- scripted transports ---------------------------------------------------------------------


@contextlib.contextmanager
def expected_protocol(mocker: MockerFixture, transport: str, pairs: Sequence[Pair],
                      **kwargs: object) -> Iterator[ModbusAxisController]:
    """A connected controller whose wire is ``pairs`` (tests/helpers/wire.py); checks all
    used, none left."""
    fake: ScriptedSocket | ScriptedSerial
    if transport == "tcp":
        fake = ScriptedSocket(pairs)
        mocker.patch("pymodbus.client.tcp.socket.create_connection", return_value=fake)
        port: int | str = 5020
    else:
        fake = ScriptedSerial(pairs)
        mocker.patch("pymodbus.client.serial.serial.serial_for_url", return_value=fake)
        port = "/dev/ttyFAKE0"
    options: dict = {"timeout_s": 0.05, "retries": 2, "baudrate": 115200, **kwargs}

    def connected() -> ModbusAxisController:
        ctl = ModbusAxisController(transport=transport, host="10.0.0.7", port=port, **options)
        ctl.connect()
        return ctl

    with wire.expected_protocol(fake, connected, ModbusAxisController.close) as ctl:
        yield ctl


POS_UM = (310250, -1, 200251)
POS_PAYLOAD = b"".join(i32_words(v) for v in POS_UM)
#: STATUS and ALARM_CODE of a drive that is homed and in position, no alarm
HOMED_STATUS = struct.pack(">HH", 0b00101, 0)


# --- Modbus TCP ------------------------------------------------------------------------------


def test_tcp_read_positions_is_one_block_read(mocker: MockerFixture) -> None:
    request = bytes.fromhex("00 01 00 00 00 06 01 03 00 14 00 06")
    assert mbap(1, 1, read_req(20, 6)) == request  # the builder agrees with the spec
    pairs = [(request, mbap(1, 1, read_rsp(POS_PAYLOAD)))]
    with expected_protocol(mocker, "tcp", pairs) as ctl:
        pos = ctl.read_positions()
    np.testing.assert_allclose(pos, [310.25, -0.001, 200.251], atol=1e-12)


def test_tcp_read_status_is_one_read_of_status_and_alarm_code(mocker: MockerFixture) -> None:
    pairs = [(mbap(1, 7, read_req(1, 2)), mbap(1, 7, read_rsp(struct.pack(">HH", 0b01001, 17))))]
    with expected_protocol(mocker, "tcp", pairs, device_id=7) as ctl:
        st = ctl.read_status()
    assert (st.homed, st.moving, st.in_position, st.alarm, st.estop) == (
        True, False, False, True, False)
    assert st.alarm_code == 17


def test_tcp_move_writes_speed_targets_then_command(mocker: MockerFixture) -> None:
    targets = b"".join(i32_words(v) for v in (370250, 293685, 293685))
    pairs = [
        (mbap(1, 1, write_single(40, 25)), mbap(1, 1, write_single(40, 25))),
        (mbap(2, 1, write_multi_req(10, targets)), mbap(2, 1, write_multi_rsp(10, 6))),
        (mbap(3, 1, write_single(0, 1)), mbap(3, 1, write_single(0, 1))),
    ]
    with expected_protocol(mocker, "tcp", pairs) as ctl:
        ctl.move([370.25, 293.6846, 293.6854], speed_mm_s=25)  # rounded, not truncated


def test_tcp_speed_is_written_once_while_it_does_not_change(mocker: MockerFixture) -> None:
    # a request per move saved: the same speed twice is written once, a new one again
    targets = b"".join(i32_words(v) for v in (370250, 293685, 293685))
    pairs = [
        (mbap(1, 1, write_single(40, 25)), mbap(1, 1, write_single(40, 25))),
        (mbap(2, 1, write_multi_req(10, targets)), mbap(2, 1, write_multi_rsp(10, 6))),
        (mbap(3, 1, write_single(0, 1)), mbap(3, 1, write_single(0, 1))),
        (mbap(4, 1, write_multi_req(10, targets)), mbap(4, 1, write_multi_rsp(10, 6))),
        (mbap(5, 1, write_single(0, 1)), mbap(5, 1, write_single(0, 1))),
        (mbap(6, 1, write_single(40, 13)), mbap(6, 1, write_single(40, 13))),  # rounded
        (mbap(7, 1, write_multi_req(10, targets)), mbap(7, 1, write_multi_rsp(10, 6))),
        (mbap(8, 1, write_single(0, 1)), mbap(8, 1, write_single(0, 1))),
    ]
    with expected_protocol(mocker, "tcp", pairs) as ctl:
        for speed in (25, 25, 12.5):
            ctl.move([370.25, 293.6846, 293.6854], speed_mm_s=speed)


def test_tcp_write_offsets_reads_back(mocker: MockerFixture) -> None:
    offsets = b"".join(i32_words(v) for v in (-480, 490, -1670))
    pairs = [
        (mbap(1, 1, write_multi_req(30, offsets)), mbap(1, 1, write_multi_rsp(30, 6))),
        (mbap(2, 1, read_req(30, 6)), mbap(2, 1, read_rsp(offsets))),
    ]
    with expected_protocol(mocker, "tcp", pairs) as ctl:
        back = ctl.write_offsets([-0.48, 0.49, -1.67])
    np.testing.assert_allclose(back, [-0.48, 0.49, -1.67], atol=1e-12)


def test_tcp_offsets_readback_mismatch(mocker: MockerFixture) -> None:
    offsets = b"".join(i32_words(v) for v in (-480, 490, -1670))
    clamped = b"".join(i32_words(v) for v in (-480, 490, -1000))
    pairs = [
        (mbap(1, 1, write_multi_req(30, offsets)), mbap(1, 1, write_multi_rsp(30, 6))),
        (mbap(2, 1, read_req(30, 6)), mbap(2, 1, read_rsp(clamped))),
    ]
    with (expected_protocol(mocker, "tcp", pairs) as ctl,
          pytest.raises(ReadbackMismatch, match=r"-1\.000")):
        ctl.write_offsets([-0.48, 0.49, -1.67])


def test_tcp_exception_3_on_targets_is_target_refused(mocker: MockerFixture) -> None:
    targets = b"".join(i32_words(v) for v in (400000, 310250, 310250))
    pairs = [(mbap(1, 1, write_multi_req(10, targets)), mbap(1, 1, exception(16, 3)))]
    with expected_protocol(mocker, "tcp", pairs) as ctl, \
            pytest.raises(TargetRefused) as info:
        ctl.move([400, 310.25, 310.25])  # no COMMAND may follow a refused target
    assert info.value.code == 3
    assert "10.0.0.7:5020" in str(info.value) and "400.000" in str(info.value)


def test_tcp_exception_6_is_retried_and_reported(mocker: MockerFixture) -> None:
    events: list[dict] = []
    pairs = [
        (mbap(1, 1, read_req(20, 6)), mbap(1, 1, exception(3, 6))),
        (mbap(2, 1, read_req(20, 6)), mbap(2, 1, read_rsp(POS_PAYLOAD))),
    ]
    with expected_protocol(mocker, "tcp", pairs, on_event=events.append,
                           busy_backoff_s=0.0) as ctl:
        pos = ctl.read_positions()
    assert pos[0] == pytest.approx(310.25, abs=1e-12)
    assert [(e["event"], e["op"], e["attempt"]) for e in events] == [
        ("retry", "read positions", 1)]
    assert "exception 6" in events[0]["error"] and events[0]["device"].endswith("10.0.0.7:5020")


def test_tcp_busy_beyond_retries_is_controller_busy(mocker: MockerFixture) -> None:
    pairs = [(mbap(t, 1, read_req(20, 6)), mbap(t, 1, exception(3, 6))) for t in (1, 2, 3)]
    with expected_protocol(mocker, "tcp", pairs, busy_backoff_s=0.0) as ctl, \
            pytest.raises(ControllerBusy, match="3 attempt"):
        ctl.read_positions()


def test_tcp_other_exception_is_not_retried(mocker: MockerFixture) -> None:
    pairs = [(mbap(1, 1, read_req(20, 6)), mbap(1, 1, exception(3, 2)))]
    with expected_protocol(mocker, "tcp", pairs) as ctl, \
            pytest.raises(ExceptionResponse) as info:
        ctl.read_positions()
    assert info.value.code == 2 and not isinstance(info.value, TargetRefused)


def test_tcp_malformed_reply_is_retried(mocker: MockerFixture) -> None:
    events: list[dict] = []
    bad = bytearray(mbap(1, 1, read_rsp(POS_PAYLOAD)))
    bad[2:4] = b"\xde\xad"  # protocol id must be 0
    pairs = [
        (mbap(1, 1, read_req(20, 6)), bytes(bad)),
        (mbap(2, 1, read_req(20, 6)), mbap(2, 1, read_rsp(POS_PAYLOAD))),
        # answered only on a retry: the drive may have restarted meanwhile, so its
        # STATUS is read before the answer counts (HOMED set: it does)
        (mbap(3, 1, read_req(1, 2)), mbap(3, 1, read_rsp(HOMED_STATUS))),
    ]
    with expected_protocol(mocker, "tcp", pairs, on_event=events.append) as ctl:
        ctl.read_positions()
    assert [e["event"] for e in events] == ["retry", "reference-check"]
    assert events[0]["op"] == "read positions" and events[1]["lost"] is False


def test_tcp_wrong_function_in_reply_is_not_trusted(mocker: MockerFixture) -> None:
    pairs = [
        (mbap(1, 1, read_req(20, 6)), mbap(1, 1, bytes([4, 12]) + POS_PAYLOAD)),
        (mbap(2, 1, read_req(20, 6)), mbap(2, 1, read_rsp(POS_PAYLOAD))),
        (mbap(3, 1, read_req(1, 2)), mbap(3, 1, read_rsp(HOMED_STATUS))),
    ]
    with expected_protocol(mocker, "tcp", pairs) as ctl:
        ctl.read_positions()


def test_tcp_no_reply_times_out_after_bounded_retries(mocker: MockerFixture) -> None:
    events: list[dict] = []
    pairs: list[Pair] = [(mbap(t, 1, read_req(20, 6)), None) for t in (1, 2, 3)]
    with expected_protocol(mocker, "tcp", pairs, on_event=events.append) as ctl, \
            pytest.raises(ControllerTimeout, match="3 attempt"):
        ctl.read_positions()
    assert [e["attempt"] for e in events] == [1, 2]


# --- Modbus RTU ------------------------------------------------------------------------------


def test_rtu_read_positions_frame_with_crc(mocker: MockerFixture) -> None:
    request = rtu(1, read_req(20, 6))
    assert request.hex(" ") == "01 03 00 14 00 06 " + crc16(request[:-2]).hex(" ")
    pairs = [(request, rtu(1, read_rsp(POS_PAYLOAD)))]
    with expected_protocol(mocker, "rtu", pairs) as ctl:
        pos = ctl.read_positions()
    np.testing.assert_allclose(pos, [310.25, -0.001, 200.251], atol=1e-12)


def test_rtu_crc_of_a_known_frame() -> None:
    # The test's own CRC against published vectors (Modbus spec example; IAI's
    # manual: "01 05 04 17 FF 00 3D 0E" for a jog coil).
    assert crc16(bytes.fromhex("01 05 04 17 FF 00")) == bytes.fromhex("3D 0E")
    assert crc16(bytes.fromhex("01 03 00 00 00 0A")) == bytes.fromhex("C5 CD")


def test_rtu_garbled_reply_is_retried(mocker: MockerFixture) -> None:
    events: list[dict] = []
    good = rtu(1, read_rsp(POS_PAYLOAD))
    garbled = good[:-1] + bytes([good[-1] ^ 0xFF])  # bad CRC
    pairs = [(rtu(1, read_req(20, 6)), garbled), (rtu(1, read_req(20, 6)), good),
             (rtu(1, read_req(1, 2)), rtu(1, read_rsp(HOMED_STATUS)))]
    with expected_protocol(mocker, "rtu", pairs, on_event=events.append) as ctl:
        pos = ctl.read_positions()
    assert pos[2] == pytest.approx(200.251, abs=1e-12)
    assert [(e["event"], e.get("op"), e.get("attempt")) for e in events] == [
        ("retry", "read positions", 1), ("reference-check", None, None)]


def test_rtu_move_and_exception_3(mocker: MockerFixture) -> None:
    ok = b"".join(i32_words(v) for v in (250000, 260000, 270000))
    bad = b"".join(i32_words(v) for v in (100000, 260000, 270000))
    pairs = [
        (rtu(2, write_multi_req(10, ok)), rtu(2, write_multi_rsp(10, 6))),
        (rtu(2, write_single(0, 1)), rtu(2, write_single(0, 1))),
        (rtu(2, write_multi_req(10, bad)), rtu(2, exception(16, 3))),
    ]
    with expected_protocol(mocker, "rtu", pairs, device_id=2) as ctl:
        ctl.move([250, 260, 270])
        with pytest.raises(TargetRefused):
            ctl.move([100, 260, 270])


def test_rtu_busy_then_success(mocker: MockerFixture) -> None:
    offsets = b"".join(i32_words(v) for v in (1, -2, 3))
    pairs = [
        (rtu(1, write_multi_req(30, offsets)), rtu(1, exception(16, 6))),
        (rtu(1, write_multi_req(30, offsets)), rtu(1, write_multi_rsp(30, 6))),
        (rtu(1, read_req(30, 6)), rtu(1, read_rsp(offsets))),
    ]
    with expected_protocol(mocker, "rtu", pairs, busy_backoff_s=0.0) as ctl:
        back = ctl.write_offsets([0.001, -0.002, 0.003])
    np.testing.assert_allclose(back, [0.001, -0.002, 0.003], atol=1e-12)


# --- a drive with one device per axis and coils (IAI PCON direct numeric) -----------------


def test_iai_profile_reads_each_axis_device(mocker: MockerFixture) -> None:
    pairs = [(rtu(d, read_req(0x9000, 2)), rtu(d, read_rsp(struct.pack(">i", v))))
             for d, v in ((1, 12345), (2, -50), (3, 0))]
    with expected_protocol(mocker, "rtu", pairs, profile="iai-pcon-direct") as ctl:
        pos = ctl.read_positions()
    np.testing.assert_allclose(pos, [123.45, -0.5, 0.0], atol=1e-12)


def test_iai_profile_move_stop_and_no_offsets(mocker: MockerFixture) -> None:
    pairs = []
    for d, v in ((1, 5000), (2, 6000), (3, 7000)):
        frame = write_multi_req(0x9900, struct.pack(">i", v))
        pairs.append((rtu(d, frame), rtu(d, write_multi_rsp(0x9900, 2))))
    for d in (1, 2, 3):
        pairs.append((rtu(d, write_coil(0x042C, True)), rtu(d, write_coil(0x042C, True))))
    with expected_protocol(mocker, "rtu", pairs, profile="iai-pcon-direct",
                           soft_limits=([0, 0, 0], [100, 100, 100])) as ctl:
        ctl.move([50, 60, 70])  # PCMD starts the move: no command follows
        ctl.stop()
        with pytest.raises(TargetRefused):
            ctl.move([50, 60, 170])  # checked locally: the drive would clamp, not refuse
        with pytest.raises(ControllerError, match="no Modbus-writable zero offset"):
            ctl.read_offsets()
        with pytest.raises(ControllerError, match="zero offset"):
            ctl.write_offsets([0, 0, 0])
        lo, hi = ctl.soft_limits()
        assert (list(lo), list(hi)) == ([0, 0, 0], [100, 100, 100])
