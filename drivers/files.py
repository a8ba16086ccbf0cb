"""Files that survive a crash or a power cut: written whole or not at all.

The one home of the atomic write used by the virtual drive's memory, the run
journal's companions (offsets backup, result.json) and report.html.
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from pathlib import Path


def fsync_dir(path: Path) -> None:
    """Make a new directory entry (a file created or renamed there) itself durable."""
    if os.name == "nt":
        return  # Windows opens no directory (EACCES); NTFS journals a rename itself
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomic(path: Path, text: str, mode: int = 0o644) -> None:
    """Write ``text`` to ``path`` so that a crash leaves either the old file or the
    new one, never half of it: a temporary file beside it, flushed and fsynced,
    renamed over it, and the rename fsynced in the directory (without that a
    power cut can lose it). ``mode``: the file's permissions (mkstemp's own 0600
    would hide a report from whoever looks after the machine)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            if hasattr(os, "fchmod"):  # Windows before Python 3.13: none, nor POSIX modes
                os.fchmod(fh.fileno(), mode)
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    try:
        fsync_dir(path.parent)
    except OSError as exc:
        # a file system that cannot sync a directory says so; any other failure
        # (a full disk, an I/O error) is the caller's to report
        if exc.errno not in (errno.EINVAL, errno.ENOTSUP, errno.EBADF):
            raise
