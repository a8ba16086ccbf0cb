"""The simulated drive's registers: what a register map (by default
"orthocal-generic", docs/design.md) serves for a
:class:`~drivers.sim.machine.VirtualOrthoglide` and what a write to it does, as a
real drive of that layout would — so a new map can be rehearsed before the
machine is touched. Kept apart from the Modbus server and its fault injection
(:mod:`drivers.sim.controller`), which hands every request to
:meth:`DriveRegisters.serve`, and from where the registers live on the wire
(:mod:`drivers.sim.layout`: device ids, tables, exception 2 outside the map): a
drive's register semantics are the same whatever transport or fault the request
came through.

What each register does follows from its role in the map:

* TARGET_i stores axis i's target; TARGET_* power up at the axes' positions (not
  0); a target outside the soft limits (default [L+ρmin−10, L+ρmax+10] on every
  axis) is refused with exception 3;
* ACTUAL_i shows the machine's counted position, OFFSET_i its zero offsets
  (writing them acts on the legs through the machine; beyond ``max_offset_mm``:
  exception 3); SPEED (or SPEED_i) sets the machine's speed (0: exception 3) and
  reads back what was written (0 until then); SOFT_MIN/SOFT_MAX show the limits
  (``soft_limit_registers=False`` leaves them out: exception 2);
* every register named in the map's status shows the machine's flags at their
  bits, honouring ``active_high`` (other bits 0); alarm-code registers its alarm
  code (0 none);
* a command acts when a write completes its sequence: for each register of the
  sequence, a write of that register's last step while it holds its step before
  (an edge: move = CONTROL 0 then 16 triggers on 16 written over 0, not on 16
  again) — each register's completion triggers (IAI's home: HOME_X, _Y, _Z each
  0 then 1). A register only one-step commands write (the generic map's
  COMMAND 1/2/3/4) takes its codes at once, refuses any other nonzero value with
  exception 3 and reads 0 once taken. A move commands the stored targets and is
  refused with exception 3 if one is outside the soft limits (they may have
  changed since they were written); a map whose move is [] (IAI) starts it with
  every TARGET write;
* any other register is plain storage: it reads back what was written.

Moves take time and the status follows the machine.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.simulator import SimDevice
from pymodbus.simulator.simdevice import SimAction

from drivers.registers import COMMANDS, GENERIC, Register, RegisterMap
from drivers.sim.layout import TABLE_OF_FC, MapLayout, WordStore, request_spans
from drivers.sim.machine import VirtualOrthoglide

_READ_CODES = {3, 23}  # function codes whose reads consume a taken command code


def default_soft_limits(machine: VirtualOrthoglide, margin_mm: float = 10.0
                        ) -> tuple[np.ndarray, np.ndarray]:
    """[L + ρmin − margin, L + ρmax + margin] on each axis: room for every test
    posture of docs/design.md with a margin (paper's machine: [200.25, 380.25] mm)."""
    g = machine.geometry
    return (np.full(3, g.leg_length + g.rho_min - margin_mm),
            np.full(3, g.leg_length + g.rho_max + margin_mm))


def command_code(command: str) -> int:
    """How :meth:`DriveRegisters.commanded` names a command whatever the map: the
    generic map's code (move 1, stop 2, home 3, reset_alarm 4)."""
    return COMMANDS.index(command) + 1


class DriveRegisters:
    """The register behaviour of one simulated drive (module docstring) serving
    ``register_map``; its registers without a device id belong to ``device_id``.

    The server lays out its datastore with :meth:`sim_devices`, asks
    :meth:`refusal` about each request and runs :meth:`serve` (the datastore's
    hook) before each request is answered or written; :meth:`power_up` makes
    the next request initialise the registers again (a drive back from a power
    cut). What a server counts or injects on top is told through
    :meth:`refused_write`, :meth:`commanded` and :meth:`moved`, which do nothing
    here.
    """

    def __init__(
        self,
        machine: VirtualOrthoglide | None = None,
        register_map: RegisterMap = GENERIC,
        *,
        soft_limits: tuple[Sequence[float], Sequence[float]] | None = None,
        max_offset_mm: float = 50.0,
        soft_limit_registers: bool | tuple[Sequence[float], Sequence[float]] = True,
        device_id: int = 1,
    ) -> None:
        self.machine = machine or VirtualOrthoglide()
        self.max_offset_mm = float(max_offset_mm)
        lo, hi = soft_limits if soft_limits is not None else default_soft_limits(self.machine)
        self.soft_min = np.asarray(lo, dtype=float).reshape(3)
        self.soft_max = np.asarray(hi, dtype=float).reshape(3)
        if np.any(self.soft_min >= self.soft_max):
            raise ValueError("soft limits: every lower limit must be below the upper one")
        # What SOFT_MIN/SOFT_MAX show: the limits enforced (True); nothing, answering
        # exception 2 as a drive that keeps them in parameters (False); or a given
        # (lower, upper), such as the zeros of a drive never set up.
        self.soft_limit_registers = soft_limit_registers
        self.map = register_map
        self.device_id = device_id
        served = [r for r in register_map.registers
                  if not (r.name.startswith("SOFT_") and soft_limit_registers is False)]
        self.layout = MapLayout(served, device_id)
        self._store = WordStore(self.layout)
        self._inited = False
        self._at: tuple[int, str] = (device_id, "holding")  # the request being served
        m = register_map
        self._targets = m.axis_registers("TARGET")
        self._offsets = m.axis_registers("OFFSET") if m.has_role("OFFSET") else []
        self._speeds = m.speed_registers()
        self._limits = (m.axis_registers("SOFT_MIN") + m.axis_registers("SOFT_MAX")
                        if m.has_role("SOFT_MIN") and soft_limit_registers is not False else [])
        self._status_regs = [m[n] for n in dict.fromkeys(
            n for spec in m.status.values() for n in spec.registers)]
        self._status_names = {reg.name for reg in self._status_regs}
        self._moving_shown = False  # the MOVING flag the status registers hold
        self._alarm_regs = [m[n] for n in m.alarm_code]
        self._actuals = m.axis_registers("ACTUAL")
        # Each register's part of each command: (command, the values it is written).
        self._parts: dict[str, list[tuple[str, list[int]]]] = {}
        for command in COMMANDS:
            steps = m.commands[command]
            # Each drive (unit id) takes a command when the last of its steps on that
            # drive is written: its trigger or control word comes last (Oriental's
            # TRIGGER after OPTYPE, ACCEL, ...), not at each register set on the way.
            last = {m[step.reg].device_id: step.reg for step in steps}
            for name in dict.fromkeys(step.reg for step in steps):
                if name not in last.values():
                    continue
                values = [s.value for s in steps if s.reg == name]
                if m[name].is_bit:
                    values = [int(v != 0) for v in values]
                self._parts.setdefault(name, []).append((command, values))
        # Registers only one-step commands write: command codes, taken at once.
        self._codes = {name: {values[0]: command for command, values in parts}
                       for name, parts in self._parts.items()
                       if not m[name].is_bit and all(
                           len(m.commands[c]) == 1 for c, _ in parts)}
        # ... per unit id, as a read of that unit finds them
        self._code_regs = {dev: [m[n] for n in self._codes
                                 if self.layout.device_of(m[n]) == dev]
                           for dev in self.layout.devices}

    # --- hooks for the server ---------------------------------------------------------------

    def refused_write(self) -> None:
        """A write was refused (an exception code answered, nothing applied)."""

    def commanded(self, code: int) -> None:
        """A command was taken (before it acts), named by :func:`command_code`."""

    def moved(self, duration_s: float) -> None:
        """A command started a move lasting ``duration_s`` (0: none started)."""

    def power_up(self) -> None:
        """The next request finds the registers at their power-up values."""
        self._inited = False

    # --- datastore ----------------------------------------------------------------------------

    @property
    def devices(self) -> list[int]:
        """The Modbus unit ids this drive answers as."""
        return self.layout.devices

    def sim_devices(self) -> list[SimDevice]:
        """The datastore: one pymodbus SimDevice per unit id, every register of the
        map that is served in its own table, :meth:`serve` its hook."""
        return self.layout.sim_devices(self._action_for)

    def _action_for(self, device_id: int) -> SimAction:
        async def action(function_code: int, start: int, address: int, count: int,
                         registers: list[int], set_values: list[int] | list[bool] | None
                         ) -> ExcCodes | None:
            return await self.serve(device_id, function_code, start, address, count,
                                    registers, set_values)
        return action

    def refusal(self, device_id: int, pdu: object) -> ExcCodes | None:
        """Exception 2 for a request (a pymodbus PDU) that leaves the map."""
        return self.layout.refusal(device_id, request_spans(pdu))

    async def action(self, function_code: int, start: int, address: int, count: int,
                     registers: list[int], set_values: list[int] | list[bool] | None
                     ) -> ExcCodes | None:
        """:meth:`serve` for the server's own device id."""
        return await self.serve(self.device_id, function_code, start, address, count,
                                registers, set_values)

    async def serve(self, device_id: int, function_code: int, start: int, address: int,
                    count: int, registers: list[int],
                    set_values: list[int] | list[bool] | None) -> ExcCodes | None:
        """pymodbus SimDevice hook of unit ``device_id``: runs before the datastore
        answers or is written, and shows it the words the drive holds."""
        table = TABLE_OF_FC.get(function_code)
        if table is None or not self.layout.serves(device_id, table):
            return ExcCodes.ILLEGAL_ADDRESS  # a table the map has none of on this unit
        if not self._inited:
            self._init_registers()
            self._inited = True
        self._refresh()
        result = None
        if set_values is None:
            if function_code in _READ_CODES:
                for reg in self._code_regs.get(device_id, ()):  # taken: reads 0
                    self._store.put_counts(reg, 0)
            if not self._moving_shown and not self._status_names.isdisjoint(
                    self.layout.touched(device_id, table, address, count)):
                self.machine.rest_reported = True  # the station is told the axes rest
        else:
            self._at = (device_id, table)
            result = self._write(start, address, [int(v) for v in set_values], registers)
            if result is not None:
                self.refused_write()
        self._store.copy_into(device_id, table, start, registers)
        return result

    def _init_registers(self) -> None:
        """Power-up values: every register 0 but these. TARGET_* start where the axes
        stand, as on a drive: a client writing one target then a move moves that
        axis alone. They are not reset per connection: an integrator's tool (mbpoll)
        connects once per request, and a drive keeps its targets across connections."""
        self._store = WordStore(self.layout)
        for reg, rho in zip(self._targets, self.machine.targets(), strict=True):
            self._store.put(reg, rho)
        if not self._limits:
            return
        registers = self.soft_limit_registers  # not False here: self._limits is empty then
        shown = (self.soft_min, self.soft_max) if isinstance(registers, bool) else \
            tuple(np.asarray(v, dtype=float).reshape(3) for v in registers)
        for reg, value in zip(self._limits, np.concatenate(shown), strict=True):
            self._store.put(reg, value)

    def _refresh(self) -> None:
        """Mirror the machine into the registers that show it."""
        m = self.machine
        st = m.status()
        self._moving_shown = st.moving
        flags = {"homed": st.homed, "moving": st.moving, "in_position": st.in_position,
                 "alarm": st.alarm, "estop": st.estop}
        bits = {reg.name: 0 for reg in self._status_regs}
        for flag, spec in self.map.status.items():
            if flags[flag] == spec.active_high:
                for name in spec.registers:
                    bits[name] |= 1 << spec.bit
        for reg in self._status_regs:
            self._store.put_counts(reg, bits[reg.name] & 1 if reg.is_bit else bits[reg.name])
        for reg in self._alarm_regs:
            self._store.put_counts(reg, st.alarm_code)
        for reg, rho in zip(self._actuals, m.actual(), strict=True):
            self._store.put(reg, rho)
        if self._offsets:
            for reg, o in zip(self._offsets, m.offsets, strict=True):
                self._store.put(reg, o)

    def _write(self, start: int, address: int, values: list[int], registers: list[int]
               ) -> ExcCodes | None:
        """A write of ``values`` from ``address`` to the request's unit and table
        (``self._at``; ``start``/``registers``: the datastore's block): refused
        with exception 3 (nothing applied), or applied and its commands run."""
        device_id, table = self._at
        old = self._store
        new = old.written(device_id, table, address, values)
        touched = self.layout.touched(device_id, table, address, len(values))

        for reg, lo, hi in zip(self._targets, self.soft_min, self.soft_max, strict=True):
            if reg.name in touched and not lo - 1e-9 <= new.value(reg) <= hi + 1e-9:
                return ExcCodes.ILLEGAL_VALUE
        speeds = [reg for reg in self._speeds if reg.name in touched]
        if any(new.value(reg) <= 0 for reg in speeds):
            return ExcCodes.ILLEGAL_VALUE
        offsets_hit = any(reg.name in touched for reg in self._offsets)
        offsets = np.array([new.value(reg) for reg in self._offsets])
        if offsets_hit and np.any(np.abs(offsets) > self.max_offset_mm):
            return ExcCodes.ILLEGAL_VALUE
        commands = self._triggered(touched, old, new)
        if commands is None:
            return ExcCodes.ILLEGAL_VALUE
        if "move" in commands:
            # Stored targets are checked again when they are used: limits may have
            # changed since they were written, and a drive never moves outside them.
            targets = np.array([new.value(reg) for reg in self._targets])
            if np.any(targets < self.soft_min - 1e-9) or np.any(targets > self.soft_max + 1e-9):
                return ExcCodes.ILLEGAL_VALUE
        # Validated: apply in the order a drive would (parameters, then the commands).
        self._store = new
        for reg in speeds:
            self.machine.speed_mm_s = new.value(reg)
        if offsets_hit:
            self.machine.set_offsets(offsets)
        for command in commands:
            self.commanded(command_code(command))
            self._command(command, new)
        return None

    def _triggered(self, touched: dict[str, Register], old: WordStore, new: WordStore
                   ) -> list[str] | None:
        """The commands this write completes, in order; None: an unknown code."""
        commands: list[str] = []
        if not self.map.commands["move"] and any(reg.name in touched for reg in self._targets):
            commands.append("move")  # writing a target starts the move (IAI)
        for reg in touched.values():
            value = new.counts(reg)
            codes = self._codes.get(reg.name)
            if codes is not None and value and value not in codes:
                return None
            for command, steps in self._parts.get(reg.name, ()):
                if value == steps[-1] and (len(steps) == 1 or old.counts(reg) == steps[-2]):
                    commands.append(command)
        return commands

    def _command(self, name: str, new: WordStore) -> None:
        m = self.machine
        if name == "move":
            self.moved(m.move_to([new.value(reg) for reg in self._targets]))
        elif name == "stop":
            m.stop()
        elif name == "home":
            m.home()
        elif name == "reset_alarm":
            m.reset_alarm()


__all__ = ["DriveRegisters", "command_code", "default_soft_limits"]
