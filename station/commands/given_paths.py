"""Paths the user names on the command line to be written (``run --out DIR``,
``sim --config-out FILE``, ``report --out FILE``, ``compensate --out FILE``,
``history --plot FILE``): checked before anything starts or moves, by trying the
file system itself (root passes every permission check, a /proc or a read-only
mount refuses all the same), so that one that cannot be written is bad input: one
line naming the option and the path, exit 2 (station.commands.cli), never a
failure halfway through.

A write that fails all the same afterwards (the disk filled meanwhile) is said in
one line naming the path by the command that writes."""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from pathlib import Path

from station.errors import BadInput, why_not


def folder_to_write(option: str, path: Path) -> None:
    """``path`` is a folder files can be made in, or can be made (its missing
    folders are made to try it, and removed again: a command refused later leaves
    nothing behind)."""
    missing: list[Path] = []
    p = path
    while not p.exists() and not p.is_symlink() and p != p.parent:
        missing.append(p)
        p = p.parent
    if not p.is_dir():
        where = "" if p == path else f" ({p})"
        raise BadInput(f"{option} {path}: a file stands where a folder is expected{where}")
    made: list[Path] = []
    try:
        for folder in reversed(missing):
            folder.mkdir()
            made.append(folder)
        os.rmdir(tempfile.mkdtemp(prefix=".orthocal-try-", dir=path))
    except OSError as exc:
        raise BadInput(f"{option} {path}: cannot make or write in this folder "
                       f"({why_not(exc)})") from None
    finally:
        for folder in reversed(made):
            with contextlib.suppress(OSError):
                folder.rmdir()


def file_to_write(option: str, path: Path, *, replace: bool) -> None:
    """``path`` can be written as a file: in a folder that exists and takes files,
    not a folder itself, not a device or a pipe (a file written whole is renamed
    over its target: a device node would be replaced), and, unless ``replace``,
    not there yet."""
    if path.exists() or path.is_symlink():
        if path.is_dir():
            raise BadInput(f"{option} {path}: a folder; give a file's name")
        if not replace:
            raise BadInput(f"{option} {path}: the file exists; not overwritten (remove it "
                           "or give another file)")
        if not stat.S_ISREG(path.stat().st_mode):
            raise BadInput(f"{option} {path}: not a regular file (a device or a pipe); "
                           "give a file's name")
    parent = path.parent
    if not parent.is_dir():
        what = "a file stands where a folder is expected" if parent.exists() else \
            "no such folder"
        raise BadInput(f"{option} {path}: {what} ({parent})")
    try:
        fd, name = tempfile.mkstemp(prefix=".orthocal-try-", dir=parent)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        raise BadInput(f"{option} {path}: cannot write in {parent} ({why_not(exc)})") from None


def write_new(option: str, path: Path, text: str) -> None:
    """``text`` into a new file ``path``, never over one that exists (made meanwhile
    too); what the file system refuses is bad input naming the option and the path."""
    try:
        fh = open(path, "x", encoding="utf-8")  # closed below, or removed if not whole
    except FileExistsError:
        raise BadInput(f"{option} {path}: the file exists; not overwritten") from None
    except OSError as exc:
        raise BadInput(f"{option} {path}: cannot write ({why_not(exc)})") from None
    try:
        with fh:
            fh.write(text)
    except OSError as exc:
        with contextlib.suppress(OSError):
            path.unlink()  # ours (made just now): nothing half-written is left
        raise BadInput(f"{option} {path}: cannot write ({why_not(exc)})") from None
