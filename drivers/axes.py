"""The axis controller over Modbus TCP or RTU: :class:`ModbusAxisController`
implements :class:`drivers.base.AxisController` for any register map of
:mod:`drivers.registers` (docs/design.md, "Register map "orthocal-generic""): the
axes' behaviour (moves and their deadlines, waits, stop, homing, offsets, soft
limits) on the link of :mod:`drivers.modbus_link`, which owns the wire
discipline (retries, reconnects, the reference check after a power cut).

Every wait has a finite deadline; positions are compared within a tolerance,
never for equality. A move's deadline is the rest-to-rest trapezoid of
:mod:`drivers.profiles` (:func:`~drivers.profiles.move_time`) with a margin.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from drivers.base import HeldBy, Vec3
from drivers.device_errors import (
    AlarmError,
    ControllerError,
    EStopError,
    MoveTimeout,
    ReadbackMismatch,
    TargetRefused,
)
from drivers.modbus_link import ModbusLink, format_mm
from drivers.profiles import move_time
from drivers.registers import RegisterMap
from drivers.soft_limits import SoftLimits, read_soft_limits

_SLACK = 1e-9  # float noise when comparing mm values derived from integer counts


class ModbusAxisController(ModbusLink):
    """Three linear axes behind one Modbus controller (or one device per axis).

    ``port`` is the TCP port for ``transport="tcp"`` or the serial device for
    ``"rtu"``. ``profile``/``overrides`` select the register map
    (:func:`drivers.map_files.load_map`). ``acceleration_mm_s2`` is what the
    station assumes when it derives move deadlines; ``soft_limits`` supplies
    limits for maps that cannot read them. Use as a context manager, or call
    ``connect()`` / ``close()``.
    """

    # The offsets are the drive's own registers; a map without OFFSET registers reads
    # and writes none, and the station wraps it in drivers.held_offsets.HeldOffsets.
    held_by: HeldBy = "controller"

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
        super().__init__(transport, host, port, device_id, profile, overrides, timeout_s,
                         retries, baudrate, bytesize, parity, stopbits, on_event,
                         busy_backoff_s=busy_backoff_s, reconnect_s=reconnect_s)
        self.name = name or self.device
        self.acceleration_mm_s2 = float(acceleration_mm_s2)
        self.poll_interval_s = float(poll_interval_s)
        self.arrival_poll_s = float(arrival_poll_s)
        self.timeout_factor = float(timeout_factor)
        self.timeout_margin_s = float(timeout_margin_s)
        self._given_limits = None
        if soft_limits is not None:
            lo, hi = (_vec3(v, "soft_limits") for v in soft_limits)
            self._given_limits = (lo, hi)
        self._speed: float | None = None
        self._speed_written: tuple[float, int] | None = None  # (mm/s, at reconnect count)

    def _unsupported(self, what: str) -> ControllerError:
        reason = self.map.unsupported.get(what, f"profile {self.map.name!r} has no {what}")
        return ControllerError(self.device, reason)

    # --- AxisController ------------------------------------------------------------------

    def soft_limits(self) -> SoftLimits:
        """(lower, upper) joint limits in mm as the controller enforces them; where the
        controller cannot tell (exception 2, no such registers in the map, a range
        that is none), the limits given to the driver, else NaN with the reason
        (:mod:`drivers.soft_limits`): the station decides what to do without them."""
        def read() -> np.ndarray:
            regs = self.map.axis_registers("SOFT_MIN") + self.map.axis_registers("SOFT_MAX")
            return self.read_mm(regs, "read soft limits")

        return read_soft_limits(
            read, self.map.has_role("SOFT_MIN"), self._given_limits,
            self.map.unsupported.get("soft_limits",
                                     f"profile {self.map.name!r} has no soft-limit registers"))

    def move(self, targets: Vec3, speed_mm_s: float | None = None) -> None:
        """Write SPEED (if given), the three targets in one write, then the move command
        (all again if the drive was unreachable or silent meanwhile).
        Exception 3 on the targets → TargetRefused."""
        rho = _vec3(targets, "targets")
        if not self.map.has_role("SOFT_MIN") and self._given_limits is not None:
            lo, hi = self._given_limits
            if np.any(rho < lo - _SLACK) or np.any(rho > hi + _SLACK):
                raise TargetRefused(self.device, f"targets {format_mm(rho)} outside the soft "
                                    f"limits {format_mm(lo)}..{format_mm(hi)}", 3)
        items = [(reg, reg.encode(v)) for reg, v in
                 zip(self.map.axis_registers("TARGET"), rho, strict=True)]
        # A drive that lost power while this was being sent holds its power-up targets
        # (where the axes stand), and perhaps its power-up speed: after an interruption
        # (a reconnect, or an answer only after silence) everything is sent again, the
        # same targets, already checked. Past three sends the wait for the arrival is
        # the judge: a drive that forgot the move does not arrive, and the wait stops
        # the axes at its deadline.
        for _ in range(3):
            seen = self.interruptions
            if speed_mm_s is not None:
                self._write_speed(speed_mm_s)
            self.write_words(items, "write targets", refused=f"targets {format_mm(rho)}")
            self.note_target(rho)
            self.send_command("move")
            if self.interruptions == seen:
                return

    def as_commanded(self, targets: Vec3) -> np.ndarray:
        """The targets as the drive holds them: rounded to its TARGET registers'
        count (IAI: 0.01 mm), where its carriages go and the arrival is judged."""
        return np.array([reg.decode(reg.encode(float(v))) for reg, v in
                         zip(self.map.axis_registers("TARGET"), targets, strict=True)])

    def _write_speed(self, speed_mm_s: float) -> None:
        if not (math.isfinite(speed_mm_s) and speed_mm_s > 0):
            raise ValueError(f"speed must be > 0 mm/s, got {speed_mm_s}")
        regs = self.map.speed_registers()
        if not regs:
            raise ControllerError(self.device, f"profile {self.map.name!r} has no speed register")
        items = [(reg, reg.encode(speed_mm_s)) for reg in regs]
        if any(reg.decode(words) <= 0 for reg, words in items):
            raise ValueError(f"speed {speed_mm_s} mm/s rounds to 0 at the register resolution")
        speed = items[0][0].decode(items[0][1])
        # Written already since the connection last came up: a request per move saved
        # (a drive that lost power may have reset it, so an interruption writes it again).
        if self._speed_written == (speed, self.interruptions):
            return
        self.write_words(items, "write speed")
        self._speed = speed
        self._speed_written = (speed, self.interruptions)

    def _current_speed(self) -> float:
        if self._speed is None:
            regs = self.map.speed_registers()
            if regs:
                speeds = self.read_mm(regs, "read speed")
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

    def wait_in_position(self, targets: Vec3, timeout_s: float,
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
        rho = self.as_commanded(_vec3(targets, "targets"))
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
                where = "" if last_pos is None else f", at {format_mm(last_pos)}"
                raise MoveTimeout(self.device, f"not in position at {format_mm(rho)} within "
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

    def move_and_wait(self, targets: Vec3, speed_mm_s: float | None = None,
                      timeout_s: float | None = None,
                      start: Vec3 | None = None,
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
        self.send_command("stop")

    def home(self, timeout_s: float = 60.0) -> None:
        """Command homing and wait (finite ``timeout_s``) until HOMED and not MOVING."""
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"timeout_s must be finite and > 0, got {timeout_s}")
        self.send_command("home")
        deadline = time.monotonic() + timeout_s
        while True:
            st = self.read_status()
            if st.estop:
                raise EStopError(self.device, "emergency stop engaged")
            if st.alarm:
                raise AlarmError(self.device, f"alarm {st.alarm_code} while homing",
                                 st.alarm_code)
            if st.homed and not st.moving:
                self.reference_restored()
                return
            if time.monotonic() >= deadline:
                raise MoveTimeout(self.device, f"homing not done within {timeout_s:.1f} s")
            time.sleep(self.poll_interval_s)

    def reset_alarm(self) -> None:
        """Command an alarm reset; raises AlarmError if the alarm persists."""
        self.send_command("reset_alarm")
        st = self.read_status()
        if st.alarm:
            raise AlarmError(self.device, f"alarm {st.alarm_code} persists after reset",
                             st.alarm_code)

    def read_offsets(self) -> np.ndarray:
        """Joint zero offsets o (mm, shape (3,))."""
        if not self.map.has_role("OFFSET"):
            raise self._unsupported("offsets")
        return self.read_mm(self.map.axis_registers("OFFSET"), "read offsets")

    def offset_resolution_mm(self) -> float:
        """One count of the OFFSET registers (of TARGET without them: where the
        station holds the offsets, the target carries them), the coarsest axis's."""
        role = "OFFSET" if self.map.has_role("OFFSET") else "TARGET"
        return max(1.0 / reg.scale for reg in self.map.axis_registers(role))

    def target_resolution_mm(self) -> np.ndarray:
        """One count of each axis's TARGET register (IAI: 0.01 mm; J15)."""
        return np.array([1.0 / reg.scale for reg in self.map.axis_registers("TARGET")])

    def write_offsets(self, offsets: Vec3) -> np.ndarray:
        """Write o in one request, read it back, raise ReadbackMismatch unless every
        axis reads back the written count. Returns what was read back (mm)."""
        if not self.map.has_role("OFFSET"):
            raise self._unsupported("offsets")
        o = _vec3(offsets, "offsets")
        regs = self.map.axis_registers("OFFSET")
        items = [(reg, reg.encode(v)) for reg, v in zip(regs, o, strict=True)]
        self.write_words(items, "write offsets")
        self.forget_positions()
        back = self.read_counts(regs, "read back offsets")
        wanted = {reg.name: reg.counts(v) for reg, v in zip(regs, o, strict=True)}
        if any(back[n] != wanted[n] for n in wanted):
            got = np.array([back[r.name] / r.scale for r in regs])
            raise ReadbackMismatch(self.device, f"offsets written {format_mm(o)} mm but read back "
                                   f"{format_mm(got)} mm")
        return np.array([back[r.name] / r.scale for r in regs])



def _vec3(values: Vec3, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be three finite numbers (x, y, z), got {values!r}")
    return arr

