"""The run journal: append-only JSONL, every record flushed and fsynced before
the station moves on, so that a run killed at any instant resumes.

Record types (field ``type``): ``header`` (config, plan, version, simulation),
``resumed``, ``setup`` (mounted), ``reading`` (stop, indicator, values),
``outlier``, ``event`` (driver retries and faults), ``cycle``, ``setup_done``,
``identification``, ``writeback`` (stage backup|intent|done|refused|declined|
failed-restored; ``round`` k of the closed loop), ``verification`` (``round``
k), ``fault``, ``aborted``, ``finished``, ``rollback``, and after a power cut
``homed``, ``reference-check`` (the Π0 check after homing) and ``setup-redo``
(that setup's earlier cycles are void, see station.engine.recovery). Driver events
include ``retry``, ``reconnect`` / ``reconnected`` / ``reference-check``
(controller) and ``reopen`` / ``reopened`` (a gauge's port).

A torn last line (killed mid-write) is tolerated when reading; reopening
appends a newline and a ``resumed`` record after it, so the journal before the
kill stays a byte prefix of the final one and the torn fragment is recognisably
followed by a resume.

A record that cannot be saved (disk full: ENOSPC, or EFBIG under a file-size
limit) is cut off again: the file is truncated back to its last whole record
and :class:`~station.errors.StorageFull` raised, so the caller never uses what
it could not journal and a later reader never meets half a record.
"""

from __future__ import annotations

import json
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.files import fsync_dir
from station.errors import BadInput, StorageFull, storage_message

JOURNAL_NAME = "journal.jsonl"


class Journal:
    """Appends records; thread-safe (driver events may arrive from reader threads)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._lock = threading.Lock()
        new = not self.path.exists()
        # Unbuffered: a failed write must not leave bytes in a buffer that a later
        # flush or close would write after the truncation.
        self._fd: int | None = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        self._good = os.fstat(self._fd).st_size  # length up to the last whole record
        self.torn = False
        if not new and self._good > 0:
            with open(self.path, "rb") as fh:
                fh.seek(-1, os.SEEK_END)
                self.torn = fh.read(1) != b"\n"
        if new:
            fsync_dir(self.path.parent)

    @property
    def closed(self) -> bool:
        return self._fd is None

    def append(self, record: dict[str, Any]) -> None:
        record = {"t": round(time.time(), 6), **record}
        line = (json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n").encode()
        with self._lock:
            if self._fd is None:
                raise RuntimeError("journal is closed")
            # Terminate the fragment a kill left behind; readers skip it.
            data = (b"\n" if self.torn else b"") + line
            try:
                view = memoryview(data)
                while view:
                    view = view[os.write(self._fd, view):]
                os.fsync(self._fd)
            except OSError as exc:
                self._cut_back()
                raise StorageFull(storage_message(self.path, exc) + "; the record "
                                  f"{record.get('type')!r} was not saved") from exc
            self._good += len(data)
            self.torn = False

    def _cut_back(self) -> None:
        """Remove whatever part of a failed append reached the file."""
        assert self._fd is not None
        try:
            os.ftruncate(self._fd, self._good)
            os.fsync(self._fd)
        except OSError:
            pass  # truncating never needs space; if even this fails, the reader copes

    def flush(self) -> None:
        with self._lock:
            if self._fd is not None:
                os.fsync(self._fd)

    def close(self) -> None:
        with self._lock:
            if self._fd is not None:
                fd, self._fd = self._fd, None
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_journal(path: str | Path) -> list[dict[str, Any]]:
    """All intact records. A line that does not parse is tolerated only if it is
    the last one (torn by a kill) or is followed by a ``resumed`` or ``rollback``
    record (the journal reopened after the kill)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise BadInput(f"{path}: no journal here") from None
    lines = raw.split(b"\n")
    records: list[dict[str, Any]] = []
    pending_bad: int | None = None
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
            if not isinstance(record, dict) or "type" not in record:
                raise ValueError("not a record")
        except (ValueError, UnicodeDecodeError):
            if pending_bad is not None:
                raise BadInput(f"{path}: line {pending_bad} is corrupt") from None
            pending_bad = number
            continue
        # A rollback reopens the journal as a resume does: it may follow a torn line.
        if pending_bad is not None and record["type"] not in ("resumed", "rollback"):
            raise BadInput(f"{path}: line {pending_bad} is corrupt") from None
        pending_bad = None
        records.append(record)
    return records


@dataclass
class JournalState:
    """What a journal says happened, rebuilt by replaying its records."""

    header: dict[str, Any] | None = None
    readings: dict[tuple[str, str], list[float]] = field(default_factory=dict)
    mounted: list[tuple[str, int]] = field(default_factory=list)  # (phase, setup)
    # The steps a resume does not take again (cycles, identifications, write-back
    # stages) are indexed by station.engine.replay, not here.
    finished: dict[str, Any] | None = None
    events: int = 0
    retries: int = 0
    resumes: int = 0

    @property
    def started(self) -> float | None:
        return None if self.header is None else self.header.get("t")


def replay(records: list[dict[str, Any]]) -> JournalState:
    state = JournalState()
    for rec in records:
        kind = rec["type"]
        if kind == "header":
            state.header = rec
        elif kind == "resumed":
            state.resumes += 1
        elif kind == "reading":
            state.readings[(rec["stop"], rec["indicator"])] = [float(v) for v in rec["values"]]
        elif kind == "setup":
            state.mounted.append((rec["phase"], int(rec["setup"])))
        elif kind == "finished":
            state.finished = rec
        elif kind == "event":
            state.events += 1
            if rec.get("event", {}).get("event") == "retry":
                state.retries += 1
    return state
