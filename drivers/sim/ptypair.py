"""A virtual null-modem cable: two pseudo-terminals bridged by a copy thread.

A single ``os.openpty()`` gives one named end (the slave) and an anonymous
master; a Modbus RTU server and a client both want a *path* to open. So two pty
pairs are opened and a thread copies bytes between the two masters: whatever is
written to ``path_a`` can be read from ``path_b`` and vice versa, like two
serial ports joined by a null-modem cable (what ``socat pty,raw pty,raw`` does).
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import tty


class PtyPair:
    """Two named serial ends, ``path_a`` and ``path_b``. ``open()``/``close()``
    (or use as a context manager); ``close()`` leaves no thread or fd behind."""

    def __init__(self, name: str = "orthocal-ptypair") -> None:
        self.name = name
        self.path_a = ""
        self.path_b = ""
        self._fds: list[int] = []
        self._thread: threading.Thread | None = None
        self._wake_w = -1

    def open(self) -> PtyPair:
        if self._thread is not None:
            return self
        m1, s1 = os.openpty()
        m2, s2 = os.openpty()
        wake_r, wake_w = os.pipe()
        self._fds = [m1, s1, m2, s2, wake_r, wake_w]
        # Raw mode before anyone opens the ends: no echo, no CR/NL translation, no
        # line buffering -- Modbus RTU frames are binary. Keeping our own slave fds
        # open also keeps the masters from reading EIO between clients.
        for fd in (s1, s2):
            tty.setraw(fd)
        self.path_a = os.ttyname(s1)
        self.path_b = os.ttyname(s2)
        self._wake_w = wake_w
        self._thread = threading.Thread(target=self._pump, args=(m1, m2, wake_r),
                                        name=self.name, daemon=True)
        self._thread.start()
        return self

    def _pump(self, m1: int, m2: int, wake_r: int) -> None:
        route = {m1: m2, m2: m1}
        while True:
            try:
                ready, _, _ = select.select([m1, m2, wake_r], [], [])
            except (OSError, ValueError):
                return
            if wake_r in ready:
                return
            for src in ready:
                try:
                    data = os.read(src, 4096)
                except OSError:
                    continue
                view = memoryview(data)
                while view:
                    try:
                        n = os.write(route[src], view)
                    except OSError:
                        break
                    view = view[n:]

    def close(self) -> None:
        if self._thread is not None:
            with contextlib.suppress(OSError):
                os.write(self._wake_w, b"x")
            self._thread.join(timeout=5.0)
            self._thread = None
        for fd in self._fds:
            with contextlib.suppress(OSError):
                os.close(fd)
        self._fds = []

    def __enter__(self) -> PtyPair:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()
