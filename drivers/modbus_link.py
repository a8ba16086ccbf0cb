"""The Modbus link to an axis controller, TCP or RTU: the client, connecting and
reconnecting, every request with its bounded retries (each retry journaled
through ``on_event``), reading and writing the registers of a
:mod:`drivers.registers` map, and the reference check after a power cut.
:class:`drivers.axes.ModbusAxisController` builds the axes' behaviour on it; a
link of its own because how a request survives a flaky line is the same
whatever the request asks the axes to do.

Wire discipline:

* one request per quantity where the map allows it: the six ACTUAL registers in
  one block read, STATUS + ALARM_CODE in one read, the three targets in one
  multi-register write;
* pymodbus's own retries are off (``retries=0``); this driver retries a request at
  most ``retries`` times and reports each retry through ``on_event({"event":
  "retry", "device", "op", "error", "attempt"})`` so the station can journal it;
* no reply / undecodable reply (pymodbus raises ``ModbusIOException``) → retry,
  then :class:`ControllerTimeout`; exception 6 (busy) → retry after a short
  back-off, then :class:`ControllerBusy`; exception 3 on a target write →
  :class:`TargetRefused`; any other exception code → :class:`ExceptionResponse`;
  a lost connection (closed, reset, refused: the drive lost power, a cable) →
  reconnect, again and again within ``reconnect_s`` (each attempt reported as
  ``{"event": "reconnect", ...}``, success as ``"reconnected"``), then
  :class:`ControllerConnectionError`;
* after a reconnect, a request that failed for good, or one answered only on a
  retry after no reply (on a serial line a drive that lost power is only silent,
  and one off for less than the retries only late), the drive's STATUS is read
  before anything else: a drive
  that came back with HOMED clear (power cut) raises :class:`ControllerNotHomed`
  for every request but homing and status, so a position counted from a lost
  reference is never returned.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, Self, TypedDict

import numpy as np
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusIOException
from pymodbus.pdu import ModbusPDU

from drivers.base import AxisStatus
from drivers.device_errors import (
    ControllerBusy,
    ControllerConnectionError,
    ControllerError,
    ControllerNotHomed,
    ControllerTimeout,
    ExceptionResponse,
    TargetRefused,
)
from drivers.map_files import load_map
from drivers.registers import Register, RegisterMap, contiguous_runs, encode_int

_pymodbus_log = logging.getLogger("pymodbus")
if _pymodbus_log.level == logging.NOTSET:
    # pymodbus logs each timeout and dropped frame at ERROR; the station reports
    # faults itself (typed errors, journaled retries), so keep the console clean.
    _pymodbus_log.setLevel(logging.CRITICAL)

EXCEPTION_NAMES = {
    1: "illegal function",
    2: "illegal data address",
    3: "illegal data value",
    4: "server device failure",
    5: "acknowledge",
    6: "server device busy",
    8: "memory parity error",
    10: "gateway path unavailable",
    11: "gateway target failed to respond",
}

_READ_FC = {"holding": 3, "input": 4, "coil": 1, "discrete": 2}
# Requests that make sense on a drive that lost its reference: homing needs them.
_REFERENCE_FREE_OPS = frozenset({"read status", "home", "stop", "reset_alarm",
                                 "read offsets", "write offsets", "read back offsets"})
# A position further than this outside the last known span (last position to the
# last target) after a reconnect is a count that restarted, not motion.
_JUMP_MM = 0.05


class _SerialSettings(TypedDict):
    """The serial line's settings (RTU), as pymodbus's serial client takes them."""

    baudrate: int
    bytesize: int
    parity: str
    stopbits: int


class ModbusLink:
    """One Modbus controller (or one device per axis) behind ``port``: the TCP port
    for ``transport="tcp"`` or the serial device for ``"rtu"``.
    ``profile``/``overrides`` select the register map
    (:func:`drivers.map_files.load_map`). Use as a context manager, or call
    ``connect()`` / ``close()``.
    """

    def __init__(
        self,
        transport: str = "tcp",
        host: str = "127.0.0.1",
        port: int | str = 502,
        device_id: int = 1,
        profile: str | RegisterMap = "orthocal-generic",
        overrides: dict[str, dict[str, Any]] | None = None,
        timeout_s: float = 2.0,
        retries: int = 3,
        baudrate: int = 19200,
        bytesize: int = 8,
        parity: str = "N",
        stopbits: int = 1,
        on_event: Callable[[dict[str, Any]], None] | None = None,
        *,
        busy_backoff_s: float = 0.02,
        reconnect_s: float = 10.0,
    ) -> None:
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"transport must be 'tcp' or 'rtu', got {transport!r}")
        if transport == "tcp":
            try:
                port = int(port)
            except (TypeError, ValueError):
                raise ValueError(f"tcp port must be an integer, got {port!r}") from None
        if not timeout_s > 0 or retries < 0:
            raise ValueError("timeout_s must be > 0 and retries >= 0")
        self.transport = transport
        self.host = host
        self.port = port
        self.device_id = device_id
        self.map = load_map(profile, overrides)
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.serial: _SerialSettings = {"baudrate": baudrate, "bytesize": bytesize,
                                        "parity": parity, "stopbits": stopbits}
        self.on_event = on_event
        self.device = (f"controller {host}:{port}" if transport == "tcp"
                       else f"controller {port}")
        self.busy_backoff_s = float(busy_backoff_s)
        if not (math.isfinite(reconnect_s) and reconnect_s >= 0):
            raise ValueError("reconnect_s must be finite and >= 0")
        self.reconnect_s = float(reconnect_s)
        #: successful reconnects after a lost connection (the station re-checks the
        #: drive's reference when this changes)
        self.reconnects = 0
        #: requests answered only after the drive was unreachable or silent (a
        #: reconnect, or a retry after no reply): it may have restarted in between,
        #: forgetting what it was just sent (a move re-sends it, drivers.axes)
        self.interruptions = 0
        # set when a reconnect found HOMED clear; cleared by a completed homing
        # after a reconnect: None until STATUS says whether the reference survived
        self._lost_reference: bool | None = False
        self._lost_why = ""
        self._checking = False
        # the last positions read and the last target written, to recognise a jump
        self._last_positions: np.ndarray | None = None
        self._last_target: np.ndarray | None = None
        self._client: ModbusTcpClient | ModbusSerialClient | None = None
        self._lock = threading.RLock()

    # --- connection -----------------------------------------------------------------------

    def connect(self) -> Self:
        """Open the connection; raises ControllerConnectionError naming host:port."""
        with self._lock:
            if self._client is not None:
                return self
            client: ModbusTcpClient | ModbusSerialClient
            if self.transport == "tcp":
                client = ModbusTcpClient(self.host, port=int(self.port), timeout=self.timeout_s,
                                         retries=0)
                where = f"{self.host}:{self.port}"
            else:
                client = ModbusSerialClient(str(self.port), timeout=self.timeout_s, retries=0,
                                            **self.serial)
                where = f"serial port {self.port}"
            if not client.connect():
                client.close()
                raise ControllerConnectionError(self.device, f"cannot connect to {where}")
            self._client = client
            return self

    def close(self) -> None:
        with self._lock:
            if self._client is not None:
                self._client.close()
                self._client = None

    def __enter__(self) -> Self:
        return self.connect()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.device}, map={self.map.name!r})"

    # --- requests with bounded retries --------------------------------------------------------

    def _event(self, **event: Any) -> None:
        if self.on_event is not None:
            self.on_event(event)

    def _execute(self, op: str, call: Callable[[Any], ModbusPDU], *, fc: int,
                 count: int | None = None, refused: str | None = None) -> ModbusPDU:
        """Run one request with bounded retries and map every failure to a typed error."""
        with self._lock:
            if self._client is None:
                self.connect()
            self._check_reference(op)
            kind, error = "timeout", ""
            attempts = self.retries + 1
            silent = False
            for attempt in range(1, attempts + 1):
                rr, kind, error = self._attempt(op, call, fc=fc, count=count, refused=refused)
                if rr is not None:
                    if silent and not self._checking:
                        # An answer after silence: on a serial line a drive that lost
                        # power for less than the retries is only late. Its reference
                        # is checked before this answer counts.
                        self.interruptions += 1
                        self._lost_reference = None
                        self._check_reference(op)
                    return rr
                silent = silent or kind == "timeout"
                if attempt < attempts:
                    self._event(event="retry", device=self.device, op=op, error=error,
                                attempt=attempt)
                    if kind == "busy":
                        time.sleep(self.busy_backoff_s * attempt)
                    elif kind == "connection":
                        self._reconnect(op, error)
                        self._check_reference(op)

            detail = f"{op}: {error} after {attempts} attempt(s)"
            if kind != "busy" and not self._checking:
                self._lost_reference = None  # whatever answers next is checked first
            if kind == "busy":
                raise ControllerBusy(self.device, detail)
            if kind == "connection":
                raise ControllerConnectionError(self.device, detail)
            raise ControllerTimeout(self.device, detail)

    def _attempt(self, op: str, call: Callable[[Any], ModbusPDU], *, fc: int,
                 count: int | None, refused: str | None
                 ) -> tuple[ModbusPDU | None, str, str]:
        """Send the request once: (reply, "", "") when it is good, else (None, kind,
        error) with kind "timeout", "connection" or "busy", which decides how
        ``_execute`` retries. An exception code that no retry can change raises."""
        client = self._client
        assert client is not None
        try:
            rr = call(client)
        except ModbusIOException as exc:
            text = str(exc)
            return None, "timeout", (f"no reply within {self.timeout_s:g} s"
                                     if "No response" in text
                                     else f"invalid reply ({_short(exc)})")
        except (ConnectionException, OSError) as exc:
            # pymodbus maps most socket failures to ConnectionException but lets
            # a reset during a read through as ConnectionResetError.
            client.close()
            return None, "connection", f"connection lost ({_short(exc)})"
        if rr.isError():
            code = int(getattr(rr, "exception_code", 0))
            text = f"Modbus exception {code} ({EXCEPTION_NAMES.get(code, '?')})"
            if code == 6:
                return None, "busy", text
            if code == 3 and refused is not None:
                raise TargetRefused(self.device, f"{refused} refused: {text}", code)
            raise ExceptionResponse(self.device, f"{op}: {text}", code)
        if rr.function_code != fc or (count is not None and len(_payload(rr, fc)) < count):
            # A stale or foreign frame that decoded cleanly: never trust it.
            return None, "timeout", (f"unexpected reply (function {rr.function_code}"
                                     f" to a function {fc} request)")
        return rr, "", ""

    def _reconnect(self, op: str, error: str) -> None:
        """Open a new connection, trying again until ``reconnect_s`` has passed (a drive
        that lost power refuses connections until it has booted). Every failed attempt
        is reported; ControllerConnectionError once the budget is spent."""
        client = self._client
        assert client is not None
        started = time.monotonic()
        deadline = started + self.reconnect_s
        attempt = 0
        while True:
            attempt += 1
            try:
                up = client.connect()
            except OSError:
                up = False
            elapsed = time.monotonic() - started
            if up:
                self.reconnects += 1
                self.interruptions += 1
                self._event(event="reconnected", device=self.device, op=op,
                            attempts=attempt, elapsed_s=round(elapsed, 3))
                self._lost_reference = None  # unknown until STATUS is read again
                return
            client.close()
            self._event(event="reconnect", device=self.device, op=op, error=error,
                        attempt=attempt, elapsed_s=round(elapsed, 3))
            if time.monotonic() >= deadline:
                raise ControllerConnectionError(
                    self.device, f"{op}: {error}; not back within {self.reconnect_s:g} s "
                    f"({attempt} reconnect attempt(s))")
            time.sleep(min(0.1 * attempt, 1.0, max(0.0, deadline - time.monotonic())))

    def _check_reference(self, op: str) -> None:
        """After a reconnect, read STATUS (and the positions) before anything else: a
        drive that restarted has lost the reference its positions are counted from."""
        if self._checking or op in _REFERENCE_FREE_OPS:
            return
        if self._lost_reference is None:
            self._checking = True
            try:
                homed = self.read_status().homed
                jump = None
                # the target is set whenever the positions are (read_positions)
                if (homed and self._last_positions is not None
                        and self._last_target is not None):
                    now = self.read_positions()
                    lo = np.minimum(self._last_positions, self._last_target) - _JUMP_MM
                    hi = np.maximum(self._last_positions, self._last_target) + _JUMP_MM
                    if np.any(now < lo) or np.any(now > hi):
                        jump = now
            finally:
                self._checking = False
            if not homed:
                self._lost_reference = True
                self._lost_why = "HOMED clear after the connection came back (power cut?)"
            elif jump is not None:
                assert self._last_positions is not None
                self._lost_reference = True
                self._lost_why = (f"positions jumped from {format_mm(self._last_positions)} to "
                                  f"{format_mm(jump)} while the connection was lost")
            else:
                self._lost_reference = False
            self._event(event="reference-check", device=self.device,
                        lost=bool(self._lost_reference),
                        why=self._lost_why if self._lost_reference else None)
        if self._lost_reference:
            raise ControllerNotHomed(self.device, f"{op}: lost its reference "
                                     f"({self._lost_why}): the machine must be homed")

    # --- registers ----------------------------------------------------------------------------

    def read_counts(self, regs: Sequence[Register], op: str) -> dict[str, int]:
        """Raw integer values of ``regs`` with as few requests as the map allows."""
        out: dict[str, int] = {}
        for dev, table, start, count, members in contiguous_runs(regs, self.map.merge_gap):
            fc = _READ_FC[table]
            device_id = self.device_id if dev is None else dev

            def call(c: Any, fc: int = fc, start: int = start, count: int = count,
                     device_id: int = device_id) -> ModbusPDU:
                read = {1: c.read_coils, 2: c.read_discrete_inputs,
                        3: c.read_holding_registers, 4: c.read_input_registers}[fc]
                return read(start, count=count, device_id=device_id)

            rr = self._execute(op, call, fc=fc, count=count)
            data = _payload(rr, fc)
            for reg in members:
                i = reg.address - start
                if reg.is_bit:
                    out[reg.name] = int(bool(data[i]))
                else:
                    out[reg.name] = reg.decode_counts(data[i:i + reg.words])
        return out

    def read_mm(self, regs: Sequence[Register], op: str) -> np.ndarray:
        """``regs`` in mm (counts over each register's scale), in the order given."""
        counts = self.read_counts(regs, op)
        return np.array([counts[r.name] / r.scale for r in regs])

    def write_words(self, items: Sequence[tuple[Register, list[int]]], op: str,
                     refused: str | None = None) -> None:
        """Write raw words, one request per contiguous run (coils one by one)."""
        words_of = {reg.name: words for reg, words in items}
        for dev, table, start, _count, members in contiguous_runs(
                [reg for reg, _ in items], 0):
            device_id = self.device_id if dev is None else dev
            if table == "coil":
                for reg in members:
                    def write_coil(c: Any, a: int = reg.address,
                                   v: bool = bool(words_of[reg.name][0]),
                                   d: int = device_id) -> ModbusPDU:
                        return c.write_coil(a, v, device_id=d)

                    self._execute(op, write_coil, fc=5)
                continue
            if table != "holding":
                raise ControllerError(self.device, f"{op}: cannot write the {table} table")
            values = [w for reg in members for w in words_of[reg.name]]
            if len(values) == 1:
                def write_one(c: Any, a: int = start, v: int = values[0],
                              d: int = device_id) -> ModbusPDU:
                    return c.write_register(a, v, device_id=d)

                self._execute(op, write_one, fc=6, refused=refused)
            else:
                def write_many(c: Any, a: int = start, v: list[int] = values,
                               d: int = device_id) -> ModbusPDU:
                    return c.write_registers(a, v, device_id=d)

                self._execute(op, write_many, fc=16, refused=refused)

    def send_command(self, command: str) -> None:
        """Write the map's steps for ``command`` ("move", "stop", "home",
        "reset_alarm"): a drive may need more than one register written."""
        for step in self.map.commands[command]:
            reg = self.map[step.reg]
            words = [step.value] if reg.is_bit else encode_int(step.value, reg.type,
                                                               reg.word_order)
            self.write_words([(reg, words)], command)

    # --- what the reference check reads, and what it is told ------------------------------

    def read_positions(self) -> np.ndarray:
        """Actual joint positions ρ (mm, shape (3,)): one block read on orthocal-generic."""
        pos = self.read_mm(self.map.axis_registers("ACTUAL"), "read positions")
        if not self._checking:
            self._last_positions = pos.copy()
            if self._last_target is None:
                self._last_target = pos.copy()
        return pos

    def read_status(self) -> AxisStatus:
        """STATUS and ALARM_CODE (one read on orthocal-generic), decoded by the map."""
        names: list[str] = []
        for spec in self.map.status.values():
            names += [n for n in spec.registers if n not in names]
        names += [n for n in self.map.alarm_code if n not in names]
        counts = self.read_counts([self.map[n] for n in names], "read status")
        flags: dict[str, bool] = {}
        for flag, spec in self.map.status.items():
            bits = [bool(counts[n] >> spec.bit & 1) == spec.active_high for n in spec.registers]
            flags[flag] = all(bits) if spec.combine == "all" else any(bits)
        code = next((counts[n] for n in self.map.alarm_code if counts[n]), 0)
        if flags.get("alarm") and not code and self.map.alarm_code:
            # On a drive per axis the code and the status bit come in requests of
            # their own: the code read first may predate the alarm the bit shows.
            again = self.read_counts([self.map[n] for n in self.map.alarm_code],
                                     "read alarm code")
            code = next((again[n] for n in self.map.alarm_code if again[n]), 0)
        return AxisStatus(alarm_code=code, **flags)

    def read_raw(self, name: str) -> int:
        """The raw integer value of one register of the map (bring-up: which
        registers a controller answers); a read request only."""
        return self.read_counts([self.map[name]], f"read {name}")[name]

    def note_target(self, targets: np.ndarray) -> None:
        """The targets just written: after a reconnect, a position between the last
        one read and these is motion, not a count that restarted."""
        self._last_target = targets.copy()

    def forget_positions(self) -> None:
        """New offsets shift every counted position of carriages that have not moved:
        not a jump for the reference check after a reconnect."""
        self._last_positions = self._last_target = None

    def reference_restored(self) -> None:
        """A completed homing: the drive counts from a reference again."""
        with self._lock:
            self._lost_reference = False
            self._last_positions = self._last_target = None


def _payload(rr: ModbusPDU, fc: int) -> list[Any]:
    return list(rr.bits) if fc in (1, 2) else list(rr.registers)


def format_mm(v: np.ndarray) -> str:
    """Positions as the link's and the axes' messages write them: (x, y, z) in mm."""
    return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"


def _short(exc: Exception) -> str:
    text = str(exc).replace("Modbus Error: ", "").strip("[] ")
    return text if len(text) <= 120 else text[:117] + "..."
