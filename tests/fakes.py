"""In-process fakes of the station's devices at the Protocol level (drivers.base:
Motion, ZeroOffsets, AxisController, Indicator), for tests of engine logic — the
sequencer, the mover, write-back, the closed loop, resume — with no Modbus server,
no pseudo-terminal, no thread and no waiting.

They behave as hardware does, not as a test would like: the axes move the virtual
Orthoglide (drivers.sim.machine, the simulator's own machine with its hidden
Δρ, tilts and gaps) on a clock they step themselves, so a move is over the moment
it is waited for; positions and offsets are counted in the drive's steps; the
gauges read the machine's legs where they are mounted, zeroed at mounting, clamped
at the ends of their stroke, quantised to 1 µm, with seeded noise. Faults are the
ones a drive has: an alarm on the n-th move, offsets that read back otherwise than
written. The wire-level simulators (drivers.sim) stay for the drivers and the
end-to-end runs.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from builders import station_config

from drivers.base import AxisStatus, HeldBy, Vec3
from drivers.errors import AlarmError, MoveTimeout, ReadbackMismatch
from drivers.indicators import IndicatorGroup
from drivers.sim.drive import default_soft_limits
from drivers.sim.machine import VirtualOrthoglide
from orthocal import Geometry, plane_at
from station.commands.run import exit_status
from station.commands.simulation import SIM_PROCEDURE
from station.config import StationConfig
from station.console.operator import VirtualOperator
from station.engine.devices import Devices
from station.engine.procedure import Run, execute
from station.engine.recovery import drop_redone
from station.plan.check import check_plan
from station.plan.checker import MotionChecker
from station.plan.steps import build_plan
from station.rundir.directory import new_run_dir, now_iso, reopen, write_run_files
from station.rundir.journal import JOURNAL_NAME, Journal, JournalState

COUNT_MM = 0.001  # the drive's count: positions and offsets in whole µm


class SteppedClock:
    """The machine's time, moved on only by the fake axes."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _counts(values: Any) -> np.ndarray:
    return np.round(np.asarray(values, dtype=float) / COUNT_MM) * COUNT_MM + 0.0


class FakeAxes:
    """An AxisController (drivers.base) over a virtual Orthoglide on a stepped clock.
    ``alarm_on_move``: the drive goes into alarm (code 0x31) on that move (counting
    from 1) and stays there until reset; ``bad_readbacks``: how many offset writes
    from now on read back ``readback_off_mm`` off what was written (a register that
    does not take what it is given)."""

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

    # --- Motion ---------------------------------------------------------------------
    def read_status(self) -> AxisStatus:
        s = self.machine.status()
        return AxisStatus(homed=s.homed, moving=s.moving, in_position=s.in_position,
                          alarm=s.alarm, estop=s.estop, alarm_code=s.alarm_code)

    def read_positions(self) -> np.ndarray:
        return _counts(self.machine.actual())

    def soft_limits(self) -> tuple[np.ndarray, np.ndarray]:
        return self.lo.copy(), self.hi.copy()

    def move(self, targets: Vec3, speed_mm_s: float | None = None) -> None:
        t = _counts(targets)
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
        if not status.in_position or np.max(np.abs(here - _counts(targets))) > tolerance_mm:
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
        return _counts(self.machine.offsets)

    def write_offsets(self, offsets: Vec3) -> np.ndarray:
        wanted = _counts(offsets)
        self.offset_writes.append(wanted.tolist())
        self.moves_at_writes.append(self.moves)
        off = self.readback_off_mm if self.bad_readbacks > 0 else 0.0
        self.bad_readbacks = max(0, self.bad_readbacks - 1)
        self.machine.set_offsets(wanted + off)
        back = self.read_offsets()
        if np.any(np.abs(back - wanted) > COUNT_MM / 2):
            raise ReadbackMismatch(self.name, f"offsets read back {back.tolist()}, "
                                   f"written {wanted.tolist()}")
        return back

    def offset_resolution_mm(self) -> float:
        return COUNT_MM

    def close(self) -> None:
        pass


class FakeGauge:
    """An Indicator (drivers.base) reading a leg of the machine where it is mounted."""

    def __init__(self, name: str, noise_mm: float, seed: int, stroke_mm: float = 12.5,
                 preload_mm: float = 6.25) -> None:
        self.name = name
        self.noise_mm = noise_mm
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
        raw = min(max(self._source() - self._zero, self.low), self.high)
        if self.noise_mm > 0:
            raw += self._rng.gauss(0.0, self.noise_mm)
        return round(raw / COUNT_MM) * COUNT_MM + 0.0

    def read_n(self, n: int) -> list[float]:
        return [self.read() for _ in range(n)]

    def close(self) -> None:
        pass


class FakeRig:
    """A machine with hidden errors, its fake axes and the two gauges A and B that the
    tests' station config (builders.BASE) moves from leg to leg, and the operator's
    hands: a gauge mounted on a leg along a direction at the middle of the leg."""

    def __init__(self, *, true_drho: Sequence[float] = (0.0, 0.0, 0.0),
                 true_tilt: Sequence[float] = (0.0, 0.0, 0.0),
                 true_gap: Sequence[float] = (0.0, 0.0, 0.0),
                 backlash: Sequence[float] = (0.0, 0.0, 0.0), mount_error_mm: float = 0.0,
                 leg_bow: Sequence[float] = (0.0, 0.0, 0.0), noise_mm: float = 0.0,
                 seed: int = 1) -> None:
        self.params = {"seed": seed, "true_drho": list(true_drho), "true_dl": [0.0] * 3,
                       "true_tilt": list(true_tilt), "true_gap": list(true_gap),
                       "noise_mm": noise_mm, "mount_error_mm": mount_error_mm,
                       "backlash_mm": list(backlash), "leg_bow_mm": list(leg_bow)}
        self.geometry = Geometry()
        self.clock = SteppedClock()
        self.machine = VirtualOrthoglide(self.geometry, true_drho, (0.0, 0.0, 0.0),
                                         true_tilt=true_tilt, true_gap=true_gap,
                                         speed_mm_s=1000.0, accel_mm_s2=20000.0,
                                         motion="coordinated", clock=self.clock,
                                         backlash=backlash, leg_bow=leg_bow)
        # stands placed by eye: each mounting off the leg's middle by a draw uniform
        # in ±mount_error_mm (a stream of its own: the gauges' noise is unchanged)
        self.mount_error_mm = mount_error_mm
        self._stands = np.random.default_rng([seed, 7])
        self.axes = FakeAxes(self.machine, self.clock)
        self.gauges = {n: FakeGauge(n, noise_mm, seed * 101 + i)
                       for i, n in enumerate(("A", "B"))}

    def mount(self, name: str, leg: str, direction: str, at: float = 0.5) -> None:
        sign = -1.0 if direction.startswith("-") else 1.0
        # the gauge's plane: L/2 along the leg, moved by plane_at for another fraction
        plane = self.geometry.mount_plane + plane_at(at, self.geometry) + \
            self.mount_error_mm * float(self._stands.uniform(-1.0, 1.0))
        read = self.machine.source(leg, direction.lstrip("-"), plane)
        self.gauges[name].mount(lambda: sign * read())

    def unmount(self, name: str) -> None:
        self.gauges[name].unmount()

    def devices(self) -> Devices:
        devices = Devices(self.axes, IndicatorGroup(list(self.gauges.values())))
        devices.stack.callback(devices.indicators.close)  # the group's reader threads
        return devices

    def operator(self) -> VirtualOperator:
        return VirtualOperator(self.mount, self.unmount)

    def simulation(self) -> dict[str, Any]:
        """The hidden machine as a simulated run's journal header keeps it
        (station.record.simulation): the result states it beside what was found."""
        return dict(self.params)


def fake_config(*, uncertainty: dict[str, Any] | None = None,
                writeback: dict[str, Any] | None = None, **procedure: Any) -> StationConfig:
    """The tests' two-gauge station (builders.BASE), coordinated axes, no figures,
    no history store, and what a simulated run starts from (station.commands.
    simulation: SIM_PROCEDURE, offsets up to 3 mm) with these [procedure] keys, and
    [uncertainty] and [writeback] keys where given."""
    sections: dict[str, Any] = {}
    if uncertainty is not None:
        sections["uncertainty"] = uncertainty
    return station_config(controller={"motion": "coordinated"},
                          procedure={**SIM_PROCEDURE, **procedure},
                          writeback={"max_abs_offset_mm": 3.0, **(writeback or {})},
                          report={"figures": False}, history={"enabled": False}, **sections)


def run_on(rig: FakeRig, out: Path, config: StationConfig) -> tuple[int, dict[str, Any]]:
    """A whole run of the engine (station.engine.procedure.execute) on the rig, as
    ``orthocal run`` starts one: the plan checked before anything moves, from where
    the axes stand, then the run directory and its journal. Returns the command's
    exit status (3: completed, the loop not converged) and the result."""
    plan, checker = _checked(rig, config, from_where_they_stand=True)
    run_dir = new_run_dir(out)
    write_run_files(run_dir, config, plan, rig.simulation())
    header = {"type": "header", "version": "test", "config": config.model_dump(),
              "plan": plan.to_json(), "simulation": rig.simulation(), "started": now_iso(),
              "argv": []}
    return _execute(rig, config, plan, checker, run_dir, header, JournalState(), [],
                    now_iso())


def resume_on(rig: FakeRig, run_dir: Path, config: StationConfig
              ) -> tuple[int, dict[str, Any]]:
    """The rest of a run from its journal (``orthocal resume``'s engine part)."""
    run_dir, records, state = reopen(run_dir)
    plan, checker = _checked(rig, config, from_where_they_stand=False)
    return _execute(rig, config, plan, checker, run_dir,
                    {"type": "resumed", "version": "test", "argv": []}, state,
                    drop_redone(records), (state.header or {}).get("started") or now_iso())


def _checked(rig: FakeRig, config: StationConfig, *, from_where_they_stand: bool
             ) -> tuple[Any, MotionChecker]:
    """The plan, checked before anything moves (and from where the axes stand, as a
    new run checks it), with the checker the run goes on with."""
    limits = rig.axes.soft_limits()
    plan = build_plan(config)
    checker = MotionChecker(config, limits)
    check_plan(plan, config, limits, checker=checker)
    if from_where_they_stand:
        check_plan(plan, config, limits, start=rig.axes.read_positions(), checker=checker)
    return plan, checker


def _execute(rig: FakeRig, config: StationConfig, plan: Any, checker: MotionChecker,
             run_dir: Path, first: dict[str, Any], state: JournalState,
             records: list[dict[str, Any]], started: str) -> tuple[int, dict[str, Any]]:
    """The engine on the rig's devices, its journal opened with ``first``: the
    command's exit status and the result."""
    devices = rig.devices()
    try:
        with Journal(run_dir / JOURNAL_NAME) as journal:
            journal.append(first)
            ctx = Run(run_dir, config, plan, journal, devices, rig.operator(),
                      rig.simulation(), state, records, started, checker=checker)
            code, result = execute(ctx)
            return exit_status(result, code), result
    finally:
        devices.close()
