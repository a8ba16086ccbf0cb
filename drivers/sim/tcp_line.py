"""A simulated gauge's line on a TCP socket, for systems without pseudo-terminals.

The gauge listens on 127.0.0.1 at an ephemeral port; the driver opens the URL
``socket://127.0.0.1:PORT`` with pyserial, which carries a serial line's bytes over
the connection as they are (no framing, no settings: the baud rate and parity a
driver sets are ignored, as a pty ignores them). One connection at a time, as one
program has a serial port open: a new one (a driver reopening its port) replaces
the one before.

Pulling the plug closes the listener and the connection: the driver's open port
fails (pyserial: "socket disconnected") and a reopen is refused, as with a pulled
adapter. Plugged in again, the line listens at the same port, so the same URL
reaches it, as a ``/dev/serial/by-id`` link reaches a replugged adapter.

Only sockets are waited on (``select`` on Windows takes nothing else): the wake-up
is a socket pair.
"""

from __future__ import annotations

import contextlib
import os
import select
import socket

HOST = "127.0.0.1"


class TcpLine:
    """A :class:`~drivers.sim.gauge_lines.GaugeLine` on 127.0.0.1 (module docstring)."""

    def __init__(self, name: str = "gauge") -> None:
        self.name = name
        self._port = 0  # chosen by the system at the first plug_in, then kept
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)

    @property
    def port(self) -> str:
        return f"socket://{HOST}:{self._port}"

    @property
    def stable(self) -> bool:
        return True

    def plug_in(self) -> None:
        listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            if os.name != "nt":
                # Listen again at the same port while the last connection's TIME_WAIT
                # lasts (on Windows this option would let another socket take the port).
                listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            listener.bind((HOST, self._port))
            listener.listen(4)
            listener.setblocking(False)
        except BaseException:
            listener.close()
            raise
        self._port = listener.getsockname()[1]
        self._listener = listener

    def bound(self) -> tuple[str, int]:
        """The address the line listens at (while plugged in)."""
        if self._listener is None:
            raise OSError("the line is unplugged")
        host, port = self._listener.getsockname()[:2]
        return str(host), int(port)

    def pull_plug(self) -> None:
        self._drop_client()
        listener, self._listener = self._listener, None
        if listener is not None:
            listener.close()

    def _drop_client(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            client.close()

    def _accept(self) -> None:
        assert self._listener is not None
        try:
            client, _ = self._listener.accept()
        except (BlockingIOError, InterruptedError, ConnectionError):
            return  # the caller gave up before it was accepted
        self._drop_client()
        client.setblocking(False)
        # each write leaves at once, as the characters of a line do
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._client = client

    def receive(self, timeout_s: float) -> bytes | None:
        if self._listener is None:
            raise OSError("the line is unplugged")
        waiting = [self._listener, self._wake_r] + ([self._client] if self._client else [])
        ready, _, _ = select.select(waiting, [], [], timeout_s)
        if self._wake_r in ready:
            with contextlib.suppress(BlockingIOError):
                self._wake_r.recv(512)
        if self._listener in ready:
            self._accept()
            return None
        client = self._client
        if client is None or client not in ready:
            return None
        try:
            data = client.recv(1024)
        except (BlockingIOError, InterruptedError):
            return None
        except OSError:  # reset by the driver: its port is closed
            data = b""
        if not data:  # the driver closed its port; the line waits for the next opener
            self._drop_client()
            return None
        return data

    def write(self, data: bytes) -> None:
        client = self._client
        if client is None:
            return  # nobody has the port open: the bytes go nowhere
        view = memoryview(data)
        try:
            while view:
                view = view[client.send(view):]
        except BlockingIOError:
            pass  # the driver's buffer is full: the rest is lost, as on an overrun UART
        except OSError:
            self._drop_client()  # the driver went away mid-reply

    def wake(self) -> None:
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")

    def close(self) -> None:
        self.pull_plug()
        self._wake_r.close()
        self._wake_w.close()
