"""Errors that end a command with a known exit status and one clear line, and the line
for the operator on stderr."""

from __future__ import annotations

import sys
import threading
from pathlib import Path


class BadInput(Exception):
    """Bad configuration, CSV or arguments: exit 2. The message names the field or line."""


class RunFailed(Exception):
    """The run failed or was aborted (exit 1) with everything recorded so far kept."""


class StorageFull(RunFailed):
    """A record could not be saved: the disk is full (ENOSPC) or a file-size limit
    was reached (EFBIG). Nothing half-written is left behind."""


def storage_message(path: Path, exc: OSError) -> str:
    """One line saying what could not be saved and why, naming a full disk as such."""
    import errno

    if exc.errno == errno.ENOSPC:
        why = "the disk is full (no space left on the device)"
    elif exc.errno == errno.EFBIG:
        why = "the disk is full for this run (file-size limit reached)"
    elif exc.errno == errno.EDQUOT:
        why = "the disk quota is exceeded"
    else:
        why = f"cannot write ({exc.strerror or exc})"
    return f"{path}: {why}"


def read_input(path: Path, encoding: str = "utf-8") -> str:
    """The text of a file the user named (config, CSV); unreadable is bad input."""
    try:
        return path.read_text(encoding=encoding)
    except FileNotFoundError:
        raise BadInput(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BadInput(f"{path}: cannot read ({exc})") from None


def say(*parts: object) -> None:
    """A line for the operator on stderr (stdout carries the summary or the JSON)."""
    print(*parts, file=sys.stderr, flush=True)


#: Set by the command line's Ctrl-C handler (station.commands.cli). The handler also
#: raises KeyboardInterrupt at once; this flag is the backstop, because CPython runs a
#: signal's handler wherever the main thread is, and a KeyboardInterrupt raised inside
#: a finaliser (an object's __del__ run by the garbage collector) is printed and
#: dropped, and the run would go on. The sequencer checks it before every step.
INTERRUPTED = threading.Event()


def check_interrupted() -> None:
    """Raise KeyboardInterrupt if Ctrl-C came, even where its first raise was lost."""
    if INTERRUPTED.is_set():
        raise KeyboardInterrupt
