"""The simulated devices' fault knobs, changed while they run, and what the controller did."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal


@dataclass
class Faults:
    """Fault-injection knobs; change them at run time. ``*_next`` counters are
    consumed one per reply (or request), ``*_rate`` are probabilities per reply."""

    #: lose the next N replies (the request is executed; the client times out)
    drop_next: int = 0
    drop_rate: float = 0.0
    #: corrupt the next N replies (RTU: bad CRC; TCP: malformed MBAP header)
    garble_next: int = 0
    garble_rate: float = 0.0
    #: TCP: close the connection instead of replying, N times
    disconnect_next: int = 0
    #: every reply this late (s)
    delay_s: float = 0.0
    #: answer the next N requests (or a fraction) with exception 6, unexecuted
    busy_next: int = 0
    busy_rate: float = 0.0
    #: no replies at all, requests ignored (cable pulled, drive off)
    silent: bool = False
    #: after N more completed moves, the next move faults halfway with alarm_code
    alarm_after_moves: int | None = None
    alarm_code: int = 17
    #: the emergency stop input (takes effect at the controller's next request)
    estop: bool = False
    #: after N more completed moves, the power goes halfway through the next one:
    #: unreachable for power_cut_s (TCP: connections closed, new ones refused; RTU:
    #: silent), then back unhomed with its count restarted at power_cut_count_mm
    #: on every axis (None: random) and moves refused with alarm 83 until homed
    power_cut_after_moves: int | None = None
    power_cut_s: float = 3.0
    power_cut_count_mm: float | None = 0.0
    #: False: only the network goes (a cable, a switch): back homed, positions kept
    power_cut_loses_reference: bool = True


@dataclass
class SimStats:
    """What the simulator did, for tests and the console."""

    requests: int = 0
    replies: int = 0
    #: connections the server set up (each TCP client's; the RTU line's, once open)
    connections: int = 0
    #: write requests received (function 5, 6, 15, 16, 22, 23), answered or not
    writes: int = 0
    dropped: int = 0
    garbled: int = 0
    delayed: int = 0
    busy: int = 0
    ignored: int = 0
    disconnects: int = 0
    refused: int = 0
    power_cuts: int = 0
    #: commands taken, by the generic map's code (1 move, 2 stop, 3 home, 4 reset alarm)
    commands: dict[int, int] = field(default_factory=dict)


@dataclass
class IndicatorFaults:
    """Fault knobs of one simulated gauge; change fields at any time.

    ``*_rate`` is a probability per request, ``*_next`` a count of the next
    requests that get the fault for sure (consumed as they happen). Per
    request, in this order: drop (no reply at all), gauge error reply (the
    protocol's ``error_format`` with ``error_code``; a protocol without one
    makes the gauge stay silent), garble (``garble_mode``: "corrupt" replaces
    one or two characters with junk, "truncate" sends part of the line without
    its terminator, "any" picks one at random). ``late`` delays whatever reply
    there is by ``late_s`` and combines with the others.
    """

    drop_rate: float = 0.0
    drop_next: int = 0
    error_rate: float = 0.0
    error_next: int = 0
    error_code: int = 1
    garble_rate: float = 0.0
    garble_next: int = 0
    garble_mode: Literal["any", "corrupt", "truncate"] = "any"
    late_rate: float = 0.0
    late_next: int = 0
    late_s: float = 0.5
    unplugged: bool = False
