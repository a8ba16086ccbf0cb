"""Digital dial indicators on serial lines.

One :class:`SerialIndicator` drives one gauge on one line, speaking a
protocol of :mod:`drivers.indicator_protocols` (protocols are data, not code);
:class:`IndicatorGroup` reads several lines in parallel, because the station
reads every mounted gauge at each stop and the lines are independent.

Failure model of one reading: a missing, partial, garbled or gauge-error reply
is retried (bounded, each retry reported through ``on_event`` so the station
can journal it); a port that fails at the OS level (unplugged USB adapter) is
closed and opened again, by its path, until ``reopen_s`` has passed (a stable
path such as ``/dev/serial/by-id/...`` comes back when the adapter is plugged
in again; each attempt is reported), then the reading goes on; a port still
gone after that raises :class:`~drivers.device_errors.IndicatorPortError`. Opening
the indicator waits for its port within the same budget.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from types import TracebackType
from typing import Any, Self

import serial

from drivers.base import Indicator
from drivers.device_errors import (
    IndicatorError,
    IndicatorPortError,
    IndicatorReplyError,
    IndicatorTimeout,
)
from drivers.indicator_protocols import IndicatorProtocol, ReplyParser, make_protocol

# What a serial port raises when the OS loses it (an unplugged adapter): the
# driver reopens the port, the bring-up probe (drivers.bringup) reports it.
try:  # termios.error is not an OSError, and pyserial lets it through from tcflush
    import termios

    PORT_ERRORS: tuple[type[BaseException], ...] = (OSError, termios.error)
except ImportError:  # pragma: no cover - not POSIX
    PORT_ERRORS = (OSError,)

EventSink = Callable[[dict[str, Any]], None]


def port_missing(port: str) -> bool:
    """Whether ``port`` names a local serial device that is not there now. A
    pyserial URL (``rfc2217://…``, ``socket://…``) is reached over the network and
    cannot be told missing before it is opened: never missing here. A path that
    resolves nowhere (a ``/dev/serial/by-id`` link whose adapter is unplugged) is
    missing: the driver waits ``reopen_s`` for one that vanishes mid-run, but
    before a run nothing is coming back, and the caller says so at once."""
    if "://" in port:
        return False
    if os.name == "nt":  # COM3 is no file; the system's list says what is plugged in
        from serial.tools import list_ports

        wanted = port.removeprefix("\\\\.\\").upper()
        return wanted not in {p.device.upper() for p in list_ports.comports()}
    return not os.path.exists(port)

# A reply longer than this without its terminator is a babbling line, not a slow gauge.
MAX_REPLY_BYTES = 256


def _os_reason(e: BaseException) -> str:
    """What the OS said, once: pyserial wraps the OSError of open() as "[Errno 2]
    could not open port P: [Errno 2] No such file or directory: 'P'", which says the
    errno twice and the port the device's name already gives."""
    cause = e.__context__
    if isinstance(cause, OSError) and cause.strerror:
        return cause.strerror
    return str(e)


class SerialIndicator:
    """One gauge on one serial line; satisfies :class:`drivers.base.Indicator`.

    ``port`` is anything ``serial_factory`` accepts (a device path or a pyserial
    URL such as ``rfc2217://host:port``). The port is opened here, so a wrong
    path fails at set-up rather than mid-run; after a port fault the next read
    reopens it, which is what a replugged USB adapter needs.

    ``timeout_s`` bounds the wait for the next byte of a reply, and also the
    whole reply (checked between bytes), so one attempt lasts at most about
    twice ``timeout_s``. A reading makes at most ``1 + retries`` attempts.
    """

    def __init__(
        self,
        name: str,
        port: str,
        protocol: IndicatorProtocol | str,
        *,
        timeout_s: float = 1.0,
        retries: int = 3,
        on_event: EventSink | None = None,
        serial_factory: Callable[..., Any] = serial.serial_for_url,
        reopen_s: float = 10.0,
    ) -> None:
        if timeout_s <= 0:
            raise ValueError("timeout_s must be positive")
        if not reopen_s >= 0:
            raise ValueError("reopen_s must be >= 0")
        if retries < 0:
            raise ValueError("retries must be >= 0")
        self.name = name
        self.port = port
        self.protocol = make_protocol(protocol) if isinstance(protocol, str) else protocol
        self.timeout_s = timeout_s
        self.retries = retries
        self.on_event = on_event
        self._factory = serial_factory
        self._parser = ReplyParser(self.protocol)
        # Serial objects are not thread-safe; a group and a direct caller may share us.
        self._lock = threading.Lock()
        self._serial: Any = None
        self._closed = False
        self.reopen_s = float(reopen_s)
        self._open_within("cannot open port")

    @property
    def device(self) -> str:
        return f"indicator {self.name} ({self.port})"

    def _open(self) -> Any:
        try:
            self._serial = self._factory(
                self.port,
                timeout=self.timeout_s,
                write_timeout=self.timeout_s,
                **self.protocol.serial_settings(),
            )
        except PORT_ERRORS as e:
            raise IndicatorPortError(self.device, f"cannot open port: {_os_reason(e)}") from e
        return self._serial

    def _open_within(self, why: str, announce: bool = False) -> Any:
        """Open the port, trying again until ``reopen_s`` has passed (an adapter being
        plugged in takes a second or two to appear); every failed try is reported."""
        started = time.monotonic()
        attempt = 0
        while True:
            attempt += 1
            try:
                ser = self._open()
            except IndicatorPortError as e:
                elapsed = time.monotonic() - started
                remaining = self.reopen_s - elapsed
                if remaining <= 0:
                    detail = e.message if attempt == 1 else (
                        f"{e.message}; still gone after {self.reopen_s:g} s "
                        f"({attempt} attempt(s))")
                    raise IndicatorPortError(self.device, detail) from e
                self._emit({"event": "reopen", "device": self.device, "indicator": self.name,
                            "port": self.port, "attempt": attempt, "error": why,
                            "elapsed_s": round(elapsed, 3)})
                time.sleep(min(0.05 * 2 ** min(attempt, 4), 0.5, remaining))
                continue
            if attempt > 1 or announce:
                self._emit({"event": "reopened", "device": self.device, "indicator": self.name,
                            "port": self.port, "attempts": attempt,
                            "elapsed_s": round(time.monotonic() - started, 3)})
            return ser

    def _drop_port(self) -> None:
        ser, self._serial = self._serial, None
        if ser is not None:
            try:
                ser.close()
            except PORT_ERRORS:
                pass  # the port is already gone; nothing more to release

    def read(self) -> float:
        """One reading in mm."""
        with self._lock:
            return self._read_locked()

    def read_n(self, n: int) -> list[float]:
        """``n`` consecutive readings in mm (each with its own retries)."""
        if n < 0:
            raise ValueError("n must be >= 0")
        with self._lock:
            return [self._read_locked() for _ in range(n)]

    def _read_locked(self) -> float:
        if self._closed:
            raise IndicatorPortError(self.device, "indicator is closed")
        failures: list[IndicatorError] = []
        attempts = 1 + self.retries
        for attempt in range(1, attempts + 1):
            ser = self._serial if self._serial is not None else \
                self._open_within("port was lost")
            try:
                return self._exchange(ser)
            except serial.SerialTimeoutException as e:
                # A write that cannot leave (flow control held) is a stuck line, not
                # a dead port: worth a retry.
                err: IndicatorError = IndicatorTimeout(self.device, f"write timed out: {e}")
            except (IndicatorTimeout, IndicatorReplyError) as e:
                err = e
            except PORT_ERRORS as e:
                # The adapter went away (or is going): reopen it by its path within
                # the budget, then take the reading again. Never retry on a port
                # that failed: its half-read reply is lost with it.
                self._drop_port()
                try:
                    self._open_within(f"port failed: {e}", announce=True)
                except IndicatorPortError as gone:
                    raise IndicatorPortError(
                        self.device, f"port failed: {e}; {gone.message}") from e
                # Bounded like any attempt; the reopen events already say what happened.
                failures.append(IndicatorPortError(self.device, f"port failed (reopened): {e}"))
                continue
            failures.append(err)
            if attempt < attempts:
                self._emit(
                    {
                        "event": "retry",
                        "device": self.device,
                        "indicator": self.name,
                        "port": self.port,
                        "attempt": attempt,
                        "error": err.message,
                    }
                )
        last = failures[-1]
        raise type(last)(
            self.device, f"no valid reply after {attempts} attempt(s); last: {last.message}"
        ) from last

    def _emit(self, event: dict[str, Any]) -> None:
        if self.on_event is not None:
            self.on_event(event)

    def _exchange(self, ser: Any) -> float:
        term = self.protocol.terminator
        # Whatever arrived unasked (a late reply to an earlier attempt, line noise)
        # would otherwise be taken for the answer to this request.
        ser.reset_input_buffer()
        ser.write(self.protocol.request)
        deadline = time.monotonic() + self.timeout_s
        buf = b""
        while True:
            # read_until() would fetch one byte per call; asking for what is already
            # buffered (at least one byte, which blocks up to the port timeout) gets
            # the reply in as few system calls as the line allows.
            chunk = ser.read(ser.in_waiting or 1)
            if not chunk:
                if buf:
                    raise IndicatorTimeout(
                        self.device, f"partial reply {buf!r} (no terminator {term!r})"
                    )
                raise IndicatorTimeout(self.device, f"no reply within {self.timeout_s:g} s")
            buf += chunk
            end = buf.find(term)
            if end >= 0:
                return self._parser.parse(buf[:end], self.device)
            if len(buf) > MAX_REPLY_BYTES:
                raise IndicatorReplyError(
                    self.device, f"garbled reply {buf[:40]!r}... (no terminator)"
                )
            if time.monotonic() > deadline:
                raise IndicatorTimeout(
                    self.device,
                    f"partial reply {buf!r} (no terminator within {self.timeout_s:g} s)",
                )


    def close(self) -> None:
        with self._lock:
            self._closed = True
            self._drop_port()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"SerialIndicator({self.name!r}, {self.port!r}, {self.protocol.name!r})"


class IndicatorGroup:
    """Several indicators read at the same time, one worker per serial line.

    The lines are independent, so reading six gauges should take as long as
    reading one; the workers are kept between reads (a thread per read would
    cost more than a short reply). The group owns its indicators: ``close()``
    closes them and joins every worker.
    """

    def __init__(self, indicators: Sequence[Indicator]) -> None:
        self._indicators: dict[str, Indicator] = {}
        for ind in indicators:
            if ind.name in self._indicators:
                raise ValueError(f"two indicators named {ind.name!r}")
            self._indicators[ind.name] = ind
        self._pool = ThreadPoolExecutor(
            max_workers=max(1, len(self._indicators)), thread_name_prefix="indicators"
        )
        self._closed = False

    @property
    def names(self) -> list[str]:
        return list(self._indicators)

    def __getitem__(self, name: str) -> Indicator:
        return self._indicators[name]

    def __len__(self) -> int:
        return len(self._indicators)

    def read(self, n: int = 1, names: Sequence[str] | None = None) -> dict[str, list[float]]:
        """``n`` readings from each named indicator (all by default), concurrently.

        Every started read is allowed to finish (each has its own bounded
        timeout) before anything is raised, so no worker is still talking on a
        line when the caller moves on. Then the first failure in ``names``
        order is raised; indicator faults already name their indicator, other
        exceptions get a note saying which one.
        """
        if self._closed:
            raise RuntimeError("indicator group is closed")
        selected = self.names if names is None else list(names)
        unknown = [x for x in selected if x not in self._indicators]
        if unknown:
            raise KeyError(f"unknown indicator(s): {', '.join(unknown)}")
        futures: dict[str, Future[list[float]]] = {
            x: self._pool.submit(self._indicators[x].read_n, n) for x in selected
        }
        results: dict[str, list[float]] = {}
        first: BaseException | None = None
        for x, fut in futures.items():
            try:
                results[x] = fut.result()
            except Exception as e:
                if first is None:
                    if not isinstance(e, IndicatorError):
                        e.add_note(f"while reading indicator {x}")
                    first = e
        if first is not None:
            raise first
        return results

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._pool.shutdown(wait=True, cancel_futures=True)
        for ind in self._indicators.values():
            ind.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
