"""The axis controller over Modbus TCP or RTU: :class:`ModbusAxisController`
implements :class:`drivers.base.AxisController` for any register map of
:mod:`drivers.registers` (design.md, "Register map "orthocal-generic"").

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
* after a reconnect, or a request that failed for good (on a serial line a drive
  that lost power is only silent), the drive's STATUS is read before anything
  else: a drive
  that came back with HOMED clear (power cut) raises :class:`ControllerNotHomed`
  for every request but homing and status, so a position counted from a lost
  reference is never returned;
* every wait has a finite deadline; positions are compared within a tolerance,
  never for equality.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusIOException
from pymodbus.pdu import ModbusPDU

from drivers.base import AxisStatus
from drivers.errors import (
    AlarmError,
    ControllerBusy,
    ControllerConnectionError,
    ControllerError,
    ControllerNotHomed,
    ControllerTimeout,
    EStopError,
    ExceptionResponse,
    MoveTimeout,
    ReadbackMismatch,
    TargetRefused,
)
from drivers.limits import SoftLimits, read_soft_limits
from drivers.registers import Register, RegisterMap, contiguous_runs, load_map

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
_SLACK = 1e-9  # float noise when comparing mm values derived from integer counts
# Requests that make sense on a drive that lost its reference: homing needs them.
_REFERENCE_FREE_OPS = frozenset({"read status", "home", "stop", "reset_alarm",
                                 "read offsets", "write offsets", "read back offsets"})
# A position further than this outside the last known span (last position to the
# last target) after a reconnect is a count that restarted, not motion.
_JUMP_MM = 0.05


def move_time(distance_mm: float, speed_mm_s: float, accel_mm_s2: float) -> float:
    """Duration of a rest-to-rest trapezoidal move (a triangle when too short)."""
    if distance_mm <= 0:
        return 0.0
    if speed_mm_s <= 0 or accel_mm_s2 <= 0:
        raise ValueError("speed and acceleration must be > 0")
    d_acc = speed_mm_s**2 / accel_mm_s2  # accelerate + decelerate distance
    if distance_mm <= d_acc:
        return 2.0 * math.sqrt(distance_mm / accel_mm_s2)
    return distance_mm / speed_mm_s + speed_mm_s / accel_mm_s2


class ModbusAxisController:
    """Three linear axes behind one Modbus controller (or one device per axis).

    ``port`` is the TCP port for ``transport="tcp"`` or the serial device for
    ``"rtu"``. ``profile``/``overrides`` select the register map
    (:func:`drivers.registers.load_map`). ``acceleration_mm_s2`` is what the
    station assumes when it derives move deadlines; ``soft_limits`` supplies
    limits for maps that cannot read them. Use as a context manager, or call
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
        name: str | None = None,
        *,
        acceleration_mm_s2: float = 500.0,
        poll_interval_s: float = 0.005,
        arrival_poll_s: float = 0.0005,
        soft_limits: tuple[Sequence[float], Sequence[float]] | None = None,
        timeout_factor: float = 1.5,
        timeout_margin_s: float = 1.0,
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
        self.serial = {"baudrate": baudrate, "bytesize": bytesize, "parity": parity,
                       "stopbits": stopbits}
        self.on_event = on_event
        self.device = (f"controller {host}:{port}" if transport == "tcp"
                       else f"controller {port}")
        self.name = name or self.device
        self.acceleration_mm_s2 = float(acceleration_mm_s2)
        self.poll_interval_s = float(poll_interval_s)
        self.arrival_poll_s = float(arrival_poll_s)
        self.timeout_factor = float(timeout_factor)
        self.timeout_margin_s = float(timeout_margin_s)
        self.busy_backoff_s = float(busy_backoff_s)
        if not (math.isfinite(reconnect_s) and reconnect_s >= 0):
            raise ValueError("reconnect_s must be finite and >= 0")
        self.reconnect_s = float(reconnect_s)
        #: successful reconnects after a lost connection (the station re-checks the
        #: drive's reference when this changes)
        self.reconnects = 0
        # set when a reconnect found HOMED clear; cleared by a completed homing
        # after a reconnect: None until STATUS says whether the reference survived
        self._lost_reference: bool | None = False
        self._lost_why = ""
        self._checking = False
        # the last positions read and the last target written, to recognise a jump
        self._last_positions: np.ndarray | None = None
        self._last_target: np.ndarray | None = None
        self._given_limits = None
        if soft_limits is not None:
            lo, hi = (_vec3(v, "soft_limits") for v in soft_limits)
            self._given_limits = (lo, hi)
        self._speed: float | None = None
        self._client: ModbusTcpClient | ModbusSerialClient | None = None
        self._lock = threading.RLock()

    # --- connection -----------------------------------------------------------------------

    def connect(self) -> ModbusAxisController:
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
                                            **self.serial)  # type: ignore[arg-type]
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

    def __enter__(self) -> ModbusAxisController:
        return self.connect()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"ModbusAxisController({self.device}, map={self.map.name!r})"

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
            for attempt in range(1, attempts + 1):
                client = self._client
                assert client is not None
                try:
                    rr = call(client)
                except ModbusIOException as exc:
                    text = str(exc)
                    kind, error = "timeout", (
                        f"no reply within {self.timeout_s:g} s" if "No response" in text
                        else f"invalid reply ({_short(exc)})")
                except (ConnectionException, OSError) as exc:
                    # pymodbus maps most socket failures to ConnectionException but lets
                    # a reset during a read through as ConnectionResetError.
                    client.close()
                    kind, error = "connection", f"connection lost ({_short(exc)})"
                else:
                    if rr.isError():
                        code = int(getattr(rr, "exception_code", 0))
                        text = f"Modbus exception {code} ({EXCEPTION_NAMES.get(code, '?')})"
                        if code == 6:
                            kind, error = "busy", text
                        elif code == 3 and refused is not None:
                            raise TargetRefused(self.device, f"{refused} refused: {text}", code)
                        else:
                            raise ExceptionResponse(self.device, f"{op}: {text}", code)
                    elif rr.function_code != fc or (
                            count is not None and len(_payload(rr, fc)) < count):
                        # A stale or foreign frame that decoded cleanly: never trust it.
                        kind, error = "timeout", (f"unexpected reply (function {rr.function_code}"
                                                  f" to a function {fc} request)")
                    else:
                        return rr
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
                if homed and self._last_positions is not None:
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
                self._lost_why = (f"positions jumped from {_fmt(self._last_positions)} to "
                                  f"{_fmt(jump)} while the connection was lost")
            else:
                self._lost_reference = False
            self._event(event="reference-check", device=self.device,
                        lost=bool(self._lost_reference),
                        why=self._lost_why if self._lost_reference else None)
        if self._lost_reference:
            raise ControllerNotHomed(self.device, f"{op}: lost its reference "
                                     f"({self._lost_why}): the machine must be homed")

    def _dev(self, reg: Register) -> int:
        return self.device_id if reg.device_id is None else reg.device_id

    def _read_counts(self, regs: Sequence[Register], op: str) -> dict[str, int]:
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

    def _read_mm(self, regs: Sequence[Register], op: str) -> np.ndarray:
        counts = self._read_counts(regs, op)
        return np.array([counts[r.name] / r.scale for r in regs])

    def _write_words(self, items: Sequence[tuple[Register, list[int]]], op: str,
                     refused: str | None = None) -> None:
        """Write raw words, one request per contiguous run (coils one by one)."""
        words_of = {reg.name: words for reg, words in items}
        for dev, table, start, _count, members in contiguous_runs(
                [reg for reg, _ in items], 0):
            device_id = self.device_id if dev is None else dev
            if table == "coil":
                for reg in members:
                    on = bool(words_of[reg.name][0])
                    self._execute(op, lambda c, a=reg.address, v=on, d=device_id:
                                  c.write_coil(a, v, device_id=d), fc=5)
                continue
            if table != "holding":
                raise ControllerError(self.device, f"{op}: cannot write the {table} table")
            values = [w for reg in members for w in words_of[reg.name]]
            if len(values) == 1:
                self._execute(op, lambda c, a=start, v=values[0], d=device_id:
                              c.write_register(a, v, device_id=d), fc=6, refused=refused)
            else:
                self._execute(op, lambda c, a=start, v=values, d=device_id:
                              c.write_registers(a, v, device_id=d), fc=16, refused=refused)

    def _command(self, command: str) -> None:
        for step in self.map.commands[command]:
            reg = self.map[step.reg]
            self._write_words([(reg, [step.value])], command)

    def _unsupported(self, what: str) -> ControllerError:
        reason = self.map.unsupported.get(what, f"profile {self.map.name!r} has no {what}")
        return ControllerError(self.device, reason)

    # --- AxisController ------------------------------------------------------------------

    def read_positions(self) -> np.ndarray:
        """Actual joint positions ρ (mm, shape (3,)): one block read on orthocal-generic."""
        pos = self._read_mm(self.map.axis_registers("ACTUAL"), "read positions")
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
        counts = self._read_counts([self.map[n] for n in names], "read status")
        flags: dict[str, bool] = {}
        for flag, spec in self.map.status.items():
            bits = [bool(counts[n] >> spec.bit & 1) == spec.active_high for n in spec.registers]
            flags[flag] = all(bits) if spec.combine == "all" else any(bits)
        code = next((counts[n] for n in self.map.alarm_code if counts[n]), 0)
        return AxisStatus(alarm_code=code, **flags)

    def soft_limits(self) -> SoftLimits:
        """(lower, upper) joint limits in mm as the controller enforces them; where the
        controller cannot tell (exception 2, no such registers in the map, a range
        that is none), the limits given to the driver, else NaN with the reason
        (:mod:`drivers.limits`): the station decides what to do without them."""
        def read() -> np.ndarray:
            regs = self.map.axis_registers("SOFT_MIN") + self.map.axis_registers("SOFT_MAX")
            return self._read_mm(regs, "read soft limits")

        return read_soft_limits(
            read, self.map.has_role("SOFT_MIN"), self._given_limits,
            self.map.unsupported.get("soft_limits",
                                     f"profile {self.map.name!r} has no soft-limit registers"))

    def read_raw(self, name: str) -> int:
        """The raw integer value of one register of the map (bring-up: which
        registers a controller answers); a read request only."""
        return self._read_counts([self.map[name]], f"read {name}")[name]

    def move(self, targets: Sequence[float], speed_mm_s: float | None = None) -> None:
        """Write SPEED (if given), the three targets in one write, then the move command.
        Exception 3 on the targets → TargetRefused."""
        rho = _vec3(targets, "targets")
        if not self.map.has_role("SOFT_MIN") and self._given_limits is not None:
            lo, hi = self._given_limits
            if np.any(rho < lo - _SLACK) or np.any(rho > hi + _SLACK):
                raise TargetRefused(self.device, f"targets {_fmt(rho)} outside the soft limits "
                                    f"{_fmt(lo)}..{_fmt(hi)}", 3)
        if speed_mm_s is not None:
            self._write_speed(speed_mm_s)
        items = [(reg, reg.encode(v)) for reg, v in
                 zip(self.map.axis_registers("TARGET"), rho, strict=True)]
        self._write_words(items, "write targets", refused=f"targets {_fmt(rho)}")
        self._last_target = rho.copy()
        self._command("move")

    def _write_speed(self, speed_mm_s: float) -> None:
        if not (math.isfinite(speed_mm_s) and speed_mm_s > 0):
            raise ValueError(f"speed must be > 0 mm/s, got {speed_mm_s}")
        regs = self.map.speed_registers()
        if not regs:
            raise ControllerError(self.device, f"profile {self.map.name!r} has no speed register")
        items = [(reg, reg.encode(speed_mm_s)) for reg in regs]
        if any(reg.decode(words) <= 0 for reg, words in items):
            raise ValueError(f"speed {speed_mm_s} mm/s rounds to 0 at the register resolution")
        self._write_words(items, "write speed")
        self._speed = items[0][0].decode(items[0][1])

    def _current_speed(self) -> float:
        if self._speed is None:
            regs = self.map.speed_registers()
            if regs:
                speeds = self._read_mm(regs, "read speed")
                if np.all(speeds > 0):
                    self._speed = float(np.min(speeds))
        if self._speed is None:
            raise ControllerError(self.device, "speed unknown: give speed_mm_s or timeout_s")
        return self._speed

    def move_timeout(self, distance_mm: float | Sequence[float], speed_mm_s: float) -> float:
        """Deadline of a move: trapezoid time × timeout_factor + timeout_margin_s.

        ``distance_mm``: one axis's travel, or every axis's: then the axes are
        allowed to move one after another (COMMAND 1 promises no more), so the
        trapezoid times add up."""
        distances = np.atleast_1d(np.abs(np.asarray(distance_mm, dtype=float)))
        t = sum(move_time(float(d), speed_mm_s, self.acceleration_mm_s2) for d in distances)
        return t * self.timeout_factor + self.timeout_margin_s

    def wait_in_position(self, targets: Sequence[float], timeout_s: float,
                         tolerance_mm: float = 0.002, expected_s: float | None = None,
                         watch: Callable[[], None] | None = None) -> np.ndarray:
        """Poll until IN_POSITION (and not MOVING) and every axis within tolerance.

        Raises EStopError / AlarmError as soon as the drive reports them, and
        MoveTimeout at the deadline. Returns the actual positions. ``expected_s``:
        when the move should end; from one poll interval before it, polls come
        every ``arrival_poll_s`` instead. ``watch``: called between polls while the
        axes move (it may take a while: the poll waits that much less); whatever
        it raises ends the wait (the caller stops the axes).
        """
        rho = _vec3(targets, "targets")
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"timeout_s must be finite and > 0, got {timeout_s}")
        started = time.monotonic()
        deadline = started + timeout_s
        # Until the move is nearly done, a slow poll still catches an alarm or an
        # e-stop promptly; around the arrival, each poll interval is time every
        # stop waits for nothing (half of it on average, 2.5 ms at 5 ms).
        arriving = math.inf if expected_s is None else \
            started + max(0.0, expected_s - self.poll_interval_s)
        last_pos: np.ndarray | None = None
        while True:
            st = self.read_status()
            if st.estop:
                raise EStopError(self.device, "emergency stop engaged")
            if st.alarm:
                raise AlarmError(self.device, f"alarm {st.alarm_code}", st.alarm_code)
            if st.in_position and not st.moving:
                last_pos = self.read_positions()
                if np.all(np.abs(last_pos - rho) <= tolerance_mm + _SLACK):
                    return last_pos
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                where = "" if last_pos is None else f", at {_fmt(last_pos)}"
                raise MoveTimeout(self.device, f"not in position at {_fmt(rho)} within "
                                  f"{timeout_s:.2f} s (moving={st.moving}, "
                                  f"in_position={st.in_position}{where})")
            now = time.monotonic()
            interval = self.arrival_poll_s if now >= arriving else \
                min(self.poll_interval_s, arriving - now)
            if watch is not None:
                watch()
                interval -= time.monotonic() - now
                remaining = deadline - time.monotonic()
            if interval > 0 and remaining > 0:
                time.sleep(min(interval, remaining))

    def move_and_wait(self, targets: Sequence[float], speed_mm_s: float | None = None,
                      timeout_s: float | None = None,
                      start: Sequence[float] | None = None,
                      watch: Callable[[], None] | None = None) -> np.ndarray:
        """move() then wait_in_position(); the deadline comes from the distances, the
        speed and the acceleration with a margin (the axes one after another, see
        move_timeout) unless ``timeout_s`` is given.
        ``start``: the positions the caller has just read (saves reading them again);
        ``watch``: see wait_in_position."""
        rho = _vec3(targets, "targets")
        expected = None
        if timeout_s is None or start is not None:
            here = self.read_positions() if start is None else _vec3(start, "start")
            distance = float(np.max(np.abs(rho - here)))
            speed = speed_mm_s if speed_mm_s is not None else self._current_speed()
            # When the axes would arrive moving together: from then on the wait polls
            # fast. The deadline allows them one after another.
            expected = move_time(distance, speed, self.acceleration_mm_s2)
            if timeout_s is None:
                timeout_s = self.move_timeout(np.abs(rho - here), speed)
        self.move(rho, speed_mm_s)
        return self.wait_in_position(rho, timeout_s, expected_s=expected, watch=watch)

    def stop(self) -> None:
        """Command a decelerating stop; returns once the command is taken."""
        self._command("stop")

    def home(self, timeout_s: float = 60.0) -> None:
        """Command homing and wait (finite ``timeout_s``) until HOMED and not MOVING."""
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"timeout_s must be finite and > 0, got {timeout_s}")
        self._command("home")
        deadline = time.monotonic() + timeout_s
        while True:
            st = self.read_status()
            if st.estop:
                raise EStopError(self.device, "emergency stop engaged")
            if st.alarm:
                raise AlarmError(self.device, f"alarm {st.alarm_code} while homing",
                                 st.alarm_code)
            if st.homed and not st.moving:
                with self._lock:
                    self._lost_reference = False
                    self._last_positions = self._last_target = None
                return
            if time.monotonic() >= deadline:
                raise MoveTimeout(self.device, f"homing not done within {timeout_s:.1f} s")
            time.sleep(self.poll_interval_s)

    def reset_alarm(self) -> None:
        """Command an alarm reset; raises AlarmError if the alarm persists."""
        self._command("reset_alarm")
        st = self.read_status()
        if st.alarm:
            raise AlarmError(self.device, f"alarm {st.alarm_code} persists after reset",
                             st.alarm_code)

    def read_offsets(self) -> np.ndarray:
        """Joint zero offsets o (mm, shape (3,))."""
        if not self.map.has_role("OFFSET"):
            raise self._unsupported("offsets")
        return self._read_mm(self.map.axis_registers("OFFSET"), "read offsets")

    def write_offsets(self, offsets: Sequence[float]) -> np.ndarray:
        """Write o in one request, read it back, raise ReadbackMismatch unless every
        axis reads back the written count. Returns what was read back (mm)."""
        if not self.map.has_role("OFFSET"):
            raise self._unsupported("offsets")
        o = _vec3(offsets, "offsets")
        regs = self.map.axis_registers("OFFSET")
        items = [(reg, reg.encode(v)) for reg, v in zip(regs, o, strict=True)]
        self._write_words(items, "write offsets")
        # New offsets shift every counted position of carriages that have not moved:
        # not a jump for the reference check after a reconnect.
        self._last_positions = self._last_target = None
        back = self._read_counts(regs, "read back offsets")
        wanted = {reg.name: reg.counts(v) for reg, v in zip(regs, o, strict=True)}
        if any(back[n] != wanted[n] for n in wanted):
            got = np.array([back[r.name] / r.scale for r in regs])
            raise ReadbackMismatch(self.device, f"offsets written {_fmt(o)} mm but read back "
                                   f"{_fmt(got)} mm")
        return np.array([back[r.name] / r.scale for r in regs])


def _payload(rr: ModbusPDU, fc: int) -> list[Any]:
    return list(rr.bits) if fc in (1, 2) else list(rr.registers)


def _vec3(values: Sequence[float] | np.ndarray, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be three finite numbers (x, y, z), got {values!r}")
    return arr


def _fmt(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"


def _short(exc: Exception) -> str:
    text = str(exc).replace("Modbus Error: ", "").strip("[] ")
    return text if len(text) <= 120 else text[:117] + "..."
