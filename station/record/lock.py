"""One station per machine at a time.

``run``, ``resume`` and ``rollback`` take an exclusive lock on the controller they
drive (its transport address and device id) before anything moves or is written,
and hold it until the command ends. The lock is an ``fcntl.flock`` on a file in a
per-user state directory (``$ORTHOCAL_STATE_DIR``, else
``$XDG_STATE_HOME/orthocal``, else ``~/.local/state/orthocal``), ``locks/<key>``;
the file's body names the holder (run directory, pid, host, command, since) so a
refusal can say who holds the machine.

The kernel releases a flock when its process dies, however it dies, so a lock
left by a killed run (kill -9, a crash, a power cut of the station PC) is simply
taken; the body it left behind is then reported as taken over. A clean exit
clears the body before unlocking.

Two stations on two computers sharing one controller are not seen by a local
lock; the lock guards one station PC (the usual case: one PC per machine).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import re
import socket
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from station.errors import RunFailed
from station.record.result_base import JsonObject, JsonValue


class MachineBusy(RunFailed):
    """Another run holds the machine: exit 1 (the command is right; it can be run
    unchanged once the other one has finished), not 2 (nothing to correct)."""


def state_dir() -> Path:
    env = os.environ.get("ORTHOCAL_STATE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_STATE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".local" / "state"
    return base / "orthocal"


def controller_key(transport: str, host: str, port: int | str, device_id: int) -> str:
    """A file name for one controller: readable, and unique by a hash of the exact
    address (two paths that sanitise alike stay apart)."""
    where = f"{transport}:{host}:{port}" if transport == "tcp" else f"{transport}:{port}"
    exact = f"{where}#{device_id}"
    readable = re.sub(r"[^A-Za-z0-9._-]+", "_", exact).strip("_")[:80]
    digest = hashlib.sha256(exact.encode()).hexdigest()[:12]
    return f"{readable}-{digest}"


def describe(holder: JsonObject) -> str:
    return (f"run {holder.get('run_dir') or '?'} ({holder.get('command') or '?'}, "
            f"pid {holder.get('pid', '?')} on {holder.get('host', '?')}, "
            f"since {holder.get('since', '?')})")


@dataclass
class MachineLock:
    """A held lock; ``taken_over`` is the body a dead holder left behind, if any."""

    path: Path
    machine: str
    fd: int | None
    taken_over: JsonObject | None = None

    def release(self) -> None:
        fd, self.fd = self.fd, None
        if fd is None:
            return
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)  # a clean exit leaves nothing to take over
        os.close(fd)  # closing the last descriptor drops the flock

    def __enter__(self) -> MachineLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _read_body(fd: int) -> JsonObject | None:
    os.lseek(fd, 0, os.SEEK_SET)
    raw = b""
    while chunk := os.read(fd, 65536):
        raw += chunk
    if not raw.strip():
        return None
    try:
        body = json.loads(raw)
    except ValueError:
        return {"run_dir": None, "note": "unreadable lock body"}
    return body if isinstance(body, dict) else {"note": "unreadable lock body"}


def acquire(transport: str, host: str, port: int | str, device_id: int, *,
            command: str, run_dir: str | Path | None) -> MachineLock:
    """Take the machine's lock at once or raise MachineBusy naming the holder."""
    machine = (f"controller {host}:{port}" if transport == "tcp" else f"controller {port}") + \
        f" (device {device_id})"
    directory = state_dir() / "locks"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / controller_key(transport, host, port, device_id)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise RunFailed(f"cannot create the machine lock in {directory}: {exc.strerror or exc}"
                        " (set ORTHOCAL_STATE_DIR to a writable directory)") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _read_body(fd) or {}
        os.close(fd)
        raise MachineBusy(f"{machine} is in use by {describe(holder)}; one station per "
                          "machine: wait for it to end (or stop it), then run this again"
                          ) from None
    except OSError as exc:
        os.close(fd)
        raise RunFailed(f"cannot lock {path}: {exc.strerror or exc}") from None
    stale = _read_body(fd)
    body = {"run_dir": None if run_dir is None else str(run_dir), "pid": os.getpid(),
            "host": socket.gethostname(), "command": command, "machine": machine,
            "since": datetime.now(UTC).astimezone().isoformat(timespec="seconds")}
    lock = MachineLock(path, machine, fd, stale)
    lock_write(lock, body)
    return lock


def lock_write(lock: MachineLock, body: Mapping[str, JsonValue]) -> None:
    """Replace the body (e.g. once the run directory is known)."""
    if lock.fd is None:
        return
    data = (json.dumps(body) + "\n").encode()
    try:
        os.ftruncate(lock.fd, 0)
        os.lseek(lock.fd, 0, os.SEEK_SET)
        os.write(lock.fd, data)
    except OSError:
        pass  # the lock holds without its body; a refusal then names no run


def update_run_dir(lock: MachineLock, run_dir: str | Path) -> None:
    if lock.fd is None:
        return
    body = _read_body(lock.fd) or {}
    body["run_dir"] = str(run_dir)
    lock_write(lock, body)


def taken_over_message(lock: MachineLock) -> str | None:
    """What to tell the operator when a dead run's lock was taken, else None."""
    if lock.taken_over is None:
        return None
    return (f"took over the lock on {lock.machine} left by {describe(lock.taken_over)}: "
            "that process is gone")
