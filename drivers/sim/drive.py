"""The simulated drive's registers: what the register map "orthocal-generic"
(design.md) serves for a :class:`~drivers.sim.machine.VirtualOrthoglide` and
what a write to it does. Kept apart from the Modbus server and its fault
injection (:mod:`drivers.sim.controller`), which hands every request to
:meth:`DriveRegisters.action`: a drive's register semantics are the same
whatever transport or fault the request came through.

It behaves like a drive: COMMAND 1/2/3/4 is taken at once and reads back 0;
moves take time; STATUS follows the machine; TARGET_* power up at the axes'
positions (not 0); a target outside the soft limits (default [L+ρmin−10,
L+ρmax+10] on every axis) is refused with exception 3, and so is a COMMAND 1
whose stored targets are outside them (the limits may have changed since), an
unknown command, a zero speed or an offset beyond ``max_offset_mm``; an
address outside the map, or any table but the holding registers, answers
exception 2 (``soft_limit_registers=False`` leaves SOFT_MIN/SOFT_MAX out too);
writing OFFSET acts on the legs through the machine.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.simulator import DataType, SimData

from drivers.registers import AXES, GENERIC, Register, decode_int
from drivers.sim.machine import VirtualOrthoglide

_READ_CODES = {3, 23}  # function codes whose reads consume a taken COMMAND
_REGISTER_CODES = {3, 6, 16, 22, 23}  # holding-register functions: the map's only table


def default_soft_limits(machine: VirtualOrthoglide, margin_mm: float = 10.0
                        ) -> tuple[np.ndarray, np.ndarray]:
    """[L + ρmin − margin, L + ρmax + margin] on each axis: room for every test
    posture of design.md with a margin (paper's machine: [200.25, 380.25] mm)."""
    g = machine.geometry
    return (np.full(3, g.leg_length + g.rho_min - margin_mm),
            np.full(3, g.leg_length + g.rho_max + margin_mm))


class DriveRegisters:
    """The register behaviour of one simulated drive (module docstring).

    The server calls :meth:`simdata` to lay out its datastore and
    :meth:`action` before each request is answered or written;
    :meth:`power_up` makes the next request initialise the registers again (a
    drive back from a power cut). What a server counts or injects on top is
    told through :meth:`refused_write`, :meth:`commanded` and :meth:`moved`,
    which do nothing here.
    """

    def __init__(
        self,
        machine: VirtualOrthoglide | None = None,
        *,
        soft_limits: tuple[Sequence[float], Sequence[float]] | None = None,
        max_offset_mm: float = 50.0,
        soft_limit_registers: bool | tuple[Sequence[float], Sequence[float]] = True,
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
        self.map = GENERIC
        self._inited = False
        self._regs = {r.name: r for r in self.map.registers}

    # --- hooks for the server ---------------------------------------------------------------

    def refused_write(self) -> None:
        """A write was refused (an exception code answered, nothing applied)."""

    def commanded(self, code: int) -> None:
        """COMMAND ``code`` was taken (before it acts)."""

    def moved(self, duration_s: float) -> None:
        """A COMMAND 1 started a move lasting ``duration_s`` (0: none started)."""

    def power_up(self) -> None:
        """The next request finds the registers at their power-up values."""
        self._inited = False

    # --- datastore ----------------------------------------------------------------------------

    def simdata(self) -> list[SimData]:
        """The datastore's layout: every register of the map that is served."""
        data = []
        for reg in self.map.registers:
            if reg.name.startswith("SOFT_") and self.soft_limit_registers is False:
                continue  # not served: exception 2, like any address outside the map
            data.append(SimData(reg.address, count=reg.words, values=0,
                                datatype=DataType.REGISTERS, readonly=reg.access == "R"))
        return data

    def _init_registers(self, registers: list[int], start: int) -> None:
        """Power-up values. TARGET_* start where the axes stand, as on a drive: a
        client writing one target then COMMAND 1 moves that axis alone. They are
        not reset per connection: an integrator's tool (mbpoll) connects once per
        request, and a drive keeps its targets across connections."""
        for ax, rho in zip(AXES, self.machine.targets(), strict=True):
            self._put(registers, start, self._regs[f"TARGET_{ax}"], rho)
        if self.soft_limit_registers is False:
            return
        shown = (self.soft_min, self.soft_max) if self.soft_limit_registers is True else \
            tuple(np.asarray(v, dtype=float).reshape(3) for v in self.soft_limit_registers)
        for ax, lo, hi in zip(AXES, *shown, strict=True):
            self._put(registers, start, self._regs[f"SOFT_MIN_{ax}"], lo)
            self._put(registers, start, self._regs[f"SOFT_MAX_{ax}"], hi)

    @staticmethod
    def _put(registers: list[int], start: int, reg: Register, value: float) -> None:
        i = reg.address - start
        registers[i:i + reg.words] = reg.encode(value)

    @staticmethod
    def _get(registers: list[int], start: int, reg: Register) -> float:
        i = reg.address - start
        return reg.decode(registers[i:i + reg.words])

    def _refresh(self, registers: list[int], start: int) -> None:
        """Mirror the machine into the read-only registers."""
        m = self.machine
        st = m.status()
        bits = (st.homed << 0 | st.moving << 1 | st.in_position << 2 | st.alarm << 3
                | st.estop << 4)
        registers[self._regs["STATUS"].address - start] = bits
        registers[self._regs["ALARM_CODE"].address - start] = st.alarm_code & 0xFFFF
        for ax, rho in zip(AXES, m.actual(), strict=True):
            self._put(registers, start, self._regs[f"ACTUAL_{ax}"], rho)
        for ax, o in zip(AXES, m.offsets, strict=True):
            self._put(registers, start, self._regs[f"OFFSET_{ax}"], o)

    async def action(self, function_code: int, start: int, address: int, count: int,
                     registers: list[int], set_values: list[int] | list[bool] | None
                     ) -> ExcCodes | None:
        """pymodbus SimDevice hook: runs before the datastore answers or is written."""
        if function_code not in _REGISTER_CODES:
            # The map is holding registers only: input registers, coils and discrete
            # inputs are outside it, as on a drive that has none.
            return ExcCodes.ILLEGAL_ADDRESS
        if not self._inited:
            self._init_registers(registers, start)
            self._inited = True
        self._refresh(registers, start)
        if set_values is None:
            if function_code in _READ_CODES:
                registers[self._regs["COMMAND"].address - start] = 0  # taken: reads 0
            return None
        result = self._write(start, address, [int(v) for v in set_values], registers)
        if result is not None:
            self.refused_write()
        return result

    def _write(self, start: int, address: int, values: list[int], registers: list[int]
               ) -> ExcCodes | None:
        new = list(registers)
        new[address - start:address - start + len(values)] = values
        touched = set(range(address, address + len(values)))

        def hit(reg: Register) -> bool:
            return bool(touched & set(range(reg.address, reg.address + reg.words)))

        for ax, lo, hi in zip(AXES, self.soft_min, self.soft_max, strict=True):
            reg = self._regs[f"TARGET_{ax}"]
            if hit(reg):
                value = self._get(new, start, reg)
                if not lo - 1e-9 <= value <= hi + 1e-9:
                    return ExcCodes.ILLEGAL_VALUE
        speed_reg = self._regs["SPEED"]
        if hit(speed_reg) and self._get(new, start, speed_reg) <= 0:
            return ExcCodes.ILLEGAL_VALUE
        offset_regs = [self._regs[f"OFFSET_{ax}"] for ax in AXES]
        offsets_hit = any(hit(r) for r in offset_regs)
        offsets = np.array([self._get(new, start, r) for r in offset_regs])
        if offsets_hit and np.any(np.abs(offsets) > self.max_offset_mm):
            return ExcCodes.ILLEGAL_VALUE
        command_reg = self._regs["COMMAND"]
        command = decode_int(new[command_reg.address - start:command_reg.address - start + 1],
                             "u16") if hit(command_reg) else 0
        codes = {self.map.command_code(c): c for c in self.map.commands}
        if command and command not in codes:
            return ExcCodes.ILLEGAL_VALUE
        if command and codes[command] == "move":
            # Stored targets are checked again when they are used: limits may have
            # changed since they were written, and a drive never moves outside them.
            targets = np.array([self._get(new, start, self._regs[f"TARGET_{ax}"])
                                for ax in AXES])
            if np.any(targets < self.soft_min - 1e-9) or np.any(targets > self.soft_max + 1e-9):
                return ExcCodes.ILLEGAL_VALUE
        # Validated: apply in the order a drive would (parameters, then the command).
        if hit(speed_reg):
            self.machine.speed_mm_s = self._get(new, start, speed_reg)
        if offsets_hit:
            self.machine.set_offsets(offsets)
        if command:
            self.commanded(command)
            self._command(codes[command], new, start)
        return None

    def _command(self, name: str, new: list[int], start: int) -> None:
        m = self.machine
        if name == "move":
            targets = [self._get(new, start, self._regs[f"TARGET_{ax}"]) for ax in AXES]
            self.moved(m.move_to(targets))
        elif name == "stop":
            m.stop()
        elif name == "home":
            m.home()
        elif name == "reset_alarm":
            m.reset_alarm()
