"""Simulated dial indicators behind pseudo-terminals, or TCP sockets where there are none.

Each :class:`SimIndicator` owns the gauge's end of a serial line
(:mod:`drivers.sim.gauge_lines`): a pty pair whose master the simulator keeps
(``line="pty"``, the default), or a socket on 127.0.0.1 (``line="tcp"``, for
Windows). ``.port`` is the other end, the slave's path or the URL
``socket://127.0.0.1:PORT``, which the real driver opens with pyserial like any
other serial port. So tests and dry runs exercise the driver's real byte handling;
only the gauge is virtual. Both lines carry the same bytes: the protocol, its
timing and its faults are the gauge's, here; the line only moves them.

What a pty (or a socket) does not do, the simulator emulates:

* line time: a pty delivers at memory speed whatever the baud rate, so with
  ``baud`` set a request counts as arrived only once its characters would
  have crossed the line, and the reply leaves one character per character
  time (10 or 11 bit-times each, from the protocol's framing), divided by
  ``time_scale`` for a gauge of a virtual station on a faster clock (late
  replies, ``late_s``, and unplugging times stay real: they are measured
  against the driver's real timeouts);
* faults (:class:`~drivers.sim.faults.IndicatorFaults`, changeable while running, drawn from a
  seeded RNG so a failing run can be replayed).

Unplugging (``faults.unplugged = True`` or :meth:`SimIndicator.unplug`) removes
the line's end: both pty ends close, the path disappears, the driver's open port
fails with EIO and a reopen finds no device, as with a pulled USB adapter (a TCP
line stops listening: the connection drops, a reopen is refused). Beware that the
kernel may reuse a pty's path for a pty created later. With ``link`` (a stable
path, as ``/dev/serial/by-id/...`` is) :attr:`SimIndicator.port` is that symlink:
an unplug removes it, :meth:`SimIndicator.replug` opens a new pty and points the
link at it (``unplug_for(s)`` does both, s apart), so a driver that opened the
link can open it again. A TCP line is plugged back at the same port: its URL is
stable by itself.

An unmounted indicator (``unmount()``) answers as a gauge lying on the bench
does: a constant reading (``unmounted_mm``) plus noise.

A scale error (``scale_error`` S, relative): the gauge shows (1 + S) times its
plunger's travel from where it was zeroed, as a gauge whose scale is off by
S·100 % does; its noise and its digits come on top, as on a real
one. The stroke and its clamp are the plunger's, so they stay in true mm.

A finite plunger (``stroke_mm``, mounted pushed in by ``preload_mm``, default
half the stroke): the reading is the plunger's travel from where it was
mounted (+ pushed in), so it clamps at −preload (the leg has left the fully
extended plunger) and at stroke − preload (the plunger is at its stop).
``clamped`` counts the readings taken there; a plunger driven past an end
between two readings goes unseen by it, which is why the virtual station counts
out-of-stroke moves from the trajectory itself (drivers.sim.strokes), with this
gauge's own :meth:`SimIndicator.travel_mm` and :meth:`SimIndicator.stroke_limits`.
"""

from __future__ import annotations

import math
import os
import random
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any, Self

from drivers.indicator_protocols import IndicatorProtocol, make_protocol
from drivers.sim.faults import IndicatorFaults
from drivers.sim.gauge_lines import GaugeLine, open_line

Source = Callable[[], float]

# Bytes a corrupted reply may contain: none of them fits any built-in reply
# grammar, so a corruption is always detectable (a real line would flag it by
# parity or framing; a digit turned into another digit would not be a fault
# but a wrong measurement, which is not what this knob models).
_JUNK = b"#%&*@~!$"

#: A reply's characters reach the reader in bursts no closer than this (s): a USB
#: serial adapter hands them over on its latency timer (1–16 ms), not one by one.
#: Each is still never early, and the last one is on time; at the tests' time scale
#: a reply of 52 µs characters costs one write instead of twenty wake-ups a side.
BURST_S = 0.002


class SimIndicator:
    """A virtual dial indicator on a pseudo-terminal (``line="pty"``) or a TCP socket
    on 127.0.0.1 (``line="tcp"``).

    Reading = ``(1 + scale_error) * sign * (source() - zero) + noise``, quantised to
    ``resolution_mm`` and written in the protocol's ``reply_format``. ``zero``
    is ``zero_mm`` if given, else ``source()`` at construction / :meth:`mount`
    / :meth:`zero` (the gauge's ZERO button). ``source`` is called from the
    simulator's thread.
    """

    def __init__(
        self,
        protocol: IndicatorProtocol | str,
        source: Source,
        *,
        noise_mm: float = 0.0,
        resolution_mm: float = 0.001,
        zero_mm: float | None = None,
        sign: int = +1,
        baud: int | None = None,
        faults: IndicatorFaults | None = None,
        seed: int | None = None,
        name: str = "A",
        unmounted_mm: float = 0.0,
        stroke_mm: float | None = None,
        preload_mm: float | None = None,
        link: str | os.PathLike[str] | None = None,
        time_scale: float = 1.0,
        scale_error: float = 0.0,
        line: str = "pty",
    ) -> None:
        self.protocol = make_protocol(protocol) if isinstance(protocol, str) else protocol
        if self.protocol.reply_format is None:
            raise ValueError(f"protocol {self.protocol.name!r} has no reply_format to answer in")
        if sign not in (1, -1):
            raise ValueError("sign must be +1 or -1")
        if resolution_mm <= 0 or noise_mm < 0:
            raise ValueError("resolution_mm must be > 0 and noise_mm >= 0")
        if baud is not None and baud <= 0:
            raise ValueError("baud must be positive")
        if not time_scale > 0:
            raise ValueError("time_scale must be > 0")
        if not (math.isfinite(scale_error) and abs(scale_error) < 1.0):
            raise ValueError(f"scale_error must be a relative error within ±1, "
                             f"got {scale_error}")
        #: The gauge's relative scale error S: it shows (1 + S)·travel.
        self.scale_error = float(scale_error)
        self.name = name
        self.noise_mm = noise_mm
        self.resolution_mm = resolution_mm
        self.sign = sign
        self.baud = baud
        self.faults = faults if faults is not None else IndicatorFaults()
        self.unmounted_mm = unmounted_mm
        if stroke_mm is not None and not stroke_mm > 0:
            raise ValueError("stroke_mm must be > 0")
        if preload_mm is not None and (stroke_mm is None or not 0 <= preload_mm <= stroke_mm):
            raise ValueError("preload_mm needs a stroke_mm and must be within 0..stroke_mm")
        self.stroke_mm = stroke_mm
        self.preload_mm = (stroke_mm / 2.0 if preload_mm is None and stroke_mm is not None
                           else preload_mm)
        self.clamped = 0
        self.time_scale = float(time_scale)
        self._char_s = self.protocol.bits_per_char / baud / self.time_scale if baud else 0.0
        self._rng = random.Random(seed)
        #: Whether the axes are known at rest (the virtual station's machine says). A
        #: reading taken otherwise, one of the plunger guard's polls of a move, draws
        #: its noise from a stream of its own: the polls number what fits into the
        #: move's time, and drawn from one stream they would shift the noise of every
        #: later reading at a stop, so that a seeded run would not repeat.
        self.at_rest: Callable[[], bool] = lambda: True
        self._moving_rng = random.Random(None if seed is None else f"{seed}:moving")
        self._lock = threading.Lock()  # source/zero against the simulator thread
        self._source: Source | None = source
        self._zero = float(source()) if zero_mm is None else float(zero_mm)
        # Counters for tests and the benchmark: requests seen, replies begun.
        self.requests = 0
        self.replies = 0
        self.source_error: Exception | None = None  # the last exception source() raised
        #: Called (from the simulator's thread) with the fault's counter name
        #: ("drop_next", "error_next", "garble_next", "late_next") each time a request
        #: gets a fault: the gauge counts requests and replies, a soak counts faults.
        self.on_fault: Callable[[str], None] | None = None

        self.link = None if link is None else os.fspath(link)
        self._wire: GaugeLine = open_line(line, name, link)
        #: Which kind of line (drivers.sim.gauge_lines.LINES) the gauge is served on.
        self.line = line
        self.port: str = self._wire.port
        self._stop = threading.Event()
        self._pulled = threading.Event()
        self._thread: threading.Thread | None = None
        self._replug_timer: threading.Timer | None = None
        self._closed = False

    @property
    def tty(self) -> str:
        """The pty a pty line's port is (its link points at it); "" on a TCP line."""
        return str(getattr(self._wire, "tty", ""))

    # --- what the gauge shows ------------------------------------------------------

    def zero(self) -> None:
        """Take the current source position as zero (the gauge's ZERO button)."""
        with self._lock:
            if self._source is not None:
                self._zero = float(self._source())

    def mount(self, source: Source, zero_mm: float | None = None) -> None:
        """Put the plunger against ``source`` and zero there (or at ``zero_mm``)."""
        with self._lock:
            self._source = source
            self._zero = float(source()) if zero_mm is None else float(zero_mm)

    @property
    def zero_mm(self) -> float:
        """The source position the gauge reads 0 at."""
        with self._lock:
            return self._zero

    def unmount(self) -> None:
        """Take the gauge off: it then reads ``unmounted_mm`` (plus noise)."""
        with self._lock:
            self._source = None

    @property
    def mounted(self) -> bool:
        return self._source is not None

    def stroke_limits(self) -> tuple[float, float] | None:
        """(−preload, stroke − preload): the plunger travel the gauge can show
        (None: an endless plunger)."""
        if self.stroke_mm is None:
            return None
        assert self.preload_mm is not None  # set with the stroke
        return -self.preload_mm, self.stroke_mm - self.preload_mm

    def travel_mm(self, source_mm: Any) -> Any:
        """Plunger travel (+ pushed in) at source position(s) ``source_mm`` (a float
        or an array): sign·(source − zero), what a reading shows before the clamp.
        Reads the zero without the lock (one float, read atomically): the virtual
        station evaluates it under the machine's lock, which ``mount`` and ``zero``
        take while they hold this gauge's."""
        return self.sign * (source_mm - self._zero)

    def _value_mm(self) -> float:
        with self._lock:
            source, zero = self._source, self._zero
        raw = self.unmounted_mm if source is None else self.sign * (float(source()) - zero)
        limits = self.stroke_limits()
        if source is not None and limits is not None:
            low, high = limits
            if not low < raw < high:
                self.clamped += 1
                raw = min(max(raw, low), high)
        if source is not None:
            raw *= 1.0 + self.scale_error  # the scale is the display's: after the stop
        if self.noise_mm > 0:
            rng = self._rng if self.at_rest() else self._moving_rng
            raw += rng.gauss(0.0, self.noise_mm)
        # + 0.0 turns -0.0 into 0.0: a gauge shows +0.000, not -0.000.
        return round(raw / self.resolution_mm) * self.resolution_mm + 0.0

    def _line(self, value_mm: float) -> bytes:
        fmt = self.protocol.reply_format
        assert fmt is not None  # checked in __init__
        value = value_mm / self.protocol.mm_per_unit
        return fmt.format(value=value).encode("ascii") + self.protocol.terminator

    # --- faults --------------------------------------------------------------------

    def _take(self, rate: float, next_field: str) -> bool:
        """Whether this request gets a fault: a pending forced one, else by rate."""
        f = self.faults
        pending = getattr(f, next_field)
        if pending > 0:
            setattr(f, next_field, pending - 1)
            hit = True
        else:
            hit = rate > 0 and self._rng.random() < rate
        if hit and self.on_fault is not None:
            self.on_fault(next_field)
        return hit

    def _garble(self, line: bytes) -> bytes:
        body = line[: -len(self.protocol.terminator)]
        mode = self.faults.garble_mode
        if mode == "any":
            mode = self._rng.choice(("corrupt", "truncate"))
        if mode == "truncate" or not body:
            return body[: self._rng.randrange(0, max(1, len(body)))]
        out = bytearray(body)
        for _ in range(self._rng.randint(1, min(2, len(out)))):
            out[self._rng.randrange(len(out))] = self._rng.choice(_JUNK)
        return bytes(out) + self.protocol.terminator

    def _reply_for_request(self) -> tuple[bytes | None, float]:
        """(bytes to send or None, extra delay in s) for one request."""
        f = self.faults
        late = self._take(f.late_rate, "late_next")
        delay = f.late_s if late else 0.0
        if self._take(f.drop_rate, "drop_next"):
            return None, 0.0
        if self._take(f.error_rate, "error_next"):
            if self.protocol.error_format is None:
                return None, 0.0
            text = self.protocol.error_format.format(code=f.error_code)
            return text.encode("ascii") + self.protocol.terminator, delay
        try:
            value = self._value_mm()
        except Exception as e:
            # A failing source (the virtual machine) must not kill the gauge for
            # the rest of the run: this request goes unanswered, the error is kept.
            self.source_error = e
            return None, 0.0
        line = self._line(value)
        if self._take(f.garble_rate, "garble_next"):
            line = self._garble(line)
        return line, delay

    # --- thread --------------------------------------------------------------------

    def start(self) -> Self:
        if self._closed:
            raise RuntimeError("simulator is closed")
        if self._thread is None:
            self._thread = threading.Thread(
                target=self._run, name=f"sim-indicator-{self.name}", daemon=True
            )
            self._thread.start()
        return self

    def unplug(self, timeout_s: float = 2.0) -> None:
        """Pull the plug now (see the module docstring); returns once the pty is gone."""
        self.faults.unplugged = True
        if self._thread is None or not self._thread.is_alive():
            self._pull_plug()
            return
        self._wake()
        if not self._pulled.wait(timeout_s):
            raise TimeoutError(f"simulated indicator {self.name} did not unplug in {timeout_s} s")

    def replug(self) -> None:
        """Plug the adapter back in: a new pty behind the same ``link``, or a TCP line
        listening at its port again."""
        if not self._wire.stable:
            raise RuntimeError("replug needs a stable link (the pty path would change)")
        if self._closed:
            return
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None
        self._pull_plug()
        self._pulled.clear()
        self._wire.plug_in()
        self.faults.unplugged = False
        self.start()

    def unplug_for(self, seconds: float) -> None:
        """Pull the plug now and plug it back ``seconds`` later (in the background)."""
        self.unplug()
        timer = threading.Timer(seconds, self.replug)
        timer.name = f"sim-indicator-{self.name}-replug"
        timer.daemon = True
        self._replug_timer = timer
        timer.start()

    def close(self, timeout_s: float = 5.0) -> None:
        if self._closed:
            return
        timer = self._replug_timer
        if timer is not None:
            timer.cancel()
            if timer is not threading.current_thread():
                timer.join(timeout_s)
        self._stop.set()
        self._wake()
        if self._thread is not None:
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                raise RuntimeError(f"simulated indicator {self.name} thread did not stop")
        self._closed = True
        self._pull_plug()
        self._wire.close()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _wake(self) -> None:
        self._wire.wake()

    def _pull_plug(self) -> None:
        self._wire.pull_plug()
        self._pulled.set()

    def _sleep_until(self, t: float) -> bool:
        """Wait until monotonic time ``t``; False if closing or unplugged meanwhile."""
        remaining = t - time.monotonic()
        if remaining > 0.005:
            # Long waits (late replies) must end promptly on close().
            self._stop.wait(remaining)
        elif remaining > 0:
            time.sleep(remaining)
        return not (self._stop.is_set() or self.faults.unplugged)

    def _send(self, data: bytes, start: float) -> bool:
        """Write ``data`` as a line sending from ``start`` delivers it: no character
        before it would have fully arrived (absolute deadlines, so sleep overshoot does
        not accumulate), in bursts at least :data:`BURST_S` apart, as a USB serial
        adapter hands them over, and the last one exactly when it arrives."""
        if not self._char_s:
            self._write(data)
            return True
        sent, n = 0, len(data)
        last = start + n * self._char_s
        while sent < n:
            now = time.monotonic()
            arrived = n if now >= last else min(n, int((now - start) / self._char_s))
            if arrived > sent:
                self._write(data[sent:arrived])
                sent = arrived
                continue
            following = start + (sent + 1) * self._char_s
            if not self._sleep_until(min(last, max(following, now + BURST_S))):
                return False
        return True

    def _write(self, data: bytes) -> None:
        self._wire.write(data)  # what does not fit is lost, as on an overrun UART

    def _run(self) -> None:
        try:
            self._serve()
        finally:
            # However the loop ended (mid-reply included), an unplug means the line goes.
            if self.faults.unplugged and not self._stop.is_set():
                self._pull_plug()

    def _serve(self) -> None:
        request = self.protocol.request
        buf = b""
        while not self._stop.is_set():
            if self.faults.unplugged:
                return
            # The timeout only bounds how late a runtime change of faults.unplugged
            # is noticed; close() and unplug() wake the wait at once.
            try:
                data = self._wire.receive(0.05)
            except OSError:
                # EIO: the pty's slave side went away; nothing can be answered any more.
                return
            if not data:
                continue
            arrived = time.monotonic()
            buf += data
            while (i := buf.find(request)) >= 0:
                buf = buf[i + len(request) :]
                self.requests += 1
                if not self._answer(arrived):
                    return
                arrived = time.monotonic()  # a queued request waited for this reply
            # Keep only what could still be the start of a request.
            buf = buf[-(len(request) - 1) :] if len(request) > 1 else b""

    def _answer(self, arrived: float) -> bool:
        # The driver wrote the whole request at once; on a real line its last
        # character lands len(request) character times later.
        received = arrived + len(self.protocol.request) * self._char_s
        if not self._sleep_until(received):
            return False
        reply, delay = self._reply_for_request()
        if reply is None:
            return True
        start = time.monotonic()
        if delay and not self._sleep_until(start + delay):
            return False
        # Counted before sending: the driver may have the last byte (and its
        # caller look at this counter) before this thread runs again.
        self.replies += 1
        return self._send(reply, start + delay)
