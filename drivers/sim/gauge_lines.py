"""The simulated gauge's end of its serial line, wherever the line runs.

A :class:`~drivers.sim.pty_gauges.SimIndicator` speaks its protocol (requests,
replies, their timing and faults) into a :class:`GaugeLine`; the driver opens
the other end, ``GaugeLine.port``, with pyserial's ``serial_for_url`` as it opens
any port. Two kinds (:data:`LINES`):

* ``"pty"``: a pseudo-terminal (:mod:`drivers.sim.pty_line`); ``port`` is its path
  (or a stable link to it). What a real adapter's ``/dev/ttyUSB0`` is, on systems
  that have pseudo-terminals (Linux, macOS).
* ``"tcp"``: a socket on 127.0.0.1, an ephemeral port (:mod:`drivers.sim.tcp_line`);
  ``port`` is the URL ``socket://127.0.0.1:PORT``, which pyserial opens as a
  serial port. For systems without pseudo-terminals (Windows).

Each kind is imported only when a line of it is opened: the pseudo-terminal's
modules (``tty``) do not exist on Windows.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path
from typing import Protocol

#: The kinds of line a simulated gauge can be served on (module docstring).
LINES = ("pty", "tcp")


class GaugeLine(Protocol):
    """One gauge's end of its line. ``plug_in``/``pull_plug`` make and remove what the
    driver opens (an unplugged adapter); ``close`` also frees what waking needs."""

    @property
    def port(self) -> str:
        """What the driver opens (pyserial's ``serial_for_url``)."""
        ...

    @property
    def stable(self) -> bool:
        """Whether ``port`` stays the same when the line is plugged in again."""
        ...

    def plug_in(self) -> None: ...

    def pull_plug(self) -> None: ...

    def receive(self, timeout_s: float) -> bytes | None:
        """What the driver sent, waiting up to ``timeout_s`` (None: nothing, or woken by
        :meth:`wake`); raises OSError when nothing can arrive any more."""
        ...

    def write(self, data: bytes) -> None:
        """Send ``data`` to the driver; bytes that do not fit are lost, as on an
        overrun UART, and nothing blocks."""
        ...

    def wake(self) -> None:
        """End a :meth:`receive` in progress at once."""
        ...

    def close(self) -> None: ...


def pseudo_terminals() -> bool:
    """Whether this system has pseudo-terminals a simulated gauge can be served on."""
    if not hasattr(os, "openpty"):
        return False
    try:
        return importlib.util.find_spec("tty") is not None
    except ImportError:  # a system whose tty cannot be loaded
        return False


def default_line() -> str:
    """``"pty"`` where the system has pseudo-terminals, else ``"tcp"``."""
    return "pty" if pseudo_terminals() else "tcp"


def open_line(kind: str, name: str, link: str | os.PathLike[str] | None = None) -> GaugeLine:
    """A line of ``kind`` (:data:`LINES`) for the gauge ``name``, plugged in; ``link``:
    a stable path to a pty (a TCP line's URL is stable by itself)."""
    if kind == "pty":
        if not pseudo_terminals():
            raise OSError("this system has no pseudo-terminals: serve the gauges over tcp")
        from drivers.sim.pty_line import PtyLine

        line: GaugeLine = PtyLine(None if link is None else Path(link))
    elif kind == "tcp":
        from drivers.sim.tcp_line import TcpLine

        line = TcpLine(name)
    else:
        raise ValueError(f"a gauge's line is one of {', '.join(LINES)}, got {kind!r}")
    try:
        line.plug_in()
    except BaseException:
        line.close()
        raise
    return line
