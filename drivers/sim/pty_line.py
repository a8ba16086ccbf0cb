"""A simulated gauge's line on a pseudo-terminal (Linux, macOS).

The gauge keeps the master; the driver opens the slave's path, or ``link``, a
stable path to it as ``/dev/serial/by-id/...`` is to a real adapter. Pulling the
plug closes both ends: the path disappears (and the link with it), the driver's
open port fails with EIO and a reopen finds no device. Beware that the kernel may
reuse a path for a pty created later: a replugged line gets a new pty, which only
the link follows.
"""

from __future__ import annotations

import contextlib
import os
import select
import tty
from pathlib import Path


class PtyLine:
    """A :class:`~drivers.sim.gauge_lines.GaugeLine` on a pseudo-terminal pair."""

    def __init__(self, link: Path | None = None) -> None:
        self.link = None if link is None else os.fspath(link)
        self._master = self._slave = -1
        #: The slave's path (the pty the link points at), once plugged in.
        self.tty = ""
        self._wake_r, self._wake_w = os.pipe()

    @property
    def port(self) -> str:
        return self.link if self.link is not None else self.tty

    @property
    def stable(self) -> bool:
        return self.link is not None

    def plug_in(self) -> None:
        master, slave = os.openpty()
        # Raw on both ends: otherwise the line discipline turns CR into LF and
        # echoes requests back to the driver.
        tty.setraw(master)
        tty.setraw(slave)
        # A full slave buffer (nobody reading) must drop bytes, as a UART
        # overrun does, never block the simulator thread.
        os.set_blocking(master, False)
        self._master = master
        # Keep the slave open: with no slave opener the master reads EIO, which
        # would make select() spin while the driver has the port closed.
        self._slave = slave
        self.tty = os.ttyname(slave)
        if self.link is not None:
            tmp = f"{self.link}.new"
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            os.symlink(self.tty, tmp)
            os.replace(tmp, self.link)  # the link never points nowhere while plugged

    def pull_plug(self) -> None:
        if self.link is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.link)
        for attr in ("_master", "_slave"):
            fd = getattr(self, attr)
            if fd >= 0:
                setattr(self, attr, -1)
                os.close(fd)

    def receive(self, timeout_s: float) -> bytes | None:
        ready, _, _ = select.select([self._master, self._wake_r], [], [], timeout_s)
        if self._wake_r in ready:
            os.read(self._wake_r, 512)
        if self._master not in ready:
            return None
        try:
            return os.read(self._master, 1024)
        except (BlockingIOError, InterruptedError):
            return None
        # any other OSError (EIO: the slave side went away) is the caller's: the end

    def write(self, data: bytes) -> None:
        try:
            os.write(self._master, data)
        except BlockingIOError:
            pass  # slave buffer full: the bytes are lost, as on an overrun UART

    def wake(self) -> None:
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def close(self) -> None:
        self.pull_plug()
        for attr in ("_wake_r", "_wake_w"):
            fd = getattr(self, attr)
            if fd >= 0:
                setattr(self, attr, -1)
                os.close(fd)
