"""Out of stroke, and knocked stands, for the virtual station
(:mod:`drivers.sim.station`): kept apart from the station's assembly because
it follows the machine's whole trajectory on its own, whoever reads a gauge.

Out of stroke (:attr:`~drivers.sim.station.VirtualStation.out_of_stroke`):
``SimIndicator.clamped`` counts readings taken at a stroke end, which says
nothing of a plunger driven past its end between two readings. The station
therefore also follows the machine's trajectory itself: every motion segment (a
move, a homing, the braking after a stop, cut where it ends or where a gauge is
mounted or taken off) is sampled densely in time and each mounted gauge's
plunger travel evaluated there from the geometry (:func:`orthocal.leg_reading`
at the true joint values, the stand's plane, the true errors, and a bowed leg's
form: :meth:`~drivers.sim.machine.VirtualOrthoglide.readings`); one
:class:`OutOfStroke` per segment and gauge whose travel left
[−preload, stroke − preload]. A knocked stand
(:meth:`~drivers.sim.station.VirtualStation.knock`) shifts a gauge's travel
from a given instant of a given move on, for the readings and this count alike.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from drivers.sim.drive_motion import Segment
from drivers.sim.machine import VirtualOrthoglide
from drivers.sim.pty_gauges import SimIndicator
from orthocal import Geometry

# Closed segments wait for the next look at them (a mounting, out_of_stroke) up to
# this many; beyond, the oldest is evaluated as each new one closes (under the
# machine's lock, ~0.1 ms per gauge), so memory stays bounded.
_PENDING_MAX = 64


@dataclass(frozen=True)
class OutOfStroke:
    """One motion segment that drove gauge ``gauge``'s plunger past an end of its
    stroke: ``past_mm`` beyond it (the farthest, over the segment), ``end`` "low"
    (−preload: the leg left the fully extended plunger) or "high" (stroke −
    preload: the plunger pushed to its stop). ``segment``/``kind``/``move``: the
    :class:`~drivers.sim.drive_motion.Segment` (its index, "move"/"home"/"brake", the
    move's number in ``moves_started``)."""

    gauge: str
    leg: str
    direction: str
    segment: int
    kind: str
    move: int | None
    past_mm: float
    end: Literal["low", "high"]


@dataclass
class _Knock:
    """A stand to be knocked during move ``on_move`` at ``at_fraction`` of its
    duration; ``t`` (clock time) once that move has started."""

    name: str
    shift_mm: float
    on_move: int
    at_fraction: float
    t: float | None = None


#: The station's gauges as (name, its mounting: leg, direction, stand_error_mm;
#: its simulator, None if the station has none of that name), looked at afresh
#: at every evaluation.
Mounts = Callable[[], list[tuple[str, dict[str, Any], SimIndicator | None]]]


class StrokeWatch:
    """The out-of-stroke count and the knocks of one virtual station (module
    docstring): listens to ``machine``'s segments and moves from construction on.
    The station says when a gauge is mounted or taken off (:meth:`mounted`,
    :meth:`unmounted`, after a :meth:`flush`), and adds :meth:`knock_shift` to
    a knocked gauge's readings."""

    def __init__(self, machine: VirtualOrthoglide, geometry: Geometry, mounts: Mounts) -> None:
        self.machine = machine
        self.geometry = geometry
        self._mounts = mounts
        # segments not yet evaluated, the events by (segment, gauge), the knocks,
        # when each gauge was mounted
        self._acct_lock = threading.Lock()
        self._pending: list[Segment] = []
        self._events: dict[tuple[int, str], OutOfStroke] = {}
        self._knocks: list[_Knock] = []
        self._mounted_at: dict[str, float] = {}
        machine.segment_listeners.append(self._on_segment)
        machine.move_listeners.append(self._on_move)

    def mounted(self, name: str) -> None:
        """Gauge ``name`` is mounted now: knocks of an earlier mounting no longer
        shift it."""
        self._mounted_at[name] = self.machine.now()

    def unmounted(self, name: str) -> None:
        self._mounted_at.pop(name, None)

    def knock(self, name: str, shift_mm: float, *, on_move: int, at_fraction: float) -> None:
        """Knock gauge ``name``'s stand during the machine's move number ``on_move``
        (as :attr:`~drivers.sim.machine.VirtualOrthoglide.moves_started` counts it:
        the next move is ``moves_started + 1``) at ``at_fraction`` (0..1) of that
        move's duration: from then on (until the gauge is mounted again) its plunger
        travel is ``shift_mm`` more (+ pushed in), as if the stand had slid along the
        measuring direction. The instant is fixed when the move starts, so a stop
        before it does not prevent the knock. Not kept across a restart of the
        station (the mounting file knows nothing of it)."""
        if not math.isfinite(shift_mm):
            raise ValueError(f"shift_mm must be finite, got {shift_mm}")
        if not 0.0 <= at_fraction <= 1.0:
            raise ValueError(f"at_fraction must be within 0..1, got {at_fraction}")
        if on_move <= self.machine.moves_started:
            raise ValueError(f"move {on_move} has already started "
                             f"({self.machine.moves_started} so far)")
        with self._acct_lock:
            self._knocks.append(_Knock(name, float(shift_mm), int(on_move), float(at_fraction)))

    def _on_move(self, number: int, t0: float, duration: float) -> None:
        # under the machine's lock: only bookkeeping here
        with self._acct_lock:
            for k in self._knocks:
                if k.t is None and k.on_move == number:
                    k.t = t0 + k.at_fraction * duration

    def _knocks_of(self, name: str) -> list[tuple[float, float]]:
        """(instant, shift) of the knocks that hit gauge ``name``'s present mounting
        (or will: the instant is known); call with ``_acct_lock`` held."""
        since = self._mounted_at.get(name)
        if since is None:
            return []
        return [(k.t, k.shift_mm) for k in self._knocks
                if k.name == name and k.t is not None and k.t >= since]

    def knock_shift(self, name: str, now: float) -> float:
        """How far the knocks so far have shifted gauge ``name``'s travel (mm)."""
        with self._acct_lock:
            return sum(shift for t, shift in self._knocks_of(name) if t <= now)

    def _on_segment(self, segment: Segment) -> None:
        # Called under the machine's lock; evaluation needs none of its state.
        with self._acct_lock:
            self._pending.append(segment)
            if len(self._pending) > _PENDING_MAX:
                # the oldest one only: a fraction of a ms, not a stall of the drive
                self._evaluate(self._pending.pop(0))

    def flush(self) -> None:
        """Evaluate every segment up to now (the one in progress included, as a
        piece), before the mounting changes or the count is looked at."""
        self.machine.flush_segment()  # not under _acct_lock: it calls _on_segment
        with self._acct_lock:
            self._evaluate_pending()

    def _evaluate_pending(self) -> None:
        pending, self._pending = self._pending, []
        for segment in pending:
            self._evaluate(segment)

    def _evaluate(self, segment: Segment) -> None:
        """The plunger travel of every mounted gauge over ``segment``, sampled
        densely (Segment.sample), from the geometry at the true joint values, the
        quantity SimIndicator._value_mm clamps: sign·(source − zero)."""
        m = self.machine
        gauges: list[tuple[str, dict[str, Any], SimIndicator]] = []
        for name, mount, gauge in self._mounts():
            if gauge is None or not gauge.mounted or gauge.stroke_mm is None:
                continue
            gauges.append((name, mount, gauge))
        if not gauges:
            return
        knocks = {name: self._knocks_of(name) for name, _, _ in gauges}
        times, rho = m.sample_segment(segment,
                                      extra_times=[t for ks in knocks.values() for t, _ in ks])
        for name, mount, gauge in gauges:
            direction: str = mount["direction"]
            sign = -1.0 if direction.startswith("-") else 1.0
            offset_key = "plane_offset_mm" if "plane_offset_mm" in mount else "stand_error_mm"
            plane = self.geometry.mount_plane + float(mount.get(offset_key, 0.0))
            # the machine's own readings: a bowed leg pushes the plunger too
            reading = m.readings(rho, mount["leg"], direction.lstrip("-"), mount=plane)
            travel = gauge.travel_mm(sign * np.asarray(reading, dtype=float))
            for t, shift in knocks[name]:
                travel = travel + np.where(times >= t, shift, 0.0)
            limits = gauge.stroke_limits()
            assert limits is not None  # a stroke, checked above
            low, high = limits
            below, above = low - float(np.min(travel)), float(np.max(travel)) - high
            if below <= 0 and above <= 0:
                continue
            end: Literal["low", "high"] = "low" if below >= above else "high"
            event = OutOfStroke(name, mount["leg"], direction, segment.index, segment.kind,
                                segment.move, max(below, above), end)
            key = (segment.index, name)
            old = self._events.get(key)
            if old is None or event.past_mm > old.past_mm:
                self._events[key] = event  # one per (segment, gauge): the farthest

    def out_of_stroke(self) -> list[OutOfStroke]:
        """Every segment so far that drove a mounted gauge's plunger past an end of
        its stroke (one per segment and gauge), whether or not a reading saw it."""
        self.flush()
        with self._acct_lock:
            return list(self._events.values())
