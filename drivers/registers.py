"""Register maps of axis controllers, as data (docs/design.md, "Register map
"orthocal-generic"").

A :class:`RegisterMap` says where every quantity the station needs lives on
the wire: register entries (address, type, word order, scale to engineering
units, access, table, device), the status bits, and the command sequences.
:class:`drivers.axes.ModbusAxisController` contains no addresses of its own;
it reads them from the map, so a new drive family is a new map, not new code.

Conventions every map follows:

* per-axis quantities are named ``<ROLE>_X``, ``<ROLE>_Y``, ``<ROLE>_Z`` with the
  roles ``TARGET``, ``ACTUAL`` (required), ``OFFSET``, ``SOFT_MIN``, ``SOFT_MAX``
  (all three axes or none) and ``SPEED`` (one shared ``SPEED`` or one per axis);
* ``scale`` is raw counts per engineering unit (positions: 1000 per mm when
  the drive counts µm);
* a map without a role lists the reason in ``unsupported`` (e.g. a drive with no
  Modbus-writable zero offset), and the driver raises that reason verbatim.

The map the simulator serves by default is :data:`GENERIC` ("orthocal-generic",
docs/design.md's table), defined here; every other built-in map is a file of
drivers/maps/, and a user's drive is a file of its own: drivers.map_files reads
and writes them, resolves a profile's name or path, and applies the single-entry
overrides of the config table ``[controller.registers]`` (``load_map``).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, model_validator

AXES: tuple[str, str, str] = ("X", "Y", "Z")
ROLES_REQUIRED = ("TARGET", "ACTUAL")
ROLES_OPTIONAL = ("OFFSET", "SOFT_MIN", "SOFT_MAX")
STATUS_FLAGS = ("homed", "moving", "in_position", "alarm", "estop")
COMMANDS = ("move", "stop", "home", "reset_alarm")

RegType = Literal["u16", "i16", "u32", "i32"]
WordOrder = Literal["high_first", "low_first"]
Access = Literal["R", "RW", "W"]
Table = Literal["holding", "input", "coil", "discrete"]

_RANGES: dict[str, tuple[int, int]] = {
    "u16": (0, 0xFFFF),
    "i16": (-0x8000, 0x7FFF),
    "u32": (0, 0xFFFF_FFFF),
    "i32": (-0x8000_0000, 0x7FFF_FFFF),
}


class RegisterMapError(ValueError):
    """A register map or an override is invalid; ``entry`` names the culprit."""

    def __init__(self, entry: str, message: str) -> None:
        self.entry = entry
        super().__init__(f"{entry}: {message}")


# --- integer and unit conversion --------------------------------------------------------


def to_counts(value: float, scale: float) -> int:
    """Engineering value → raw counts, rounded half away from zero.

    Rounding, never truncation: int(0.0029 * 1000) would give 2 µm for 2.9 µm.
    The product is first rounded to 9 decimals so that binary noise such as
    1.0005 * 1000 = 1000.4999999999999 still rounds as the decimal value does.
    """
    if not math.isfinite(value):
        raise ValueError(f"cannot encode non-finite value {value!r}")
    x = round(value * scale, 9)
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


def from_counts(raw: int, scale: float) -> float:
    """Raw counts → engineering value."""
    return raw / scale


def um_to_mm(um: int) -> float:
    return um / 1000.0


def encode_int(value: int, reg_type: RegType = "i32", word_order: WordOrder = "high_first"
               ) -> list[int]:
    """Integer → 16-bit words (two's complement for signed types)."""
    lo, hi = _RANGES[reg_type]
    if not lo <= value <= hi:
        raise ValueError(f"{value} does not fit in {reg_type} [{lo}, {hi}]")
    if reg_type in ("u16", "i16"):
        return [value & 0xFFFF]
    u = value & 0xFFFF_FFFF
    words = [(u >> 16) & 0xFFFF, u & 0xFFFF]
    return words if word_order == "high_first" else words[::-1]


def decode_int(words: Sequence[int], reg_type: RegType = "i32",
               word_order: WordOrder = "high_first") -> int:
    """16-bit words → integer (two's complement for signed types)."""
    n = 1 if reg_type in ("u16", "i16") else 2
    if len(words) != n:
        raise ValueError(f"{reg_type} needs {n} word(s), got {len(words)}")
    if any(not 0 <= w <= 0xFFFF for w in words):
        raise ValueError(f"words must be 0..65535, got {list(words)}")
    if n == 1:
        u = words[0]
    else:
        hi, lo = (words[0], words[1]) if word_order == "high_first" else (words[1], words[0])
        u = (hi << 16) | lo
    bits = 16 * n
    if reg_type.startswith("i") and u >= 1 << (bits - 1):
        u -= 1 << bits
    return u


def encode_i32(value: int, word_order: WordOrder = "high_first") -> list[int]:
    return encode_int(value, "i32", word_order)


def decode_i32(words: Sequence[int], word_order: WordOrder = "high_first") -> int:
    return decode_int(words, "i32", word_order)


# --- the map as data -------------------------------------------------------------------


class Register(BaseModel):
    """One register (or coil) entry. ``address`` is the 0-based protocol address."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field(pattern=r"^[A-Z][A-Z0-9_]*$")
    address: int = Field(ge=0, le=0xFFFF)
    type: RegType = "u16"
    word_order: WordOrder = "high_first"
    scale: float = Field(default=1.0, gt=0)
    unit: str = ""
    access: Access = "R"
    table: Table = "holding"
    device_id: int | None = Field(default=None, ge=0, le=247)
    description: str = ""

    @model_validator(mode="after")
    def _consistent(self) -> Register:
        if self.address + self.words - 1 > 0xFFFF:
            raise ValueError(f"{self.type} at {self.address} runs past address 65535")
        if self.table in ("coil", "discrete") and (self.type != "u16" or self.scale != 1.0):
            raise ValueError("coils and discrete inputs are single bits: type u16, scale 1")
        if self.table in ("input", "discrete") and self.access != "R":
            raise ValueError(f"{self.table} table is read-only, access must be R")
        return self

    @property
    def words(self) -> int:
        """Number of 16-bit registers (coils: 1 bit)."""
        return 2 if self.type in ("u32", "i32") else 1

    @property
    def is_bit(self) -> bool:
        return self.table in ("coil", "discrete")

    def encode(self, value: float) -> list[int]:
        """Engineering value → words, rounded to the register resolution."""
        try:
            return encode_int(to_counts(value, self.scale), self.type, self.word_order)
        except ValueError as exc:
            raise ValueError(f"{self.name}: {exc}") from None

    def counts(self, value: float) -> int:
        return to_counts(value, self.scale)

    def decode(self, words: Sequence[int]) -> float:
        return from_counts(self.decode_counts(words), self.scale)

    def decode_counts(self, words: Sequence[int]) -> int:
        return decode_int(words, self.type, self.word_order)


class StatusBit(BaseModel):
    """Where one AxisStatus flag comes from: bit ``bit`` of each named register,
    combined over the registers (one per axis on a per-axis drive) with
    ``all`` or ``any``; ``active_high`` false for drives reporting e.g. "EMG off"."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    registers: list[str] = Field(min_length=1)
    bit: int = Field(ge=0, le=15)
    combine: Literal["all", "any"] = "any"
    active_high: bool = True


class CommandStep(BaseModel):
    """Write ``value`` (counts, encoded by the register's type and word order) to
    register ``reg`` (coils: 0 = OFF, 1 = ON/FF00). The map checks that it fits."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    reg: str
    value: int


class RegisterMap(BaseModel):
    """A complete register map of a three-axis controller."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    description: str = ""
    registers: list[Register]
    status: dict[str, StatusBit]
    alarm_code: list[str] = Field(default_factory=list)
    commands: dict[str, list[CommandStep]]
    unsupported: dict[str, str] = Field(default_factory=dict)
    #: the controller's sign convention for OFFSET (docs/design.md "Writing the offsets back")
    offset_convention: str = ""
    #: read registers up to this many addresses apart in one request
    merge_gap: int = Field(default=0, ge=0, le=16)
    #: what a move promises: "coordinated" (the axes interpolated on the straight line
    #: in joint space) or "independent" (each axis monotone to its target at any pace,
    #: in any order); the safe default promises no interpolation
    motion: Literal["coordinated", "independent"] = "independent"

    _by_name: dict[str, Register] = PrivateAttr(default_factory=dict)

    @model_validator(mode="after")
    def _check(self) -> RegisterMap:
        by_name: dict[str, Register] = {}
        for reg in self.registers:
            if reg.name in by_name:
                raise ValueError(f"register {reg.name} defined twice")
            by_name[reg.name] = reg
        self._by_name = by_name
        self._check_roles()
        missing = set(STATUS_FLAGS) - set(self.status)
        if missing or set(self.status) - set(STATUS_FLAGS):
            raise ValueError(f"status must define exactly {STATUS_FLAGS}")
        if set(self.commands) != set(COMMANDS):
            raise ValueError(f"commands must define exactly {COMMANDS}")
        refs = [n for s in self.status.values() for n in s.registers]
        refs += list(self.alarm_code)
        refs += [step.reg for steps in self.commands.values() for step in steps]
        for n in refs:
            if n not in by_name:
                raise ValueError(f"reference to unknown register {n}")
        for steps in self.commands.values():
            for step in steps:
                self._check_step(step)
        self._check_overlaps()
        return self

    def _check_roles(self) -> None:
        """Every required role on all three axes, an optional one on all or none, and
        a reason for each role the drive cannot offer."""
        for role in ROLES_REQUIRED:
            for ax in AXES:
                if f"{role}_{ax}" not in self._by_name:
                    raise ValueError(f"missing register {role}_{ax}")
        for role in ROLES_OPTIONAL:
            present = [f"{role}_{ax}" in self._by_name for ax in AXES]
            if any(present) and not all(present):
                raise ValueError(f"{role} needs all of {role}_X/_Y/_Z or none")
        if self.has_role("OFFSET") == ("offsets" in self.unsupported):
            raise ValueError("either OFFSET_X/_Y/_Z exist or unsupported['offsets'] says why not")
        if self.has_role("SOFT_MIN") != self.has_role("SOFT_MAX"):
            raise ValueError("SOFT_MIN and SOFT_MAX come together")

    def _check_step(self, step: CommandStep) -> None:
        """A command step writes a writable register, a value its type can hold."""
        reg = self._by_name[step.reg]
        if reg.access == "R":
            raise ValueError(f"command writes read-only register {step.reg}")
        if reg.is_bit:
            if step.value not in (0, 1):
                raise ValueError(f"command writes {step.value} to the bit "
                                 f"{step.reg} (0 or 1)")
            return
        try:
            encode_int(step.value, reg.type, reg.word_order)
        except ValueError as exc:
            raise ValueError(f"command value for {step.reg}: {exc}") from None

    def _check_overlaps(self) -> None:
        spans: dict[tuple[int | None, str], list[tuple[int, int, str]]] = {}
        for reg in self.registers:
            table = "bits" if reg.is_bit else reg.table
            spans.setdefault((reg.device_id, table), []).append(
                (reg.address, reg.address + reg.words, reg.name))
        for group in spans.values():
            group.sort()
            for (_a0, a1, n0), (b0, _b1, n1) in itertools.pairwise(group):
                if b0 < a1:
                    raise ValueError(f"registers {n0} and {n1} overlap at address {b0}")

    # --- lookup ---------------------------------------------------------------------------

    def __getitem__(self, name: str) -> Register:
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(f"register map {self.name!r} has no register {name!r}") from None

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def names(self) -> list[str]:
        return list(self._by_name)

    def has_role(self, role: str) -> bool:
        return f"{role}_X" in self._by_name

    def axis_registers(self, role: str) -> list[Register]:
        """The three per-axis registers of ``role`` (TARGET, ACTUAL, ...)."""
        return [self[f"{role}_{ax}"] for ax in AXES]

    def speed_registers(self) -> list[Register]:
        """One shared SPEED register, or SPEED_X/_Y/_Z, or none."""
        if "SPEED" in self:
            return [self["SPEED"]]
        if "SPEED_X" in self:
            return self.axis_registers("SPEED")
        return []

    def command_code(self, command: str) -> int | None:
        """The value written by a one-step command (generic map: move 1, stop 2, ...)."""
        steps = self.commands[command]
        return steps[0].value if len(steps) == 1 else None


# --- built-in profiles ------------------------------------------------------------------


def _axis_regs(role: str, base: int, step: int, **kw: Any) -> list[Register]:
    return [Register(name=f"{role}_{ax}", address=base + step * i, **kw)
            for i, ax in enumerate(AXES)]


_POS = {"type": "i32", "scale": 1000.0, "unit": "mm"}

GENERIC = RegisterMap(
    name="orthocal-generic",
    description=(
        "docs/design.md's built-in map: one Modbus device, holding registers, i32 = two "
        "registers high word first, positions in µm. Extended with the soft limits "
        "SOFT_MIN_* (50/52/54) and SOFT_MAX_* (60/62/64) the station reads before planning."
    ),
    registers=[
        Register(name="COMMAND", address=0, access="W",
                 description="1 move all axes to their targets, 2 stop, 3 home, "
                             "4 reset alarm; reads 0 once taken"),
        Register(name="STATUS", address=1,
                 description="bit0 HOMED, bit1 MOVING, bit2 IN_POSITION, bit3 ALARM, bit4 ESTOP"),
        Register(name="ALARM_CODE", address=2, description="0 = none"),
        *_axis_regs("TARGET", 10, 2, access="RW", description="joint target ρ_i", **_POS),
        *_axis_regs("ACTUAL", 20, 2, description="joint position ρ_i as counted", **_POS),
        *_axis_regs("OFFSET", 30, 2, access="RW",
                    description="joint zero offset o_i: commanded ρ_i puts the carriage "
                                "at ρ_i + o_i of the machine's own scale", **_POS),
        Register(name="SPEED", address=40, access="RW", unit="mm/s",
                 description="mm/s for the next moves"),
        *_axis_regs("SOFT_MIN", 50, 2, description="lower soft limit of ρ_i", **_POS),
        *_axis_regs("SOFT_MAX", 60, 2, description="upper soft limit of ρ_i", **_POS),
    ],
    status={
        "homed": StatusBit(registers=["STATUS"], bit=0),
        "moving": StatusBit(registers=["STATUS"], bit=1),
        "in_position": StatusBit(registers=["STATUS"], bit=2),
        "alarm": StatusBit(registers=["STATUS"], bit=3),
        "estop": StatusBit(registers=["STATUS"], bit=4),
    },
    alarm_code=["ALARM_CODE"],
    commands={
        "move": [CommandStep(reg="COMMAND", value=1)],
        "stop": [CommandStep(reg="COMMAND", value=2)],
        "home": [CommandStep(reg="COMMAND", value=3)],
        "reset_alarm": [CommandStep(reg="COMMAND", value=4)],
    },
    offset_convention="commanded ρ_i puts the carriage at ρ_i + o_i; write-back sets "
                      "o_i ← o_i − Δρ_i",
    # docs/design.md: COMMAND 1 promises no interpolation, so a controller serving this
    # map is planned as independent axes unless its config says coordinated.
    motion="independent",
)


def contiguous_runs(regs: Iterable[Register], max_gap: int = 0
                    ) -> list[tuple[int | None, str, int, int, list[Register]]]:
    """Group registers into requests: (device_id, table, start, count, registers),
    merging registers of one device and table whose address gap is ≤ ``max_gap``."""
    by_key: dict[tuple[int | None, str], list[Register]] = {}
    for reg in regs:
        by_key.setdefault((reg.device_id, reg.table), []).append(reg)
    runs: list[tuple[int | None, str, int, int, list[Register]]] = []
    for (dev, table), group in by_key.items():
        group.sort(key=lambda r: r.address)
        cur: list[Register] = [group[0]]
        for reg in group[1:]:
            end = cur[-1].address + cur[-1].words
            if reg.address - end <= max_gap and reg.address >= end:
                cur.append(reg)
            else:
                runs.append(_run(dev, table, cur))
                cur = [reg]
        runs.append(_run(dev, table, cur))
    return runs


def _run(dev: int | None, table: str, regs: list[Register]
         ) -> tuple[int | None, str, int, int, list[Register]]:
    start = regs[0].address
    return dev, table, start, regs[-1].address + regs[-1].words - start, regs
