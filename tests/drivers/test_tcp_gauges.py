"""Simulated gauges served over TCP (``line="tcp"``, for systems without
pseudo-terminals): the same bytes as on a pty, byte for byte, through pyserial's
``socket://`` URLs, and a line that goes and comes back reopened like an adapter."""

from __future__ import annotations

from typing import Any

import pytest
import serial

from drivers.device_errors import IndicatorPortError
from drivers.indicator_protocols import BUILTIN_PROTOCOLS
from drivers.indicators import SerialIndicator
from drivers.sim.gauge_lines import LINES
from drivers.sim.pty_gauges import SimIndicator
from drivers.sim.tcp_line import TcpLine

# Per protocol: its request and the gauge's reply at +1.234 mm, as the protocol table
# of docs/design.md writes them (the pty gauges give the same: the test below).
EXCHANGES: dict[str, tuple[bytes, bytes]] = {
    "mitutoyo": (b"1\r", b"01A+0001.234\r"),
    "sylvac": (b"?\r", b"+1.2340\r"),
    "mahr": (b"?\r", b"1.2340 mm\r\n"),
    "generic": (b"?\r", b"+1.2340\r"),
}


def test_every_protocol_has_its_exchange() -> None:
    assert set(EXCHANGES) == set(BUILTIN_PROTOCOLS)


def _exchange(name: str, line: str, request: bytes, terminator: bytes) -> bytes:
    with SimIndicator(name, lambda: 1.234, zero_mm=0.0, line=line) as sim:
        with serial.serial_for_url(sim.port, timeout=2.0) as port:
            port.write(request)
            reply = port.read_until(terminator)
        assert sim.requests == sim.replies == 1
    return bytes(reply)


@pytest.mark.parametrize("name", sorted(EXCHANGES))
def test_one_request_one_reply_byte_for_byte_as_on_a_pty(name: str) -> None:
    request, expected = EXCHANGES[name]
    terminator = BUILTIN_PROTOCOLS[name].terminator
    assert _exchange(name, "tcp", request, terminator) == expected
    assert _exchange(name, "pty", request, terminator) == expected


def test_the_line_listens_on_the_loopback_at_an_ephemeral_port() -> None:
    line = TcpLine("A")
    try:
        line.plug_in()
        host, port = line.bound()
        assert host == "127.0.0.1" and 0 < port < 65536
        assert line.port == f"socket://127.0.0.1:{port}"
        line.pull_plug()
        line.plug_in()  # plugged in again: the same port, so the same URL
        assert line.bound() == (host, port)
    finally:
        line.close()
    with SimIndicator("mitutoyo", lambda: 0.0, line="tcp") as a, \
            SimIndicator("mitutoyo", lambda: 0.0, line="tcp") as b:
        assert a.port.startswith("socket://127.0.0.1:") and a.port != b.port
        assert a.line == "tcp" and a.tty == ""
    assert LINES == ("pty", "tcp")


def test_a_request_split_across_writes_counts_once_and_junk_is_ignored() -> None:
    with SimIndicator("mahr", lambda: 2.0, zero_mm=0.0, line="tcp") as sim:
        with serial.serial_for_url(sim.port, timeout=1.0) as port:
            port.write(b"junk")
            port.write(b"?")
            port.write(b"\r")
            assert port.read_until(b"\n") == b"2.0000 mm\r\n"
            port.write(b"1\r")  # mitutoyo's request means nothing to a Mahr gauge
            port.write(b"?\r")
            assert port.read_until(b"\n") == b"2.0000 mm\r\n"
        assert sim.requests == 2


def test_a_port_opened_again_replaces_the_connection_before() -> None:
    with SimIndicator("sylvac", lambda: 0.5, zero_mm=0.0, line="tcp") as sim:
        first = serial.serial_for_url(sim.port, timeout=1.0)
        try:
            with SerialIndicator("B", sim.port, "sylvac") as ind:
                assert ind.read() == 0.5
        finally:
            first.close()
        assert sim.replies == 1


def test_replies_sent_at_the_lines_pace_arrive_whole() -> None:
    # at 4800 baud the reply leaves in bursts (drivers.sim.pty_gauges.BURST_S), each
    # its own TCP segment (no Nagle delay): the driver puts them together
    with SimIndicator("sylvac", lambda: 1.234, zero_mm=0.0, baud=4800, line="tcp") as sim:
        with SerialIndicator("B", sim.port, "sylvac") as ind:
            assert ind.read_n(5) == [1.234] * 5
        assert sim.requests == sim.replies == 5


def test_a_server_that_goes_and_comes_back_is_reopened_at_the_same_url() -> None:
    events: list[dict[str, Any]] = []
    with SimIndicator("mitutoyo", lambda: 1.0, zero_mm=0.0, line="tcp") as sim:
        url = sim.port
        with SerialIndicator("A", url, "mitutoyo", reopen_s=5.0,
                             on_event=events.append) as ind:
            assert ind.read() == 1.0
            sim.unplug_for(0.4)
            assert ind.read_n(3) == [1.0] * 3  # waits for the server, then reads on
        assert sim.port == url
    kinds = [e["event"] for e in events]
    assert kinds.count("reopened") == 1 and kinds.index("reopen") < kinds.index("reopened")
    assert all(e["port"] == url for e in events)


def test_a_server_gone_for_good_is_a_port_error_naming_the_url() -> None:
    with SimIndicator("mitutoyo", lambda: 1.0, zero_mm=0.0, line="tcp") as sim:
        with SerialIndicator("A", sim.port, "mitutoyo", reopen_s=0.3) as ind:
            assert ind.read() == 1.0
            sim.unplug()
            with pytest.raises(IndicatorPortError) as info:
                ind.read()
            assert info.value.device == f"indicator A ({sim.port})"
            assert "still gone after 0.3 s" in info.value.message
        with pytest.raises(IndicatorPortError, match="cannot open"):
            SerialIndicator("A", sim.port, "mitutoyo", reopen_s=0.0)


def test_an_unknown_line_is_refused() -> None:
    with pytest.raises(ValueError, match="pty, tcp"):
        SimIndicator("mitutoyo", lambda: 0.0, line="usb")
