"""One station per machine: the lock on a controller, with real
processes holding it, dying with it (kill -9) and releasing it."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from station.record import lock as machine_lock
from station.record.lock import MachineBusy, acquire, taken_over_message

ROOT = Path(__file__).resolve().parents[2]

HOLDER = r"""
import sys, time
from station.record.lock import acquire
lock = acquire("tcp", "192.0.2.7", 502, 1, command="run", run_dir=sys.argv[1])
print("held", flush=True)
sys.stdin.readline()  # hold until told (or killed)
lock.release()
print("released", flush=True)
"""


@pytest.fixture
def state(tmp_path: Path, monkeypatch) -> Path:
    monkeypatch.setenv("ORTHOCAL_STATE_DIR", str(tmp_path / "state"))
    return tmp_path / "state"


@pytest.fixture
def holder(state: Path, tmp_path: Path) -> Iterator[subprocess.Popen[str]]:
    env = {**os.environ, "ORTHOCAL_STATE_DIR": str(state)}
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(tmp_path / "run-A")],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                            cwd=ROOT, env=env)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=30)
        for f in (proc.stdin, proc.stdout):
            if f is not None:
                f.close()


def test_a_second_station_is_refused_naming_the_run_that_holds_the_machine(
        holder: subprocess.Popen[str], tmp_path: Path) -> None:
    with pytest.raises(MachineBusy) as info:
        acquire("tcp", "192.0.2.7", 502, 1, command="resume", run_dir=None)
    text = str(info.value)
    assert f"run {tmp_path / 'run-A'} (run, pid {holder.pid} on {socket.gethostname()}" in text
    assert "controller 192.0.2.7:502 (device 1) is in use" in text
    # Another device id behind the same gateway, or another port, is another machine.
    with acquire("tcp", "192.0.2.7", 502, 2, command="run", run_dir=None) as other:
        assert other.taken_over is None
    with acquire("tcp", "192.0.2.7", 5020, 1, command="run", run_dir=None):
        pass


def test_a_lock_left_by_a_killed_run_is_taken_over_and_says_so(
        holder: subprocess.Popen[str], tmp_path: Path) -> None:
    holder.send_signal(signal.SIGKILL)
    holder.wait(timeout=30)
    with acquire("tcp", "192.0.2.7", 502, 1, command="resume", run_dir="run-B") as lock:
        assert lock.taken_over is not None and lock.taken_over["pid"] == holder.pid
        message = taken_over_message(lock)
        assert message is not None and str(tmp_path / "run-A") in message
        assert f"pid {holder.pid}" in message and "that process is gone" in message
        body = json.loads(lock.path.read_text())
        assert body["pid"] == os.getpid() and body["run_dir"] == "run-B"


def test_a_cleanly_released_lock_leaves_nothing_to_take_over(
        holder: subprocess.Popen[str]) -> None:
    assert holder.stdin is not None and holder.stdout is not None
    holder.stdin.write("\n")
    holder.stdin.flush()
    assert holder.stdout.readline().strip() == "released"
    with acquire("tcp", "192.0.2.7", 502, 1, command="run", run_dir=None) as lock:
        assert lock.taken_over is None and taken_over_message(lock) is None


def test_keys_keep_distinct_addresses_apart() -> None:
    a = machine_lock.controller_key("rtu", "", "/dev/ttyUSB0", 1)
    b = machine_lock.controller_key("rtu", "", "/dev/ttyUSB_0", 1)
    assert a != b and "/" not in a
