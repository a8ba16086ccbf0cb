"""One station per machine: the lock on a controller, with real
processes holding it, dying with it (kill -9) and releasing it; through filelock,
and through it where fcntl cannot be imported (as on Windows)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import filelock
import no_posix
import pytest

from station.record import lock as machine_lock
from station.record.lock import MachineBusy, acquire, taken_over_message

ROOT = Path(__file__).resolve().parents[3]

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


def test_the_lock_is_filelocks_beside_the_holders_body(
        holder: subprocess.Popen[str], state: Path, tmp_path: Path) -> None:
    # What another tool sees: the OS lock on <key>.lock, held, and the body naming the run.
    key = machine_lock.controller_key("tcp", "192.0.2.7", 502, 1)
    with pytest.raises(filelock.Timeout):
        filelock.FileLock(state / "locks" / f"{key}.lock", timeout=0).acquire()
    body = json.loads((state / "locks" / key).read_text())
    assert body["pid"] == holder.pid and body["run_dir"] == str(tmp_path / "run-A")
    assert holder.stdin is not None and holder.stdout is not None
    holder.stdin.write("\n")
    holder.stdin.flush()
    assert holder.stdout.readline().strip() == "released"
    assert not (state / "locks" / key).exists()  # a clean exit leaves no body
    other = filelock.FileLock(state / "locks" / f"{key}.lock", timeout=0)
    other.acquire()
    other.release()


# --- where fcntl cannot be imported (as on Windows) ------------------------------------

CONTENDER = r"""
import json
from station.record.lock import MachineBusy, acquire, taken_over_message
try:
    lock = acquire("tcp", "192.0.2.7", 502, 1, command="resume", run_dir="run-B")
except MachineBusy as exc:
    print(json.dumps({"busy": str(exc)}))
else:
    print(json.dumps({"taken_over": taken_over_message(lock), "pid": lock.taken_over
                      and lock.taken_over["pid"]}))
    lock.release()
"""


def _without_posix(code: str, state: Path, *args: str,
                   stdin: int | None = None) -> subprocess.Popen[str]:
    return subprocess.Popen(no_posix.argv(code + no_posix.REPORT_LOADED, *args),
                            stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT,
                            env={**os.environ, "ORTHOCAL_STATE_DIR": str(state)})


def _contend(state: Path) -> tuple[dict, str]:
    proc = _without_posix(CONTENDER, state)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and err == "", err
    answer, loaded = out.splitlines()
    return json.loads(answer), loaded


def test_without_fcntl_a_second_station_is_refused_and_a_dead_ones_lock_taken_over(
        state: Path, tmp_path: Path) -> None:
    holder = _without_posix(HOLDER, state, str(tmp_path / "run-A"), stdin=subprocess.PIPE)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        answer, loaded = _contend(state)
        assert loaded == "loaded:"  # neither process imported fcntl, termios, pty or tty
        assert f"run {tmp_path / 'run-A'} (run, pid {holder.pid} on" in answer["busy"]
        assert "controller 192.0.2.7:502 (device 1) is in use" in answer["busy"]
        holder.kill()  # kill -9: filelock's marker stays behind, naming a dead process
        holder.wait(timeout=30)
        answer, _ = _contend(state)
        assert answer["pid"] == holder.pid
        assert str(tmp_path / "run-A") in answer["taken_over"]
        assert "that process is gone" in answer["taken_over"]
        answer, _ = _contend(state)  # and released cleanly by that one: nothing left
        assert answer == {"taken_over": None, "pid": None}
    finally:
        if holder.poll() is None:
            holder.kill()
        holder.communicate(timeout=30)
