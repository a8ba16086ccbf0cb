"""`orthocal probe` through pseudo-terminals and a real Modbus server: which
port is which gauge (Sylvac and Mahr told apart by their replies), a silent
port with its reason, and a controller probed by reads alone."""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest

from drivers import bringup as probe
from drivers.bringup import classify, probe_port
from drivers.sim.controller import SimController
from drivers.sim.pty_gauges import SimIndicator
from drivers.sim.ptypair import PtyPair
from station.commands.cli import main

READINGS = {"mitutoyo": 1.234, "sylvac": -0.567, "mahr": 2.5}


@pytest.fixture
def ports() -> Iterator[dict[str, str]]:
    sims = [SimIndicator(name, lambda v=value: v, zero_mm=0.0, name=name)
            for name, value in READINGS.items()]
    silent = PtyPair(name="silent").open()  # a port with nothing behind it
    try:
        for sim in sims:
            sim.start()
        yield {**{s.protocol.name: s.port for s in sims}, "silent": silent.path_b}
    finally:
        for sim in sims:
            sim.close()
        silent.close()


@pytest.mark.parametrize(("raw", "expected"), [
    (b"01A+0001.234\r", ("mitutoyo", 1.234)),
    (b"+0.0123\r", ("sylvac", 0.0123)),
    (b"-0.0123\r", ("sylvac", -0.0123)),
    (b"0.0123 mm\r\n", ("mahr", 0.0123)),
    (b"-0.0123 mm\r\n", ("mahr", -0.0123)),
    (b"ERR4\r", ("sylvac", None)),
    (b"+0.0123\r\n", None),  # Sylvac's digits with Mahr's terminator: neither
    (b"0.0123 mm\r", None),
    (b"hello\r", None),
])
def test_replies_are_told_apart_by_their_grammar(raw: bytes, expected) -> None:
    found = classify(raw)
    assert (found if found is None else found[:2]) == expected


def test_probe_identifies_each_gauge_and_the_silent_port(ports, capsys) -> None:
    order = ["mitutoyo", "sylvac", "mahr", "silent"]
    assert main(["probe", *[ports[k] for k in order], "--timeout", "0.3", "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert found["controller"] is None
    by_port = {ind["port"]: ind for ind in found["indicators"]}
    for name, value in READINGS.items():
        ind = by_port[ports[name]]
        assert ind["protocol"] == name
        assert ind["reading_mm"] == pytest.approx(value, abs=0.0011)
    assert by_port[ports["mitutoyo"]]["baudrate"] == 9600
    assert by_port[ports["sylvac"]]["line"] == "4800 7E2"
    assert by_port[ports["mahr"]]["line"] == "9600 7E2"
    silent = by_port[ports["silent"]]
    assert silent["protocol"] is None and silent["reading_mm"] is None
    assert "no reply" in silent["reason"] and "sylvac" in silent["reason"]


def test_the_order_of_attempts_does_not_decide(ports, monkeypatch) -> None:
    # Mahr tried first: the Sylvac gauge answers its "?\r" too, with Sylvac's
    # grammar, and must not be taken for a Mahr.
    monkeypatch.setattr(probe, "PROBED", ("mahr", "sylvac", "mitutoyo"))
    assert probe_port(ports["sylvac"], 0.3).protocol == "sylvac"
    assert probe_port(ports["mahr"], 0.3).protocol == "mahr"


@pytest.mark.parametrize("registers", [True, False], ids=["with-limits", "without-limits"])
def test_probe_controller_reads_only(ports, capsys, registers: bool) -> None:
    with SimController(soft_limit_registers=registers) as sim:
        before = sim.machine.actual().copy()
        code = main(["probe", ports["mitutoyo"], "--controller", f"127.0.0.1:{sim.port}",
                     "--timeout", "0.3", "--json"])
        found = json.loads(capsys.readouterr().out)
        assert code == 0
        c = found["controller"]
        assert c["address"] == f"127.0.0.1:{sim.port}"
        assert c["positions_mm"] == pytest.approx(dict(zip("xyz", before, strict=True)))
        assert set(c["offsets_mm"]) == {"x", "y", "z"}
        assert c["status"]["homed"] is True and c["status"]["alarm"] is False
        regs = c["registers"]
        assert regs["ACTUAL_X"]["state"] == "ok" and regs["ACTUAL_X"]["value"] == 310250
        if registers:
            assert regs["SOFT_MIN_X"]["state"] == "ok"
            assert c["soft_limits_mm"]["lower"]["x"] == pytest.approx(200.25)
        else:
            assert regs["SOFT_MAX_Z"]["state"] == "absent"
            assert c["soft_limits_mm"]["source"] == "absent"
            assert c["soft_limits_mm"]["lower"] is None
        # Never a write, never a command: the simulated drive saw reads only.
        assert sim.stats.writes == 0 and sim.stats.commands == {}
        assert sim.stats.requests > len(regs)
        assert (sim.machine.actual() == before).all()


def test_probe_human_table(ports, capsys) -> None:
    with SimController(soft_limit_registers=False) as sim:
        assert main(["probe", ports["mahr"], ports["silent"], "--timeout", "0.3",
                     "--controller", f"127.0.0.1:{sim.port}"]) == 0
    out = capsys.readouterr().out
    assert "mahr" in out and "9600 7E2" in out and "+2.5000" in out
    assert "no reply" in out
    assert "SOFT_MIN_X" in out and "absent" in out and "exception 2" in out


def test_unreachable_controller_exit_1(ports, capsys) -> None:
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["probe", ports["silent"], "--timeout", "0.2",
                 "--controller", f"127.0.0.1:{port}", "--json"]) == 1
    found = json.loads(capsys.readouterr().out)
    assert "cannot connect" in found["controller"]["error"]


def test_bad_controller_argument_exit_2(capsys) -> None:
    assert main(["probe", "--controller", "nohostport", "--json"]) == 2
    assert "--controller: expected HOST:PORT" in capsys.readouterr().err


def test_a_port_that_does_not_exist_exits_2_after_the_findings(ports, tmp_path, capsys) -> None:
    missing = str(tmp_path / "ttyUSB99")
    assert main(["probe", missing, ports["silent"], "--timeout", "0.2", "--json"]) == 2
    out, err = capsys.readouterr()
    by_port = {ind["port"]: ind for ind in json.loads(out)["indicators"]}
    assert by_port[missing]["exists"] is False and by_port[missing]["reason"] == \
        "the port does not exist"
    assert by_port[ports["silent"]]["exists"] is True  # silent, but there: a finding
    assert err.splitlines() == [f"orthocal: error: probe: port {missing} does not exist"]
    assert main(["probe", missing, "--timeout", "0.2"]) == 2  # the table, then the line
    out, err = capsys.readouterr()
    assert out.startswith("indicators") and err.count("\n") == 1
