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

Each record is one of station.record.journal's types: it is parsed into its type
before it is written (one that is not is refused, unwritten) and folded, once saved,
into the journal's :class:`~station.record.state.RunState`, which is what the run
reads back instead of the file.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Mapping
from pathlib import Path

from pydantic import ValidationError

from drivers.files import fsync_dir
from station.errors import BadInput, StorageFull, storage_message
from station.record.journal import RECORD, JournalRecord
from station.record.result_base import JsonObject
from station.record.state import RunState

JOURNAL_NAME = "journal.jsonl"


class Journal:
    """Appends records; thread-safe (driver events may arrive from reader threads).
    ``state``: the run state of the records already in the file (a reopened run's);
    without it the file's records are folded now. Every record saved is folded into
    it (:attr:`state`)."""

    def __init__(self, path: str | Path, state: RunState | None = None) -> None:
        self.path = Path(path)
        self._lock = threading.Lock()
        new = not self.path.exists()
        if state is None:
            state = RunState() if new else RunState.of(read_records(self.path))
        self.state = state
        # Unbuffered: a failed write must not leave bytes in a buffer that a later
        # flush or close would write after the truncation. O_BINARY (Windows): each
        # record ends in \n, not \r\n, as the torn-line check below reads it.
        flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_BINARY", 0)
        self._fd: int | None = os.open(self.path, flags, 0o644)
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

    def append(self, body: Mapping[str, object]) -> None:
        # Any JSON-able mapping: the line is validated against the journal's typed
        # records below, before anything is written.
        record = {"t": round(time.time(), 6), **body}
        line = (json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n").encode()
        # Parsed from the very line a reader will parse; a record of no journal type
        # is a bug, refused before a reader could meet it.
        try:
            typed = RECORD.validate_json(line)
        except ValidationError as exc:
            raise ValueError(f"journal record {record.get('type')!r} is not of the "
                             f"journal's schema: {_why(exc)}") from None
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
            self.state.apply(typed)  # under the lock: records fold in the order saved

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


def read_journal(path: str | Path) -> list[JsonObject]:
    """All intact records, as JSON objects. A line that does not parse is tolerated
    only if it is the last one (torn by a kill) or is followed by a ``resumed`` or
    ``rollback`` record (the journal reopened after the kill)."""
    return [record for _, record in _lines(Path(path))]


def read_records(path: str | Path) -> list[JournalRecord]:
    """All intact records (as :func:`read_journal`), each parsed into its record type
    (station.record.journal; an older version's lines read as they are): BadInput
    names a line that is not one."""
    path = Path(path)
    records: list[JournalRecord] = []
    for number, record in _lines(path):
        try:
            records.append(RECORD.validate_python(record))
        except ValidationError as exc:
            raise BadInput(f"{path}: line {number} is not a journal record "
                           f"({_why(exc)})") from None
    return records


def _why(exc: ValidationError) -> str:
    first = exc.errors()[0]
    where = ".".join(str(part) for part in first["loc"])
    more = f", and {exc.error_count() - 1} more" if exc.error_count() > 1 else ""
    return f"{where}: {first['msg']}{more}"


def _lines(path: Path) -> list[tuple[int, JsonObject]]:
    """(line number, record) of every intact line (:func:`read_journal`)."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise BadInput(f"{path}: no journal here") from None
    records: list[tuple[int, JsonObject]] = []
    pending_bad: int | None = None
    for number, line in enumerate(raw.split(b"\n"), start=1):
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
        records.append((number, record))
    return records
