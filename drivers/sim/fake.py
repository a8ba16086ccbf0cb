"""In-process fakes of the devices at the Protocol level (drivers.base: Motion,
ZeroOffsets, AxisController, Indicator), for tests of whatever drives them, with
no Modbus server, no pseudo-terminal, no thread and no waiting; shipped beside the
simulator, as ophyd-async ships its mocks, so that any user of the drivers may test
against them.

They behave as hardware does, not as a test would like: the axes move the virtual
Orthoglide (:mod:`drivers.sim.machine`, the simulator's own machine with its hidden
Δρ, tilts and gaps) on a clock they step themselves, so a move is over the moment
it is waited for; positions and offsets are counted in the drive's steps; the
gauges read the machine's legs where they are mounted, zeroed at mounting, clamped
at the ends of their stroke, quantised to 1 µm, with seeded noise. Faults are the
ones a drive has: an alarm on the n-th move, offsets that read back otherwise than
written. The wire-level simulators (:mod:`drivers.sim.station`) stay for the
drivers and the end-to-end runs.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from drivers.base import AxisStatus, HeldBy, Vec3
from drivers.device_errors import AlarmError, MoveTimeout, ReadbackMismatch
from drivers.sim.drive import default_soft_limits
from drivers.sim.length_reference import VirtualReference
from drivers.sim.machine import VirtualOrthoglide
from drivers.sim.specs import MachineTruth
from orthocal import counted, plane_at

COUNT_MM = 0.001  # the drive's count: positions and offsets in whole µm


class SteppedClock:
    """The machine's time, moved on only by the fake axes."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class FakeAxes:
    """An AxisController (drivers.base) over a virtual Orthoglide on a stepped clock.
    ``alarm_on_move``: the drive goes into alarm (code 0x31) on that move (counting
    from 1) and stays there until reset; ``bad_readbacks``: how many offset writes
    from now on read back ``readback_off_mm`` off what was written (a register that
    does not take what it is given); ``count_mm``: the drive's count, of its targets,
    positions and offsets alike (an IAI drive's 0.01 mm)."""

    name = "fake axes"
    held_by: HeldBy = "controller"  # the drive keeps its offsets (ZeroOffsets.held_by)

    def __init__(self, machine: VirtualOrthoglide, clock: SteppedClock) -> None:
        self.machine, self.clock = machine, clock
        self.lo, self.hi = default_soft_limits(machine)
        self.moves = 0
        self.alarm_on_move: int | None = None
        self.bad_readbacks = 0
        self.readback_off_mm = 0.005
        self.offset_writes: list[list[float]] = []
        self.moves_at_writes: list[int] = []  # how many moves preceded each write
        self.count_mm = COUNT_MM

    def _counts(self, values: Any) -> np.ndarray:
        # the drives' own rounding (J15), so that the station's model of it is exact here
        return counted(np.asarray(values, dtype=float), (self.count_mm,) * 3) + 0.0

    # --- Motion ---------------------------------------------------------------------
    def read_status(self) -> AxisStatus:
        s = self.machine.status()
        if not s.moving:
            self.machine.rest_reported = True  # the station is told the axes rest
        return AxisStatus(homed=s.homed, moving=s.moving, in_position=s.in_position,
                          alarm=s.alarm, estop=s.estop, alarm_code=s.alarm_code)

    def read_positions(self) -> np.ndarray:
        return self._counts(self.machine.actual())

    def soft_limits(self) -> tuple[np.ndarray, np.ndarray]:
        return self.lo.copy(), self.hi.copy()

    def move(self, targets: Vec3, speed_mm_s: float | None = None) -> None:
        t = self._counts(targets)
        if np.any(t < self.lo) or np.any(t > self.hi):
            raise MoveTimeout(self.name, f"target {t.tolist()} outside the soft limits")
        self.moves += 1
        if self.alarm_on_move is not None and self.moves >= self.alarm_on_move:
            self.machine.raise_alarm(0x31)
        self.clock.t += self.machine.move_to(t)

    def wait_in_position(self, targets: Vec3, timeout_s: float,
                         tolerance_mm: float = 0.002) -> np.ndarray:
        status = self.read_status()
        if status.alarm:
            raise AlarmError(self.name, "drive in alarm", status.alarm_code)
        here = self.read_positions()
        if (not status.in_position
                or np.max(np.abs(here - self._counts(targets))) > tolerance_mm):
            raise MoveTimeout(self.name, f"not in position at {here.tolist()}")
        return here

    def move_and_wait(self, targets: Vec3, speed_mm_s: float | None = None,
                      timeout_s: float | None = None, start: Vec3 | None = None,
                      watch: Callable[[], None] | None = None) -> np.ndarray:
        self.move(targets, speed_mm_s)
        if watch is not None:
            watch()  # once, with the axes already there: no time passes in between
        return self.wait_in_position(targets, timeout_s or 1.0)

    def stop(self) -> None:
        self.machine.stop()

    def home(self, timeout_s: float = 60.0) -> None:
        self.clock.t += self.machine.home()

    def reset_alarm(self) -> None:
        self.machine.reset_alarm()
        self.alarm_on_move = None

    # --- ZeroOffsets ----------------------------------------------------------------
    def read_offsets(self) -> np.ndarray:
        return self._counts(self.machine.offsets)

    def write_offsets(self, offsets: Vec3) -> np.ndarray:
        wanted = self._counts(offsets)
        self.offset_writes.append(wanted.tolist())
        self.moves_at_writes.append(self.moves)
        off = self.readback_off_mm if self.bad_readbacks > 0 else 0.0
        self.bad_readbacks = max(0, self.bad_readbacks - 1)
        self.machine.set_offsets(wanted + off)
        back = self.read_offsets()
        if np.any(np.abs(back - wanted) > self.count_mm / 2):
            raise ReadbackMismatch(self.name, f"offsets read back {back.tolist()}, "
                                   f"written {wanted.tolist()}")
        return back

    def offset_resolution_mm(self) -> float:
        return self.count_mm

    def target_resolution_mm(self) -> np.ndarray:
        return np.full(3, self.count_mm)

    def close(self) -> None:
        pass


class FakeGauge:
    """An Indicator (drivers.base) reading a leg of the machine where it is mounted;
    ``scale``: its relative scale error S, showing (1 + S) times its plunger's travel
    from where it was zeroed (as the wire-level gauge's ``scale_error``)."""

    def __init__(self, name: str, noise_mm: float, seed: int, stroke_mm: float = 12.5,
                 preload_mm: float = 6.25, scale: float = 0.0) -> None:
        self.name = name
        self.noise_mm = noise_mm
        self.scale = float(scale)
        self._rng = random.Random(seed)
        self.low, self.high = -preload_mm, stroke_mm - preload_mm
        self._source: Callable[[], float] | None = None
        self._zero = 0.0
        self.reads = 0

    def mount(self, source: Callable[[], float]) -> None:
        self._source = source
        self._zero = source()

    def unmount(self) -> None:
        self._source = None

    def read(self) -> float:
        self.reads += 1
        if self._source is None:
            return self.high  # a plunger in the air is all the way out
        raw = (1.0 + self.scale) * min(max(self._source() - self._zero, self.low), self.high)
        if self.noise_mm > 0:
            raw += self._rng.gauss(0.0, self.noise_mm)
        return round(raw / COUNT_MM) * COUNT_MM + 0.0

    def read_n(self, n: int) -> list[float]:
        return [self.read() for _ in range(n)]

    def close(self) -> None:
        pass


class FakeRig:
    """A machine with hidden errors (``truth``), its fake axes, the gauges
    ``names`` (with ``noise_mm`` of noise, seeded from ``seed``), and the
    operator's hands: a gauge mounted on a leg along a direction, its stand placed
    by eye (off its plane by a draw uniform in ±``mount_error_mm``). ``scale``: the
    gauges' scale errors by name (:class:`FakeGauge`; not named: none)."""

    def __init__(self, truth: MachineTruth | None = None, *, noise_mm: float = 0.0,
                 mount_error_mm: float = 0.0, seed: int = 1,
                 names: tuple[str, ...] = ("A", "B"),
                 scale: Mapping[str, float] | None = None) -> None:
        self.truth = truth = truth or MachineTruth()
        self.seed, self.noise_mm = seed, noise_mm
        self.geometry = truth.geometry
        self.clock = SteppedClock()
        self.machine = VirtualOrthoglide(self.geometry, truth.drho, truth.dl,
                                         true_tilt=truth.tilt, true_gap=truth.gap,
                                         speed_mm_s=1000.0, accel_mm_s2=20000.0,
                                         motion="coordinated", clock=self.clock,
                                         backlash=truth.backlash, leg_bow=truth.leg_bow,
                                         plane_bow=truth.plane_bow,
                                         joint_lead=truth.joint_lead,
                                         joint_pitch=truth.joint_pitch)
        # stands placed by eye: each mounting off the leg's middle by a draw uniform
        # in ±mount_error_mm (a stream of its own: the gauges' noise is unchanged)
        self.mount_error_mm = mount_error_mm
        self._stands = np.random.default_rng([seed, 7])
        self.axes = FakeAxes(self.machine, self.clock)
        self.gauges = {n: FakeGauge(n, noise_mm, seed * 101 + i,
                                    scale=(scale or {}).get(n, 0.0))
                       for i, n in enumerate(names)}
        #: The length references of the joints' own tests (drivers.sim.length_reference).
        self.reference = VirtualReference(self.machine.joint_values)

    def mount(self, name: str, leg: str, direction: str, at: float = 0.5) -> None:
        sign = -1.0 if direction.startswith("-") else 1.0
        # the gauge's plane: L/2 along the leg, moved by plane_at for another fraction
        plane = self.geometry.mount_plane + plane_at(at, self.geometry) + \
            self.mount_error_mm * float(self._stands.uniform(-1.0, 1.0))
        read = self.machine.source(leg, direction.lstrip("-"), plane)
        self.gauges[name].mount(lambda: sign * read())

    def unmount(self, name: str) -> None:
        self.gauges[name].unmount()

    def mount_joint_gauge(self, name: str, axis: str, plunger: int) -> None:
        """Gauge ``name`` clamped to carriage ``axis`` on a reference's datum face
        (drivers.sim.length_reference; ``plunger`` −1: pointing toward lower ρ)."""
        self.gauges[name].mount(self.reference.mount(axis, plunger))

    def set_face(self, axis: str, face_mm: float) -> None:
        self.reference.set_face(axis, face_mm)

    def remove_reference(self, axis: str) -> None:
        self.reference.remove(axis)
