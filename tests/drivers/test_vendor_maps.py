"""Byte-exact RTU tests of the two shipped vendor maps, kinco-fd-cia402-modbus and
oriental-az-direct (the style of tests/drivers/test_axes_protocol.py: scripted request/reply
pairs, every pair used once, nothing left over).

The project's simulator serves the same map file the driver reads, so a wrong
address there is wrong in both and the simulated tests still pass. Here every
frame is built from the address the vendor (or code that drives the vendor's
drive) gives, written out below as a constant with its source, never from the map
file: a map address that disagrees fails the test.

Sources (cited per address at the constants):

Kinco FD series (CiA 402 objects over Modbus RTU, 32-bit objects low word first):
  [K1] Kinco, "Kinco FD5P AC series servo driver User Manual", 10.2.3 "MODBUS RTU
       communication protocol", printed pp. 132-133
       (https://www.easymanua.ls/kinco/fd5p-series/manual?p=139 and ?p=140): statusword
       60410010 read as "01 03 32 00 00 02 CA B3", controlword 60400010 written as
       "01 06 31 00 00 0F C7 32", 60FF0020 written as
       "01 10 6F 00 00 02 04 4E 82 00 1B ED 56" = 001B4E82h (low word first).
       Same manual pp. 129-130 (?p=136, ?p=137), RS232 examples: mode 6060h = 6 then
       controlword 0Fh, 1Fh to home, statusword bit 15 "home is found"; mode 1,
       controlword 2Fh then 3Fh for absolute positioning, bit 10 target reached.
  [K2] Kinco, "Kinco FD3&CD3 User Manual", 12.3 MODBUS RTU, printed pp. 118-119
       (https://www.easymanua.ls/kinco/cd3-series/manual?p=122, ?p=123): the same 3200h
       and 3100h frames and "01 10 6F 00 00 02 04 55 55 00 08 1A 47" = 00085555h.
  [K3] KincoNamespace.h, enum KINCO::register_map_enum of an open-source libmodbus
       driver for Kinco FD servos (KincoDriver.cpp beside it; the repository that
       hosts it was not identified): OPERATION_MODE 3500h, POS_ACTUAL 3700h,
       TARGET_POSITION 4000h, HOMING_OFFSET 4100h, SOFT_POSITIVE_LIMIT 4410h,
       SOFT_NEGATIVE_LIMIT 4420h, PROFILE_SPEED 4A00h, ERROR_STATE 1F00h; STATUS_BITS
       3 FAULT, 5 QUICK_STOP, 10 TARGET_REACHED, 15 REFERENCE_FOUND. No Kinco document
       with these addresses was found: they rest on that code alone.

Oriental Motor AZ series, direct data operation (32-bit data upper word first):
  [O1] Oriental Motor FAQ No. 331 (https://www.orientalmotor.eu/eu/support/faq/0331):
       the manual's register address is the address on the wire, upper word at the
       lower address: "01 10 18 02 00 02 04 FF FF FC 18 99 58" writes -1000.
  [O2] asukiaaa/arduino-OrientalAZ, src/OrientalAZ_asukiaaa.hpp (cites HM-60262E):
       direct data operation 0058h data No., 005Ah type (1 = absolute positioning),
       005Ch position, 005Eh speed, 0060h starting/changing rate, 0062h stopping
       deceleration, 0064h current, 0066h trigger (1 = all data updated); driver
       input command lower word 007Dh, bits 3 START, 4 ZHOME, 5 STOP, 6 FREE, 7 ALM-RST.
  [O3] yankailab/OpenKAI, src/Actuator/_OrientalMotor.cpp: FC 10h of 18 registers at
       88 (0058h) with type 1, current, trigger 1; feedback position read at 204
       (00CCh), upper word first; ALM-RST (1 << 7) written at 125 (007Dh).
  [O4] VJ_OrientalMaster.cpp, Arduino library for AZD-C(D) drives (repository not
       identified): driver input command written as (0, mask) from 007Ch; driver
       output status lower word 007Fh: READY 5, ALM-A 7, SYS-BSY 8, MOVE 13, IN-POS 14.
  [O5] an AZD-KD diagnostic script (minimalmodbus; repository not identified):
       PRESENT_ALARM 128 (0080h), two registers, upper word first; codes such as 4Ah.
  The manual itself (HM-60262E) was not read; no source was found for HOME-END at
  bit 4 of 007Fh (the map's assumption of the factory NET-OUT4 assignment).

Counts use the maps' stated scales (Kinco 2000 increments/mm and 32768 per mm/s;
Oriental 1000 steps/mm and 1000 Hz per mm/s), which are bench assumptions of the
maps, not vendor facts: a user's drive sets its own.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from pytest_mock import MockerFixture
from test_axes_protocol import (
    Pair,
    expected_protocol,
    read_req,
    read_rsp,
    rtu,
    write_multi_req,
    write_multi_rsp,
    write_single,
)

from drivers.device_errors import ControllerError

KINCO = "kinco-fd-cia402-modbus"
ORIENTAL = "oriental-az-direct"
AXIS_UNITS = (1, 2, 3)  # both maps: one drive per axis, station numbers X = 1, Y = 2, Z = 3

# --- Kinco FD: CiA 402 object -> Modbus address ---------------------------------------
K_CONTROLWORD = 0x3100  # 6040.00: [K1] 10.2.3 frame "01 06 31 00 00 0F"; [K2] 12.3
K_STATUSWORD = 0x3200  # 6041.00: [K1] 10.2.3 frame "01 03 32 00 00 02"; [K2] 12.3
K_MODE = 0x3500  # 6060.00 modes of operation: [K3] OPERATION_MODE only
K_POS_ACTUAL = 0x3700  # 6063.00 Pos_Actual: [K3] POS_ACTUAL only (6064h: no address found)
K_TARGET_POSITION = 0x4000  # 607A.00: [K3] TARGET_POSITION only
K_HOME_OFFSET = 0x4100  # 607C.00: [K3] HOMING_OFFSET only
K_SOFT_POSITIVE = 0x4410  # 607D, positive limit: [K3] SOFT_POSITIVE_LIMIT only
K_SOFT_NEGATIVE = 0x4420  # 607D, negative limit: [K3] SOFT_NEGATIVE_LIMIT only
K_PROFILE_SPEED = 0x4A00  # 6081.00: [K3] PROFILE_SPEED only
K_ERROR_STATE = 0x1F00  # 2601.00 Error_State: [K3] ERROR_STATE only (603Fh: no address found)

# --- Oriental AZ: register addresses (upper word of each 32-bit item) ---------------------
O_OPERATION_TYPE = 0x005A  # direct data operation type: [O2]; [O3] (88 + 2)
O_POSITION = 0x005C  # direct data position: [O2]; [O3] (92)
O_SPEED = 0x005E  # direct data operating speed: [O2]; [O3]
O_RATE = 0x0060  # direct data starting/changing rate: [O2]; [O3] (96)
O_STOP_RATE = 0x0062  # direct data stopping deceleration: [O2]; [O3]
O_CURRENT = 0x0064  # direct data operating current: [O2]; [O3]
O_TRIGGER = 0x0066  # direct data trigger: [O2]; [O3] (value 1 at 0067h)
O_INPUT_COMMAND = 0x007C  # driver input command, upper; lower 007Dh: [O2], [O3], [O4]
O_OUTPUT_STATUS_LOWER = 0x007F  # driver output status, lower word: [O4]
O_PRESENT_ALARM = 0x0080  # present alarm: [O5]
O_FEEDBACK_POSITION = 0x00CC  # feedback position: [O3] (204)

# Oriental NET-IN bits of the driver input command lower word: [O2], [O4]
O_ZHOME, O_STOP, O_ALM_RST = 1 << 4, 1 << 5, 1 << 7
# Oriental NET-OUT bits of 007Fh: READY, ALM-A, MOVE, IN-POS [O4]; HOME-END: no source
O_HOME_END, O_READY, O_ALM_A, O_MOVE, O_IN_POS = 1 << 4, 1 << 5, 1 << 7, 1 << 13, 1 << 14


# --- frames (built by the protocol tests' builders, independent of pymodbus and of
# drivers.registers; CRC and word order checked against the vendors' own frames below) ---


def low_first(value: int) -> bytes:
    """A 32-bit value as Kinco sends it: low word, then high word ([K1], [K2])."""
    u = value & 0xFFFF_FFFF
    return struct.pack(">HH", u & 0xFFFF, u >> 16)


def high_first(value: int) -> bytes:
    """A 32-bit value as Oriental sends it: upper word at the lower address ([O1])."""
    return struct.pack(">I", value & 0xFFFF_FFFF)


def echo(unit: int, pdu: bytes) -> Pair:
    """An FC 06 write: the drive answers with the request itself."""
    return rtu(unit, pdu), rtu(unit, pdu)


def multi(unit: int, address: int, payload: bytes) -> Pair:
    """An FC 10h write and the drive's acknowledgement of its register count."""
    return (rtu(unit, write_multi_req(address, payload)),
            rtu(unit, write_multi_rsp(address, len(payload) // 2)))


def read(unit: int, address: int, count: int, payload: bytes) -> Pair:
    return rtu(unit, read_req(address, count)), rtu(unit, read_rsp(payload))


def test_frames_reproduce_the_vendors_published_frames() -> None:
    # The CRC and the word orders checked against whole frames the vendors print.
    assert rtu(1, read_req(K_STATUSWORD, 2)) == bytes.fromhex("01 03 32 00 00 02 CA B3")
    assert rtu(1, write_single(K_CONTROLWORD, 0x0F)) == bytes.fromhex("01 06 31 00 00 0F C7 32")
    assert rtu(1, write_multi_req(0x6F00, low_first(0x001B4E82))) == bytes.fromhex(
        "01 10 6F 00 00 02 04 4E 82 00 1B ED 56")  # [K1]
    assert rtu(1, write_multi_req(0x6F00, low_first(0x00085555))) == bytes.fromhex(
        "01 10 6F 00 00 02 04 55 55 00 08 1A 47")  # [K2]
    assert rtu(1, write_multi_req(0x1802, high_first(-1000))) == bytes.fromhex(
        "01 10 18 02 00 02 04 FF FF FC 18 99 58")  # [O1]


# --- Kinco FD ----------------------------------------------------------------------------


K_READY = 0x0437  # ready, switched on, operation enabled, voltage, quick stop off, reached
K_HOMED = 1 << 15  # [K1] "bit15=1 indicates home is found"; [K3] REFERENCE_FOUND
K_FAULT = 1 << 3  # [K3] FAULT
K_REACHED = 1 << 10  # [K1] "bit10 indicates target position reached"; [K3]


def kinco_status(words: tuple[tuple[int, int], ...]) -> list[Pair]:
    """read_status on a drive per axis: Error_State, then the statusword, each drive."""
    pairs: list[Pair] = []
    for unit, (error, status) in zip(AXIS_UNITS, words, strict=True):
        pairs.append(read(unit, K_ERROR_STATE, 1, struct.pack(">H", error)))
        pairs.append(read(unit, K_STATUSWORD, 1, struct.pack(">H", status)))
    return pairs


def kinco_controlword(value: int) -> list[Pair]:
    return [echo(u, write_single(K_CONTROLWORD, value)) for u in AXIS_UNITS]


def kinco_mode(value: int) -> list[Pair]:
    return [echo(u, write_single(K_MODE, value)) for u in AXIS_UNITS]


def test_kinco_reads_each_axis_pos_actual(mocker: MockerFixture) -> None:
    pairs = [read(u, K_POS_ACTUAL, 2, low_first(c))
             for u, c in zip(AXIS_UNITS, (25000, -2, 400001), strict=True)]
    with expected_protocol(mocker, "rtu", pairs, profile=KINCO) as ctl:
        pos = ctl.read_positions()
    np.testing.assert_allclose(pos, [12.5, -0.001, 200.0005], atol=1e-12)


def test_kinco_move_writes_speed_targets_then_mode_and_new_setpoint_edge(
        mocker: MockerFixture) -> None:
    pairs = [multi(u, K_PROFILE_SPEED, low_first(81920)) for u in AXIS_UNITS]  # 2.5 mm/s
    pairs += [multi(u, K_TARGET_POSITION, low_first(c))
              for u, c in zip(AXIS_UNITS, (25000, 200000, -6500), strict=True)]
    # [K1]: profile position is mode 1, then 2Fh -> 3Fh starts the absolute move
    pairs += kinco_mode(1) + kinco_controlword(0x2F) + kinco_controlword(0x3F)
    with expected_protocol(mocker, "rtu", pairs, profile=KINCO) as ctl:
        ctl.move([12.5, 100.0, -3.25], speed_mm_s=2.5)


def test_kinco_stop_sets_the_halt_bit(mocker: MockerFixture) -> None:
    # 10Fh = enable operation (0Fh) + bit 8 halt: CiA 402, not found in a Kinco document
    with expected_protocol(mocker, "rtu", kinco_controlword(0x10F), profile=KINCO) as ctl:
        ctl.stop()


def test_kinco_status_decodes_statusword_and_error_state(mocker: MockerFixture) -> None:
    pairs = kinco_status(((0, K_READY | K_HOMED),
                          (0x0002, K_READY | K_FAULT),  # Y faulted, not homed
                          (0, (K_READY | K_HOMED) & ~K_REACHED)))  # Z still moving
    with expected_protocol(mocker, "rtu", pairs, profile=KINCO) as ctl:
        st = ctl.read_status()
    assert (st.homed, st.moving, st.in_position, st.alarm, st.estop) == (
        False, True, False, True, False)
    assert st.alarm_code == 2


def test_kinco_home_and_reset_alarm_sequences(mocker: MockerFixture) -> None:
    settled = ((0, K_READY | K_HOMED),) * 3
    # [K1]: homing is mode 6, then controlword 0Fh -> 1Fh
    pairs = kinco_mode(6) + kinco_controlword(0x0F) + kinco_controlword(0x1F)
    pairs += kinco_status(settled)
    # fault reset (80h), shutdown (06h), enable operation (0Fh): CiA 402 and [K3]
    pairs += kinco_controlword(0x80) + kinco_controlword(0x06) + kinco_controlword(0x0F)
    pairs += kinco_status(settled)
    with expected_protocol(mocker, "rtu", pairs, profile=KINCO) as ctl:
        ctl.home(timeout_s=5.0)
        ctl.reset_alarm()


def test_kinco_home_offset_is_only_read_and_offsets_are_refused(
        mocker: MockerFixture) -> None:
    # 607Ch acts only after the next homing: the map reads it (probe shows it) and
    # refuses offsets without a single write on the wire.
    pairs = [read(1, K_HOME_OFFSET, 2, low_first(-4000))]
    with expected_protocol(mocker, "rtu", pairs, profile=KINCO) as ctl:
        assert ctl.read_raw("HOME_OFFSET_X") == -4000
        with pytest.raises(ControllerError, match="607Ch"):
            ctl.write_offsets([0.01, 0.0, 0.0])
        with pytest.raises(ControllerError, match="607Ch"):
            ctl.read_offsets()


def test_kinco_soft_limits_read_positive_and_negative_limit(mocker: MockerFixture) -> None:
    pairs: list[Pair] = []
    for u, (lo, hi) in zip(AXIS_UNITS, ((-2000, 400000), (0, 390000), (-1, 380000)),
                           strict=True):
        pairs.append(read(u, K_SOFT_POSITIVE, 2, low_first(hi)))
        pairs.append(read(u, K_SOFT_NEGATIVE, 2, low_first(lo)))
    with expected_protocol(mocker, "rtu", pairs, profile=KINCO) as ctl:
        lo, hi = ctl.soft_limits()
    np.testing.assert_allclose(lo, [-1.0, 0.0, -0.0005], atol=1e-12)
    np.testing.assert_allclose(hi, [200.0, 195.0, 190.0], atol=1e-12)


# --- Oriental AZ ---------------------------------------------------------------------------


def oriental_status(words: tuple[tuple[int, int], ...]) -> list[Pair]:
    """One read per drive: output status lower word 007Fh and the present alarm
    0080h/0081h right after it."""
    return [read(u, O_OUTPUT_STATUS_LOWER, 3, struct.pack(">H", status) + high_first(alarm))
            for u, (status, alarm) in zip(AXIS_UNITS, words, strict=True)]


def oriental_input(value: int) -> list[Pair]:
    """A NET-IN bit on, then off: (0, mask) from 007Ch as [O4] writes it."""
    return [multi(u, O_INPUT_COMMAND, high_first(v)) for v in (value, 0) for u in AXIS_UNITS]


def test_oriental_reads_each_axis_feedback_position(mocker: MockerFixture) -> None:
    pairs = [read(u, O_FEEDBACK_POSITION, 2, high_first(c))
             for u, c in zip(AXIS_UNITS, (12500, -1, 200000), strict=True)]
    with expected_protocol(mocker, "rtu", pairs, profile=ORIENTAL) as ctl:
        pos = ctl.read_positions()
    np.testing.assert_allclose(pos, [12.5, -0.001, 200.0], atol=1e-12)


def test_oriental_move_writes_direct_data_then_trigger(mocker: MockerFixture) -> None:
    pairs = [multi(u, O_SPEED, high_first(10000)) for u in AXIS_UNITS]  # 10 mm/s
    pairs += [multi(u, O_POSITION, high_first(c))
              for u, c in zip(AXIS_UNITS, (12500, 100000, -3250), strict=True)]
    for u in AXIS_UNITS:
        pairs += [multi(u, O_OPERATION_TYPE, high_first(1)),  # absolute positioning [O2]
                  multi(u, O_RATE, high_first(1_000_000)),
                  multi(u, O_STOP_RATE, high_first(1_000_000)),
                  multi(u, O_CURRENT, high_first(1000))]  # 100.0 %
    pairs += [multi(u, O_TRIGGER, high_first(1)) for u in AXIS_UNITS]  # all data updated
    with expected_protocol(mocker, "rtu", pairs, profile=ORIENTAL) as ctl:
        ctl.move([12.5, 100.0, -3.25], speed_mm_s=10.0)


def test_oriental_stop_pulses_the_stop_input(mocker: MockerFixture) -> None:
    with expected_protocol(mocker, "rtu", oriental_input(O_STOP), profile=ORIENTAL) as ctl:
        ctl.stop()


def test_oriental_status_is_one_read_of_output_status_and_present_alarm(
        mocker: MockerFixture) -> None:
    pairs = oriental_status(((O_IN_POS | O_READY | O_HOME_END, 0),
                             (O_IN_POS | O_ALM_A | O_READY | O_HOME_END, 0x4A),
                             (O_MOVE | O_READY | O_HOME_END, 0)))
    with expected_protocol(mocker, "rtu", pairs, profile=ORIENTAL) as ctl:
        st = ctl.read_status()
    assert (st.homed, st.moving, st.in_position, st.alarm, st.estop) == (
        True, True, False, True, False)
    assert st.alarm_code == 0x4A  # return-to-home incomplete


def test_oriental_home_and_reset_alarm_pulse_their_inputs(mocker: MockerFixture) -> None:
    settled = ((O_IN_POS | O_READY | O_HOME_END, 0),) * 3
    pairs = oriental_input(O_ZHOME) + oriental_status(settled)
    pairs += oriental_input(O_ALM_RST) + oriental_status(settled)
    with expected_protocol(mocker, "rtu", pairs, profile=ORIENTAL) as ctl:
        ctl.home(timeout_s=5.0)
        ctl.reset_alarm()


def test_oriental_refuses_offsets_and_has_no_soft_limits(mocker: MockerFixture) -> None:
    # No live zero-offset register: refused without a request on the wire.
    with expected_protocol(mocker, "rtu", [], profile=ORIENTAL) as ctl:
        with pytest.raises(ControllerError, match="no live home/zero-offset register"):
            ctl.write_offsets([0.01, 0.0, 0.0])
        with pytest.raises(ControllerError, match="no live home/zero-offset register"):
            ctl.read_offsets()
        limits = ctl.soft_limits()
    lower, upper = limits
    assert not limits.usable and np.all(np.isnan(lower)) and np.all(np.isnan(upper))
    assert "Software overtravel" in limits.reason
