"""Byte-exact tests of the indicator driver against a scripted serial port.

In the style of pymeasure's ``expected_protocol``: the fake port is given the
conversation as (bytes the driver must send, bytes the gauge answers) pairs;
every pair must be used, in order, and no byte may be left unread.
"""

from __future__ import annotations

import termios
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
import serial
import wire
from wire import Pair, ScriptedSerial

from drivers.base import Indicator
from drivers.device_errors import (
    IndicatorError,
    IndicatorPortError,
    IndicatorReplyError,
    IndicatorTimeout,
)
from drivers.indicator_protocols import BUILTIN_PROTOCOLS, IndicatorProtocol, make_protocol
from drivers.indicators import IndicatorGroup, SerialIndicator

PORT = "/dev/ttyFAKE0"


FakeSerial = ScriptedSerial  # tests/helpers/wire.py: the one scripted wire of every byte-exact test


@contextmanager
def expected_protocol(
    mocker: Any,
    protocol: IndicatorProtocol | str,
    pairs: Sequence[Pair],
    *,
    chunk: int = 0,
    **kwargs: Any,
) -> Iterator[tuple[SerialIndicator, list[dict[str, Any]]]]:
    fake = FakeSerial(pairs, chunk=chunk)
    factory = mocker.Mock(return_value=fake)
    events: list[dict[str, Any]] = []

    def opened() -> SerialIndicator:
        ind = SerialIndicator(
            "A", PORT, protocol, serial_factory=factory, on_event=events.append, **kwargs
        )
        proto = ind.protocol
        factory.assert_called_once_with(
            PORT,
            baudrate=proto.baudrate,
            bytesize=proto.bytesize,
            parity=proto.parity,
            stopbits=proto.stopbits,
            timeout=ind.timeout_s,
            write_timeout=ind.timeout_s,
        )
        return ind

    with wire.expected_protocol(fake, opened, SerialIndicator.close) as ind:
        yield ind, events
    assert fake.closed


# Per protocol: request, good replies with their exact value, a garbled and a
# partial reply, and the gauge's error reply with its code (None if it has none).
CASES: dict[str, dict[str, Any]] = {
    "mitutoyo": {
        "request": b"1\r",
        "good": [
            (b"01A+0000.123\r", 0.123),
            (b"01A-0012.345\r", -12.345),
            (b"01A+0000.000\r", 0.0),
            (b"01A-0000.001\r", -0.001),
        ],
        "garbled": b"01A+00#0.123\r",
        "partial": b"01A+000",
        "error": (b"91\r", "1"),
    },
    "sylvac": {
        "request": b"?\r",
        "good": [
            (b"+0.0123\r", 0.0123),
            (b"-1.2500\r", -1.25),
            (b"+0.0000\r", 0.0),
            (b"-12.3456\r", -12.3456),
        ],
        "garbled": b"+0.01%3\r",
        "partial": b"+0.01",
        "error": (b"ERR7\r", "7"),
    },
    "mahr": {
        "request": b"?\r",
        "good": [
            (b"0.0123 mm\r\n", 0.0123),
            (b"-3.5000 mm\r\n", -3.5),
            (b"0.0000 mm\r\n", 0.0),
            (b"12.0010 mm\r\n", 12.001),
        ],
        "garbled": b"0.0123 #m\r\n",
        "partial": b"0.0123 mm\r",  # the \n of its two-byte terminator never came
        "error": None,
    },
    "generic": {
        "request": b"?\r",
        "good": [(b"+0.0123\r", 0.0123), (b"-2.5\r", -2.5), (b"0\r", 0.0), (b" 1.5 mm\r", 1.5)],
        "garbled": b"+0.0@23\r",
        "partial": b"+0.01",
        "error": None,
    },
}
NAMES = sorted(CASES)


def test_cases_cover_every_builtin() -> None:
    assert set(CASES) == set(BUILTIN_PROTOCOLS)


@pytest.mark.parametrize(
    ("name", "baud", "bytesize", "parity", "stopbits", "bits"),
    [
        ("mitutoyo", 9600, 8, "N", 1, 10),
        ("sylvac", 4800, 7, "E", 2, 11),
        ("mahr", 9600, 7, "E", 2, 11),
        ("generic", 9600, 8, "N", 1, 10),
    ],
)
def test_line_settings(
    name: str, baud: int, bytesize: int, parity: str, stopbits: int, bits: int
) -> None:
    p = make_protocol(name)
    assert (p.baudrate, p.bytesize, p.parity, p.stopbits) == (baud, bytesize, parity, stopbits)
    assert p.bits_per_char == bits


@pytest.mark.parametrize("name", NAMES)
def test_good_replies(mocker: Any, name: str) -> None:
    case = CASES[name]
    pairs = [(case["request"], reply) for reply, _ in case["good"]]
    with expected_protocol(mocker, name, pairs) as (ind, events):
        assert isinstance(ind, Indicator)
        for _, value in case["good"]:
            assert ind.read() == value
    assert events == []


@pytest.mark.parametrize("name", NAMES)
def test_reply_arriving_byte_by_byte(mocker: Any, name: str) -> None:
    case = CASES[name]
    reply, value = case["good"][0]
    with expected_protocol(mocker, name, [(case["request"], reply)], chunk=1) as (ind, _):
        assert ind.read() == value


@pytest.mark.parametrize("name", NAMES)
def test_stale_input_is_discarded_before_the_request(mocker: Any, name: str) -> None:
    case = CASES[name]
    (stale, _), (fresh, value) = case["good"][:2]
    fake = FakeSerial([(None, stale), (case["request"], fresh)])
    ind = SerialIndicator("A", PORT, name, serial_factory=mocker.Mock(return_value=fake))
    assert ind.read() == value
    assert bytes(fake.flushed) == stale
    assert not fake.pairs and not fake.rx
    ind.close()


@pytest.mark.parametrize("name", NAMES)
def test_read_n(mocker: Any, name: str) -> None:
    case = CASES[name]
    pairs = [(case["request"], reply) for reply, _ in case["good"][:3]]
    with expected_protocol(mocker, name, pairs) as (ind, _):
        assert ind.read_n(3) == [v for _, v in case["good"][:3]]
        assert ind.read_n(0) == []


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("kind", ["garbled", "partial", "missing", "error"])
def test_one_bad_reply_is_retried_and_reported(mocker: Any, name: str, kind: str) -> None:
    case = CASES[name]
    terminator = make_protocol(name).terminator
    if kind == "error":
        # A gauge without an error grammar: its error line is just not a value.
        bad = case["error"][0] if case["error"] else b"E1" + terminator
    else:
        bad = {"garbled": case["garbled"], "partial": case["partial"], "missing": b""}[kind]
    reply, value = case["good"][0]
    req = case["request"]
    with expected_protocol(mocker, name, [(req, bad), (req, reply)]) as (ind, events):
        assert ind.read() == value
    assert len(events) == 1
    ev = events[0]
    assert ev["event"] == "retry"
    assert ev["device"] == f"indicator A ({PORT})"
    assert ev["attempt"] == 1
    expected_words = {
        "garbled": "garbled",
        "partial": "partial",
        "missing": "no reply",
        "error": "gauge error" if case["error"] else "garbled",
    }[kind]
    assert expected_words in ev["error"]


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(
    ("kind", "error_type", "words"),
    [
        ("garbled", IndicatorReplyError, "garbled reply"),
        ("partial", IndicatorTimeout, "partial reply"),
        ("missing", IndicatorTimeout, "no reply"),
    ],
)
def test_persistent_bad_replies_raise_typed_error_naming_indicator_and_port(
    mocker: Any, name: str, kind: str, error_type: type[IndicatorError], words: str
) -> None:
    case = CASES[name]
    bad = {"garbled": case["garbled"], "partial": case["partial"], "missing": b""}[kind]
    pairs = [(case["request"], bad)] * 4
    with expected_protocol(mocker, name, pairs, retries=3) as (ind, events):
        with pytest.raises(error_type) as info:
            ind.read()
    err = info.value
    assert err.device == f"indicator A ({PORT})"
    assert "A" in str(err) and PORT in str(err)
    assert words in str(err) and "4 attempt" in str(err)
    assert [e["attempt"] for e in events] == [1, 2, 3]
    assert err.transient


@pytest.mark.parametrize("name", ["mitutoyo", "sylvac"])
def test_gauge_error_replies_carry_the_code(mocker: Any, name: str) -> None:
    case = CASES[name]
    reply, code = case["error"]
    with expected_protocol(mocker, name, [(case["request"], reply)] * 3, retries=2) as (
        ind,
        events,
    ):
        with pytest.raises(IndicatorReplyError) as info:
            ind.read()
    assert f"gauge error {code}" in str(info.value)
    assert PORT in str(info.value)
    assert len(events) == 2


def test_mitutoyo_any_line_starting_with_9_is_an_error(mocker: Any) -> None:
    with expected_protocol(mocker, "mitutoyo", [(b"1\r", b"92 OVER\r")], retries=0) as (
        ind,
        events,
    ):
        with pytest.raises(IndicatorReplyError, match="gauge error 2"):
            ind.read()
    assert events == []  # retries=0: nothing retried, nothing reported


@pytest.mark.parametrize(
    "reply",
    [b"\xff\xfe\r", b"01A+0000.123 \r", b"01A0000.123\r", b"01A+0000\r", b"\r", b"01B+0000.123\r"],
)
def test_mitutoyo_rejects_what_is_not_its_grammar(mocker: Any, reply: bytes) -> None:
    with expected_protocol(mocker, "mitutoyo", [(b"1\r", reply)], retries=0) as (ind, _):
        with pytest.raises(IndicatorReplyError, match="garbled"):
            ind.read()


def test_babbling_line_without_terminator_is_garbled(mocker: Any) -> None:
    with expected_protocol(mocker, "sylvac", [(b"?\r", b"+" * 300)], retries=0) as (ind, _):
        with pytest.raises(IndicatorReplyError, match="garbled"):
            ind.read()


def test_port_that_fails_is_reopened_by_its_path_and_the_reading_goes_on(mocker: Any) -> None:
    dead = FakeSerial([])
    mocker.patch.object(dead, "write", side_effect=serial.SerialException("write failed: EIO"))
    alive = FakeSerial([(b"1\r", b"01A+0001.000\r")])
    factory = mocker.Mock(side_effect=[dead, alive])
    events: list[dict[str, Any]] = []
    ind = SerialIndicator("B", PORT, "mitutoyo", serial_factory=factory, on_event=events.append)
    # A replugged adapter comes back on the same path: reopened, the reading taken.
    assert ind.read() == 1.0
    assert dead.closed and factory.call_count == 2
    assert [e["event"] for e in events] == ["reopened"]  # journaled; never a retry
    assert events[0]["port"] == PORT and events[0]["attempts"] == 1
    ind.close()


def test_port_that_fails_and_stays_gone_is_a_port_error(mocker: Any) -> None:
    dead = FakeSerial([])
    mocker.patch.object(dead, "write", side_effect=serial.SerialException("write failed: EIO"))
    gone = serial.SerialException("could not open port: No such file or directory")
    factory = mocker.Mock(side_effect=[dead, gone, gone, gone, gone])
    events: list[dict[str, Any]] = []
    ind = SerialIndicator("B", PORT, "mitutoyo", serial_factory=factory, on_event=events.append,
                          reopen_s=0.1)
    with pytest.raises(IndicatorPortError) as info:
        ind.read()
    assert info.value.device == f"indicator B ({PORT})"
    assert "EIO" in str(info.value) and "still gone after 0.1 s" in str(info.value)
    assert not info.value.transient
    assert events and {e["event"] for e in events} == {"reopen"}
    ind.close()


def test_termios_failure_is_a_port_error(mocker: Any) -> None:
    fake = FakeSerial([])
    mocker.patch.object(fake, "reset_input_buffer", side_effect=termios.error(5, "I/O error"))
    ind = SerialIndicator("C", PORT, "sylvac", serial_factory=mocker.Mock(return_value=fake))
    # Reopened after each failure (it is the same failing port), then given up.
    with pytest.raises(IndicatorPortError, match="I/O error"):
        ind.read()
    ind.close()


def test_port_that_cannot_be_opened(mocker: Any) -> None:
    factory = mocker.Mock(side_effect=serial.SerialException("could not open port"))
    with pytest.raises(IndicatorPortError) as info:
        SerialIndicator("D", "/dev/ttyUSB9", "mahr", serial_factory=factory, reopen_s=0.0)
    assert info.value.device == "indicator D (/dev/ttyUSB9)"


def test_write_timeout_is_retried_as_timeout(mocker: Any) -> None:
    fake = FakeSerial([(b"?\r", b"+0.5000\r")])
    real_write = fake.write
    calls: list[bytes] = []

    def stuck_once(data: bytes) -> int:
        calls.append(data)
        if len(calls) == 1:
            raise serial.SerialTimeoutException("Write timeout")
        return real_write(data)

    mocker.patch.object(fake, "write", side_effect=stuck_once)
    events: list[dict[str, Any]] = []
    ind = SerialIndicator(
        "E", PORT, "sylvac", serial_factory=mocker.Mock(return_value=fake), on_event=events.append
    )
    assert ind.read() == 0.5
    assert calls == [b"?\r", b"?\r"]
    assert len(events) == 1 and "write timed out" in events[0]["error"]
    assert not fake.pairs and not fake.rx
    ind.close()


def test_closed_indicator_refuses_to_read(mocker: Any) -> None:
    ind = SerialIndicator(
        "F", PORT, "sylvac", serial_factory=mocker.Mock(return_value=FakeSerial([]))
    )
    ind.close()
    with pytest.raises(IndicatorPortError, match="closed"):
        ind.read()


# --- protocols from the config ----------------------------------------------------


def test_generic_protocol_from_config(mocker: Any) -> None:
    # As a [[indicators]] table would give it: strings for bytes, TOML escapes decoded.
    proto = make_protocol(
        "generic",
        {
            "baudrate": 19200,
            "bytesize": 7,
            "parity": "O",
            "stopbits": 1,
            "request": "\x05R\r\n",
            "terminator": "\r\n",
            "reply_pattern": r"X=([+-]?\d+)",
            "error_pattern": r"E(\d{2})",
            "unit": "um",
            "scale": 0.5,
        },
    )
    assert proto.request == b"\x05R\r\n" and proto.terminator == b"\r\n"
    assert proto.reply_format is None  # the built-in's format no longer fits
    pairs = [(b"\x05R\r\n", b"X=+246\r\n"), (b"\x05R\r\n", b"E04\r\n"), (b"\x05R\r\n", b"X=-2\r\n")]
    with expected_protocol(mocker, proto, pairs) as (ind, events):
        assert ind.read() == pytest.approx(0.123, abs=1e-12)
        assert ind.read() == pytest.approx(-0.001, abs=1e-12)
    assert len(events) == 1 and "gauge error 04" in events[0]["error"]


# --- group error handling (concurrency itself is tested over ptys) ----------------


def test_group_raises_the_failing_indicator_after_all_reads_finished(mocker: Any) -> None:
    good = FakeSerial([(b"1\r", b"01A+0000.100\r")] * 2)
    bad = FakeSerial([(b"1\r", b"")] * 2)
    inds = [
        SerialIndicator(
            n, f"/dev/tty{n}", "mitutoyo", retries=1, serial_factory=mocker.Mock(return_value=f)
        )
        for n, f in (("G", good), ("H", bad))
    ]
    with IndicatorGroup(inds) as group:
        assert group.names == ["G", "H"]
        assert group.read(1, names=["G"]) == {"G": [0.1]}
        with pytest.raises(IndicatorTimeout) as info:
            group.read(1)
        assert info.value.device == "indicator H (/dev/ttyH)"
        with pytest.raises(KeyError, match="Z"):
            group.read(1, names=["Z"])
    assert not good.pairs and not bad.pairs  # G's read completed despite H's failure
    assert good.closed and bad.closed


def test_group_names_the_indicator_of_an_unexpected_exception(mocker: Any) -> None:
    fake = FakeSerial([])
    mocker.patch.object(fake, "write", side_effect=RuntimeError("bug"))
    ind = SerialIndicator("K", PORT, "sylvac", serial_factory=mocker.Mock(return_value=fake))
    with IndicatorGroup([ind]) as group:
        with pytest.raises(RuntimeError) as info:
            group.read(1)
    assert "indicator K" in "".join(info.value.__notes__)


def test_group_refuses_duplicate_names(mocker: Any) -> None:
    a = SerialIndicator(
        "A", PORT, "sylvac", serial_factory=mocker.Mock(return_value=FakeSerial([]))
    )
    with pytest.raises(ValueError, match="two indicators named 'A'"):
        IndicatorGroup([a, a])
    a.close()


def test_a_port_that_is_not_there_is_said_once(tmp_path: Path) -> None:
    # pyserial's own text repeats the errno and the port: the OS's words, once
    gone = tmp_path / "ttyUSB99"
    with pytest.raises(IndicatorPortError) as info:
        SerialIndicator("D", str(gone), "mitutoyo", reopen_s=0.0)
    assert str(info.value) == f"indicator D ({gone}): cannot open port: No such file or directory"
