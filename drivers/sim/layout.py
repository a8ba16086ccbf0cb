"""Where a register map lives on the wire, as a simulated drive serves it: which
device id, table and address hold each register of a
:class:`~drivers.registers.RegisterMap`, what a request may touch, and the words
they hold (:class:`WordStore`). What the registers *mean* is the drive's
(:mod:`drivers.sim.drive`); this module only knows addresses and encodings.

A register with ``device_id`` None belongs to the server's own device id, so one
server may be several Modbus units (IAI and one-drive-per-axis layouts: 1, 2, 3).
Every register is served in its own table (holding, input, coil, discrete) and
nowhere else: any other (device, table, address), and a write to a read-only
register, answers exception 2 (illegal data address) — :meth:`MapLayout.refusal`,
which the server asks with the whole request before the datastore sees it
(pymodbus's datastore hands a coil read to its hook without the bit count).

The datastore itself is pymodbus 3.16's ``SimDevice``, one per unit id, its four
tables laid out register by register (:meth:`MapLayout.sim_devices`); the words it
answers with are copied in from the :class:`WordStore` before every request.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any

from pymodbus.constants import ExcCodes
from pymodbus.simulator import DataType, SimData, SimDevice
from pymodbus.simulator.simdevice import SimAction

from drivers.registers import Register, decode_int, encode_int, to_counts

#: The table each Modbus function code reads or writes.
TABLE_OF_FC: dict[int, str] = {1: "coil", 5: "coil", 15: "coil", 2: "discrete", 4: "input",
                               3: "holding", 6: "holding", 16: "holding", 22: "holding",
                               23: "holding"}
#: SimDevice's order of the four tables (non-shared blocks).
_TABLES = ("coil", "discrete", "holding", "input")
_RANGES = {"u16": (0, 0xFFFF), "i16": (-0x8000, 0x7FFF), "u32": (0, 0xFFFF_FFFF),
           "i32": (-0x8000_0000, 0x7FFF_FFFF)}

#: (device id, table, address) of one 16-bit word or one bit
Key = tuple[int, str, int]
#: (table, first address, count, is a write) of what a request touches
Span = tuple[str, int, int, bool]


def request_spans(pdu: Any) -> list[Span]:
    """What a request PDU reads and writes; [] for functions that touch no table
    (or a count outside what the function allows, which pymodbus refuses itself)."""
    fc = pdu.function_code
    if fc in (1, 2, 3, 4):
        spans = [(TABLE_OF_FC[fc], pdu.address, pdu.count, False)]
    elif fc in (5, 6, 22):
        spans = [(TABLE_OF_FC[fc], pdu.address, 1, True)]
    elif fc == 15:
        spans = [("coil", pdu.address, len(pdu.bits), True)]
    elif fc == 16:
        spans = [("holding", pdu.address, len(pdu.registers), True)]
    elif fc == 23:
        spans = [("holding", pdu.write_address, len(pdu.write_registers), True),
                 ("holding", pdu.read_address, pdu.read_count, False)]
    else:
        return []
    return [s for s in spans if s[2] >= 1]


class MapLayout:
    """The addresses of ``registers`` (a map's, perhaps without some) on a server
    whose own device id is ``device_id``."""

    def __init__(self, registers: Iterable[Register], device_id: int) -> None:
        self.device_id = device_id
        self.registers = list(registers)
        # Every request of a run looks up the same registers' words: found once.
        self._keys: dict[str, tuple[Register, list[Key]]] = {}
        self._at: dict[Key, tuple[Register, int]] = {}
        for reg in self.registers:
            self._keys[reg.name] = (reg, self._keys_of(reg))
            for i, key in enumerate(self.keys(reg)):
                if key in self._at:
                    raise ValueError(f"registers {self._at[key][0].name} and {reg.name} "
                                     f"overlap at {key[1]} address {key[2]} of device {key[0]}")
                self._at[key] = (reg, i)
        #: the unit ids that answer
        self.devices = sorted({key[0] for key in self._at})
        self._tables = {(key[0], key[1]) for key in self._at}

    def device_of(self, reg: Register) -> int:
        return self.device_id if reg.device_id is None else reg.device_id

    def keys(self, reg: Register) -> list[Key]:
        """The (device, table, address) of each word of ``reg``, in word order."""
        known = self._keys.get(reg.name)
        if known is not None and known[0] is reg:
            return known[1]
        return self._keys_of(reg)

    def _keys_of(self, reg: Register) -> list[Key]:
        dev = self.device_of(reg)
        return [(dev, reg.table, reg.address + i) for i in range(reg.words)]

    def serves(self, device_id: int, table: str) -> bool:
        return (device_id, table) in self._tables

    def refusal(self, device_id: int, spans: Sequence[Span]) -> ExcCodes | None:
        """Exception 2 if a span leaves the map or writes a read-only register."""
        for table, address, count, write in spans:
            for a in range(address, address + count):
                entry = self._at.get((device_id, table, a))
                if entry is None or (write and entry[0].access == "R"):
                    return ExcCodes.ILLEGAL_ADDRESS
        return None

    def touched(self, device_id: int, table: str, address: int, count: int
                ) -> dict[str, Register]:
        """The registers a request on ``count`` words (bits) from ``address`` touches,
        by name, in address order, each once (asked by name: a Register's == compares
        every field)."""
        out: dict[str, Register] = {}
        for a in range(address, address + count):
            entry = self._at.get((device_id, table, a))
            if entry is not None:
                out.setdefault(entry[0].name, entry[0])
        return out

    def sim_devices(self, action_for: Callable[[int], SimAction]) -> list[SimDevice]:
        """One pymodbus SimDevice per unit id, its four tables laid out register by
        register (gaps are invalid addresses), ``action_for(device_id)`` its hook."""
        devices = []
        for dev in self.devices:
            blocks: list[list[SimData]] = [[], [], [], []]
            for reg in self.registers:
                if self.device_of(reg) != dev:
                    continue
                if reg.is_bit:
                    data = SimData(reg.address, values=False, datatype=DataType.BITS)
                else:
                    data = SimData(reg.address, count=reg.words, values=0,
                                   datatype=DataType.REGISTERS, readonly=reg.access == "R")
                blocks[_TABLES.index(reg.table)].append(data)
            for i, block in enumerate(blocks):
                if not block:  # pymodbus needs every table; refusal() keeps it unreachable
                    block.append(SimData(0, values=False, datatype=DataType.BITS) if i < 2
                                 else SimData(0, datatype=DataType.INVALID))
            devices.append(SimDevice(id=dev, simdata=(blocks[0], blocks[1], blocks[2],
                                                      blocks[3]),
                                     action=action_for(dev)))
        return devices


class WordStore:
    """The words (and bits) a drive holds, by :data:`Key`; every register of the
    layout starts at 0. Values go in and out through each register's type, word
    order and scale; :meth:`written` gives a copy with a request's values applied,
    to judge a write before it lands."""

    def __init__(self, layout: MapLayout, words: dict[Key, int] | None = None) -> None:
        self.layout = layout
        self._words = dict(words) if words is not None else {
            key: 0 for reg in layout.registers for key in layout.keys(reg)}

    def written(self, device_id: int, table: str, address: int,
                values: Sequence[int]) -> WordStore:
        new = WordStore(self.layout, self._words)
        for i, v in enumerate(values):
            key = (device_id, table, address + i)
            if key in new._words:
                new._words[key] = int(bool(v)) if table in ("coil", "discrete") else int(v)
        return new

    def words(self, reg: Register) -> list[int]:
        return [self._words[key] for key in self.layout.keys(reg)]

    def counts(self, reg: Register) -> int:
        """The raw integer value (a bit: 0 or 1)."""
        words = self.words(reg)
        return words[0] if reg.is_bit else decode_int(words, reg.type, reg.word_order)

    def value(self, reg: Register) -> float:
        return self.counts(reg) / reg.scale

    def put_counts(self, reg: Register, counts: int) -> None:
        """Store raw counts, saturated at the register's range as a drive's would be
        (a bit: any nonzero count is 1)."""
        if reg.is_bit:
            words = [int(counts != 0)]
        else:
            lo, hi = _RANGES[reg.type]
            words = encode_int(min(max(counts, lo), hi), reg.type, reg.word_order)
        for key, w in zip(self.layout.keys(reg), words, strict=True):
            self._words[key] = w

    def put(self, reg: Register, value: float) -> None:
        # float(): the machine's values are numpy scalars, several times slower to
        # round than a float, and every request of a run stores a dozen of them
        self.put_counts(reg, to_counts(float(value), reg.scale))

    def copy_into(self, device_id: int, table: str, start: int, registers: list[int]) -> None:
        """Show the stored words in a SimDevice block of ``table`` starting at
        ``start`` (bits: packed 16 to a word, ``start`` in words), in place."""
        bits = table in ("coil", "discrete")
        for (dev, tab, address), w in self._words.items():
            if dev != device_id or tab != table:
                continue
            i = address // 16 - start if bits else address - start
            if not 0 <= i < len(registers):
                continue
            if bits:
                mask = 1 << address % 16
                registers[i] = registers[i] | mask if w else registers[i] & ~mask
            else:
                registers[i] = w
