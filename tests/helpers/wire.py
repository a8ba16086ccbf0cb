"""The wire of a byte-exact protocol test, for every such test (imported by them), in the
style of pymeasure's ``expected_protocol``: a device's port replaced by a scripted
conversation of (sent, reply) pairs. Every pair must be used, in order, and no reply
byte left unread; a byte sent that the script does not expect fails at once, naming
both.

- :class:`Script`: the conversation itself. ``(None, reply)`` is bytes that arrive
  unasked (at the start, or right after the previous reply); a reply of None is a
  request the device never answers.
- :class:`ScriptedSerial`: a pyserial port that plays a script (the indicators' ports,
  and the port pymodbus's RTU client opens); ``chunk`` > 0 hides the input buffer and
  delivers at most ``chunk`` bytes per read, like a slow line.
- :class:`ScriptedSocket`: the socket pymodbus's TCP client creates, whose replies go
  through a real socketpair so that select() and recv() run unchanged.
- :func:`expected_protocol`: a device on a scripted port, checked when the test is done.
"""

from __future__ import annotations

import contextlib
import socket
from collections.abc import Callable, Iterator, Sequence
from typing import Protocol, TypeVar

Pair = tuple[bytes | None, bytes | None]  # (sent, or None: unasked; reply, or None: none)


class Script:
    """A conversation, played one request at a time."""

    def __init__(self, pairs: Sequence[Pair]) -> None:
        self.pairs = list(pairs)

    def unasked(self) -> bytes:
        """The bytes that arrive before anything more is sent."""
        out = bytearray()
        while self.pairs and self.pairs[0][0] is None:
            out += self.pairs.pop(0)[1] or b""
        return bytes(out)

    def answer(self, data: bytes) -> bytes:
        """The reply to ``data`` (and what arrives unasked after it), or a failure
        naming what was sent and what the script expected."""
        assert self.pairs, f"unexpected {data.hex(' ')} ({data!r}): the conversation is over"
        sent, reply = self.pairs.pop(0)
        assert sent is not None and data.hex(" ") == sent.hex(" "), \
            f"sent {data.hex(' ')} ({data!r}), expected {(sent or b'').hex(' ')} ({sent!r})"
        return (reply or b"") + self.unasked()


class Wire(Protocol):
    script: Script

    def unread(self) -> bytes: ...

    def close(self) -> None: ...


class ScriptedSerial:
    """A pyserial port that plays a script."""

    def __init__(self, pairs: Sequence[Pair], chunk: int = 0) -> None:
        self.script = Script(pairs)
        self.rx = bytearray(self.script.unasked())
        self.flushed = bytearray()
        self.chunk = chunk
        self.closed = False
        self.is_open = True
        self.inter_byte_timeout = 0.0

    @property
    def pairs(self) -> list[Pair]:
        return self.script.pairs

    @property
    def in_waiting(self) -> int:
        return 0 if self.chunk else len(self.rx)

    def reset_input_buffer(self) -> None:
        self.flushed += self.rx
        self.rx.clear()

    def write(self, data: bytes) -> int:
        self.rx += self.script.answer(data)
        return len(data)

    def read(self, size: int = 1) -> bytes:
        if self.chunk:
            size = min(size, self.chunk)
        out = bytes(self.rx[:size])
        del self.rx[:size]
        return out  # b"": the port's timeout elapsed with nothing received

    def unread(self) -> bytes:
        return bytes(self.rx)

    def close(self) -> None:
        self.closed = True
        self.is_open = False


class ScriptedSocket:
    """The socket of a TCP client, replies through a real socketpair."""

    def __init__(self, pairs: Sequence[Pair]) -> None:
        self.script = Script(pairs)
        self._ours, self._theirs = socket.socketpair()
        if first := self.script.unasked():
            self._theirs.sendall(first)

    @property
    def pairs(self) -> list[Pair]:
        return self.script.pairs

    def send(self, data: bytes) -> int:
        if reply := self.script.answer(data):
            self._theirs.sendall(reply)
        return len(data)

    def recv(self, size: int) -> bytes:
        return self._ours.recv(size)

    def setblocking(self, flag: bool) -> None:
        self._ours.setblocking(flag)

    def fileno(self) -> int:
        return self._ours.fileno()

    def getsockname(self) -> tuple[str, int]:
        return ("127.0.0.1", 50000)

    def unread(self) -> bytes:
        self._ours.setblocking(False)
        with contextlib.suppress(BlockingIOError):
            return self._ours.recv(4096)
        return b""

    def close(self) -> None:
        self._ours.close()
        self._theirs.close()


D = TypeVar("D")


@contextlib.contextmanager
def expected_protocol(wire: Wire, device: Callable[[], D],
                      close: Callable[[D], None]) -> Iterator[D]:
    """``device()`` on ``wire``, yielded to the test; afterwards every pair must have
    been used and every reply byte read. The device and the wire are closed however
    the test ends."""
    made = device()
    try:
        yield made
        assert wire.script.pairs == [], \
            f"{len(wire.script.pairs)} expected exchange(s) never happened: {wire.script.pairs}"
        assert wire.unread() == b"", f"reply bytes left unread: {wire.unread()!r}"
    finally:
        close(made)
        wire.close()
