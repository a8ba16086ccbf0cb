"""The station on a shop's PC (Windows, macOS): nothing it loads needs fcntl,
termios, pty or tty, and the simulator serves its gauges over TCP where there are
no pseudo-terminals (``--gauges tcp``).

Windows is not at hand: a Python where those four modules cannot be imported
(tests/helpers/no_posix.py) stands in for it. In it the quick start runs to a
converged result, ``orthocal sim`` serves a station, and every module of the
station loads but the simulator's two pseudo-terminal ones.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import no_posix
import pytest
import serial
from builders import FAST, Rig, no_figures_file, on_setup

from drivers.sim import gauge_lines
from drivers.sim.station import VirtualStation
from station.commands.options import SimOptions
from station.commands.simulate import launch
from station.commands.simulate.file_options import load_simulation, with_command_line
from station.config import load_config
from station.errors import BadInput

ROOT = Path(__file__).resolve().parents[3]

CLI = """
from station.commands.cli import main
code = main(sys.argv[1:])
""" + no_posix.REPORT_LOADED + """
sys.exit(code)
"""


def _without_posix(args: list[str], tmp_path: Path, **popen: object) -> subprocess.Popen[str]:
    return subprocess.Popen(no_posix.argv(CLI, *args, serial_backend=True), cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "ORTHOCAL_STATE_DIR": str(tmp_path / "state")},
                            **popen)  # type: ignore[call-overload]


def _clean(stderr: str) -> None:
    """Nothing on stderr but the station's own lines: no traceback, no warning."""
    assert "Traceback" not in stderr and "internal error" not in stderr, stderr[-3000:]
    assert "Warning" not in stderr, stderr[-3000:]


def test_the_quick_start_converges_where_fcntl_termios_pty_and_tty_cannot_be_imported(
        tmp_path: Path) -> None:
    # The README's quick start, seeded (a converged result is asserted) and with the
    # hidden short procedure of the tests.
    out = tmp_path / "runs"
    proc = _without_posix(["run", "--simulate", "--gauges", "tcp", "--yes", "--out", str(out),
                           "--seed", "4", "--sim-procedure", json.dumps(
                               {"cycles": 2, "readings": 3, "settle_s": 0.0})], tmp_path)
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr[-3000:]
    _clean(stderr)
    assert stdout.splitlines()[-1] == "loaded:"  # none of the four, by anything
    assert stdout.startswith("orthocal run: COMPLETED")
    (run_dir,) = out.glob("run-*")
    result = json.loads((run_dir / "result.json").read_text())
    assert result["status"] == "ok" and result["converged"] is True
    assert result["loop"]["stopped"] == "converged"
    assert result["writeback"]["status"] == "written"
    # the gauges were TCP lines, and the journal says so for resume
    ports = [ind.port for ind in load_config(run_dir / "config.toml").indicators]
    assert len(ports) == 2 and all(re.fullmatch(r"socket://127\.0\.0\.1:\d+", p) for p in ports)
    header = json.loads((run_dir / "journal.jsonl").read_text().splitlines()[0])
    assert header["simulation"]["gauges"] == "tcp"
    # the machine was locked (filelock's marker here) and released: nothing left behind
    assert (tmp_path / "state" / "locks").is_dir()
    assert list((tmp_path / "state" / "locks").iterdir()) == []


def test_orthocal_sim_serves_its_gauges_over_tcp_by_default_where_there_are_no_ptys(
        tmp_path: Path) -> None:
    config_path = tmp_path / "sim.toml"
    proc = _without_posix(["sim", "--config-out", str(config_path), "--seed", "4"], tmp_path)
    try:
        deadline = time.monotonic() + 60
        while not config_path.exists() or "[[setups]]" not in config_path.read_text():
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "orthocal sim wrote no config in 60 s"
            time.sleep(0.05)
        gauges = load_config(config_path).indicators
        assert len(gauges) == 6
        assert all(re.fullmatch(r"socket://127\.0\.0\.1:\d+", g.port) for g in gauges)
        with serial.serial_for_url(gauges[0].port, timeout=2.0) as line:
            line.write(b"1\r")
            reply = line.read_until(b"\r")
        assert re.fullmatch(rb"01A[+-]\d{4}\.\d{3}\r", reply), reply
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 0, stderr[-3000:]
    _clean(stderr)
    assert "on TCP 127.0.0.1, socket:// URLs" in stderr and "stopped" in stderr
    assert stdout.splitlines()[-1] == "loaded:"


@pytest.mark.parametrize(("argv", "option"), [
    (["--gauges", "pty"], "--gauges pty"), (["--transport", "rtu"], "--transport rtu")])
def test_what_needs_pseudo_terminals_is_refused_in_one_line_where_there_are_none(
        tmp_path: Path, argv: list[str], option: str) -> None:
    config_path = tmp_path / "sim.toml"
    proc = _without_posix(["sim", "--config-out", str(config_path), *argv], tmp_path)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 2
    (line,) = stderr.splitlines()
    assert line.startswith(f"orthocal: error: {option}:") and "pseudo-terminal" in line
    assert not config_path.exists()


MODULES = r"""
import importlib, pkgutil
failed = {}
for package in ("orthocal", "drivers", "station"):
    for info in pkgutil.walk_packages(importlib.import_module(package).__path__, package + "."):
        if info.name.endswith(".__main__"):
            continue  # python -m station: the command line itself
        try:
            importlib.import_module(info.name)
        except ImportError as exc:
            failed[info.name] = exc.name
print(json.dumps(failed))
"""


def test_every_module_but_the_simulators_pseudo_terminals_loads_without_them(
        tmp_path: Path) -> None:
    # the commands the quick start does not run (probe, report, history, export...)
    # load as well; the pty lines are imported only where pseudo-terminals are used
    proc = subprocess.Popen(
        no_posix.argv("import json\n" + MODULES + no_posix.REPORT_LOADED, serial_backend=True),
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr[-3000:]
    failed, loaded = stdout.splitlines()[-2:]
    assert json.loads(failed) == {"drivers.sim.pty_line": "tty", "drivers.sim.ptypair": "tty"}
    assert loaded == "loaded:"


# --- the choice, kept for resume --------------------------------------------------------


def test_resume_restarts_the_same_virtual_station_on_tcp(tmp_path: Path, orthocal) -> None:
    def ctrl_c_at_the_second_setup(rig: Rig, station: VirtualStation) -> None:
        def interrupt() -> None:
            raise KeyboardInterrupt

        if len(rig.stations) == 1:
            on_setup(station, 2, interrupt)

    rig = Rig()
    argv = ["run", "--simulate", no_figures_file(tmp_path), "--gauges", "tcp", "--seed", "5",
            "--noise", "0", "--true-drho", "0.6,-0.9,0.4", "--sim-procedure", json.dumps(FAST),
            "--sim-speed", "20000",
            "--out", str(tmp_path / "runs"), "--json"]
    o = orthocal(*argv, rig=rig, prepare=ctrl_c_at_the_second_setup)
    assert o.code == 1 and "orthocal resume" in o.err, o.err
    assert o.journal[0]["simulation"]["gauges"] == "tcp"
    r = orthocal("resume", str(o.run_dir), "--json", rig=rig)
    assert r.code == 0, r.err
    assert json.loads(r.out)["status"] == "ok"
    assert [s.gauge_spec.line for s in rig.stations] == ["tcp", "tcp"]


def test_the_default_is_ptys_where_there_are_and_tcp_elsewhere(
        monkeypatch: pytest.MonkeyPatch) -> None:
    assert gauge_lines.pseudo_terminals()  # this Linux has them
    assert launch.gauge_line(None) == "pty" and launch.gauge_line("tcp") == "tcp"
    monkeypatch.setattr(gauge_lines, "pseudo_terminals", lambda: False)
    assert launch.gauge_line(None) == "tcp"
    with pytest.raises(BadInput, match="--gauges pty: this system has no pseudo-terminals"):
        launch.gauge_line("pty")


def test_a_sim_toml_gives_the_gauges_and_the_command_line_wins(tmp_path: Path) -> None:
    path = tmp_path / "sim.toml"
    path.write_text('[simulation]\nseed = 3\ngauges = "tcp"\n', encoding="utf-8")
    from_file = load_simulation(path)
    assert from_file.gauges == "tcp"
    assert with_command_line(from_file, SimOptions(gauges="pty")).gauges == "pty"
    assert with_command_line(from_file, SimOptions()).gauges == "tcp"
    path.write_text('[simulation]\ngauges = "usb"\n', encoding="utf-8")
    with pytest.raises(BadInput, match=r"sim\.toml.*simulation\.gauges"):
        load_simulation(path)


# --- the console where termios is missing ---------------------------------------------


def test_without_termios_or_msvcrt_a_question_is_still_asked_and_answered(
        monkeypatch: pytest.MonkeyPatch) -> None:
    import io

    from station.console import operator as console

    monkeypatch.setattr(console, "termios", None)
    monkeypatch.setattr(console, "msvcrt", None)
    master, slave = os.openpty()  # a terminal, whose typed-ahead keys stay unflushed
    inp = os.fdopen(slave, "r")
    try:
        os.write(master, b"y\n")
        out = io.StringIO()
        assert console.ConsoleOperator(False, stream_in=inp, stream_out=out).confirm(
            "Write offsets?") is True
        assert out.getvalue() == "Write offsets? [y/N] "
    finally:
        inp.close()
        os.close(master)


def test_a_file_is_written_whole_where_os_has_no_fchmod(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Windows before Python 3.13 has no os.fchmod (nor POSIX permissions to set)
    from drivers.files import write_atomic

    monkeypatch.delattr(os, "fchmod")
    write_atomic(tmp_path / "result.json", '{"status": "ok"}\n')
    assert (tmp_path / "result.json").read_text() == '{"status": "ok"}\n'
    assert [p.name for p in tmp_path.iterdir()] == ["result.json"]  # no temporary left
