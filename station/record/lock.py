"""One station per machine at a time.

``run``, ``resume`` and ``rollback`` take an exclusive lock on the controller they
drive (its transport address and device id) before anything moves or is written,
and hold it until the command ends. The lock lives in a per-user state directory
(``$ORTHOCAL_STATE_DIR``, else ``$XDG_STATE_HOME/orthocal``, else
``~/.local/state/orthocal``), as two files per controller under ``locks/``:

* ``<key>.lock``, the lock itself: a ``filelock.FileLock``, taken without waiting.
  That is ``fcntl.flock`` on Linux and macOS and ``LockFileEx`` on Windows: the
  operating system drops it when its process dies, however it dies (kill -9, a
  crash, a power cut of the station PC). Where neither exists, filelock keeps a
  marker file naming its process instead, and takes it over once that process is
  gone from this host.
* ``<key>``, the holder's body (run directory, pid, host, command, since), so that
  a refusal can say who holds the machine. It is a file of its own because the
  lock file cannot carry it: Windows locks are mandatory, so nobody else could
  read a body under one.

A clean exit removes the body before unlocking; a body found by whoever takes the
lock was left by a run that died holding it, and is reported as taken over.

Two stations on two computers sharing one controller are not seen by a local
lock; the lock guards one station PC (the usual case: one PC per machine).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import socket
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import filelock

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
    """A held lock: ``path`` is the holder's body, ``held`` the operating system's
    lock beside it (None once released); ``taken_over`` is the body a dead holder
    left behind, if any."""

    path: Path
    machine: str
    held: filelock.BaseFileLock | None
    taken_over: JsonObject | None = None

    def release(self) -> None:
        held, self.held = self.held, None
        if held is None:
            return
        _clear_body(self.path)  # a clean exit leaves nothing to take over
        held.release()

    def __enter__(self) -> MachineLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _read_body(path: Path) -> JsonObject | None:
    try:
        raw = path.read_bytes()
    except OSError:  # none (a clean exit removed it), or not readable now
        return None
    if not raw.strip():
        return None
    try:
        body = json.loads(raw)
    except ValueError:
        return {"run_dir": None, "note": "unreadable lock body"}
    return body if isinstance(body, dict) else {"note": "unreadable lock body"}


def _clear_body(path: Path) -> None:
    try:
        path.unlink(missing_ok=True)
    except OSError:  # Windows: someone refused is reading it this instant
        with contextlib.suppress(OSError):
            path.write_bytes(b"")


def acquire(transport: str, host: str, port: int | str, device_id: int, *,
            command: str, run_dir: str | Path | None) -> MachineLock:
    """Take the machine's lock at once or raise MachineBusy naming the holder."""
    machine = (f"controller {host}:{port}" if transport == "tcp" else f"controller {port}") + \
        f" (device {device_id})"
    directory = state_dir() / "locks"
    key = controller_key(transport, host, port, device_id)
    path = directory / key
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunFailed(f"cannot create the machine lock in {directory}: {exc.strerror or exc}"
                        " (set ORTHOCAL_STATE_DIR to a writable directory)") from None
    # thread_local=False: the run may end (and release) on another thread than it began
    held = filelock.FileLock(directory / f"{key}.lock", timeout=0, thread_local=False)
    try:
        held.acquire()
    except filelock.Timeout:
        holder = _read_body(path) or {}
        raise MachineBusy(f"{machine} is in use by {describe(holder)}; one station per "
                          "machine: wait for it to end (or stop it), then run this again"
                          ) from None
    except OSError as exc:
        raise RunFailed(f"cannot lock {held.lock_file}: {exc.strerror or exc}") from None
    stale = _read_body(path)
    body = {"run_dir": None if run_dir is None else str(run_dir), "pid": os.getpid(),
            "host": socket.gethostname(), "command": command, "machine": machine,
            "since": datetime.now(UTC).astimezone().isoformat(timespec="seconds")}
    lock = MachineLock(path, machine, held, stale)
    lock_write(lock, body)
    return lock


def lock_write(lock: MachineLock, body: Mapping[str, JsonValue]) -> None:
    """Replace the body (e.g. once the run directory is known): written beside it and
    renamed over it, so that one refused meanwhile reads the old body or the new."""
    if lock.held is None:
        return
    data = (json.dumps(body) + "\n").encode()
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{lock.path.name}.", dir=lock.path.parent)
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
            os.replace(tmp, lock.path)
        except OSError:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
    except OSError:
        pass  # the lock holds without its body; a refusal then names no run


def update_run_dir(lock: MachineLock, run_dir: str | Path) -> None:
    if lock.held is None:
        return
    body = _read_body(lock.path) or {}
    body["run_dir"] = str(run_dir)
    lock_write(lock, body)


def taken_over_message(lock: MachineLock) -> str | None:
    """What to tell the operator when a dead run's lock was taken, else None."""
    if lock.taken_over is None:
        return None
    return (f"took over the lock on {lock.machine} left by {describe(lock.taken_over)}: "
            "that process is gone")
