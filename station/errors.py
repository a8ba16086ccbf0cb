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


def why_not(exc: OSError) -> str:
    """What a file system's refusal means, in words for the operator (a full disk said
    as such)."""
    import errno

    words = {
        errno.ENOENT: "no such file or folder",
        errno.ENOTDIR: "a file stands where a folder is expected",
        errno.EISDIR: "a folder, not a file",
        errno.EEXIST: "exists already",
        errno.EACCES: "permission denied",
        errno.EPERM: "not permitted",
        errno.EROFS: "a read-only file system",
        errno.ENOSPC: "the disk is full (no space left on the device)",
        errno.EFBIG: "the disk is full for this run (file-size limit reached)",
        errno.EDQUOT: "the disk quota is exceeded",
        errno.ENAMETOOLONG: "the name is too long",
    }
    return words.get(exc.errno or 0) or (exc.strerror or str(exc))


def storage_message(path: Path, exc: OSError) -> str:
    """One line saying what could not be saved and why, naming a full disk as such."""
    import errno

    if exc.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
        return f"{path}: {why_not(exc)}"
    return f"{path}: cannot write ({why_not(exc)})"


def path_message(exc: OSError) -> str:
    """An OSError nobody caught nearer, in one line naming its path(s) where it has any."""
    where = " → ".join(str(f) for f in (exc.filename, exc.filename2) if f is not None)
    return f"{where}: {why_not(exc)}" if where else why_not(exc)


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
