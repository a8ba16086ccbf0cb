"""The whole virtual station in-process: a simulated controller (real Modbus TCP
server on 127.0.0.1, ephemeral port) and simulated dial indicators on ptys (or on
TCP sockets, ``GaugeSpec.line``, where there are none), all
looking at one :class:`~drivers.sim.machine.VirtualOrthoglide` with hidden
errors. What it is made of comes as specs (:mod:`drivers.sim.specs`): the
machine's hidden truth, the drive, the gauges and their stands, the devices'
faults. It is hardware only: which gauges a calibration moves where, and how
whoever uses it is told about it (a config file), are that user's business.

The drive serves any register map (``DriveSpec.register_map``, default
"orthocal-generic"), as a drive of that layout would (:mod:`drivers.sim.drive`),
so a new map can be rehearsed before the machine is touched.

The gauges (``GaugeSpec.names``) wait to be mounted: the operator — here
:meth:`VirtualStation.mount` — puts each against a leg along a direction ("-y":
reversed, to exercise the sign convention), or the spec mounts them from the
start (``GaugeSpec.mounted``).

Stand misplacement (``GaugeSpec.mount_error_mm``): an operator sets each indicator
stand "at the middle of the leg" by eye, so each mounting puts the indicator's
plane x_i = M_i off the nominal L/2 by a hidden error drawn uniform in
±``mount_error_mm`` (docs/model.md, "Where the indicator plane is"); every mounting
draws anew, as a real operator places the stand again. ``mount_errors`` fixes
them instead (name -> mm), for figures that need a given misplacement.

The virtual controller's offsets can be persisted to a file after every write
(``nvram_path``), like a real drive's non-volatile memory, so a resumed or
rolled-back simulated run sees what was written before. The same file keeps
whether the drive is homed and how its count relates to the carriages (a power
cut loses both until homing), and a second file next to it
(``sim_gauges.json``) where the operator's gauges sit and where they were
zeroed: a virtual station restarted after an interruption finds the machine and
the gauges as they were left.

The drive (``DriveSpec.motion``): "coordinated", "independent" or a
:class:`~drivers.sim.drive_motion.DriveMotion` (profile shape, acceleration, start
delays, one axis after another), and ``DriveSpec.actual_accel_mm_s2`` an
acceleration of its own: what a real drive does without telling anyone.
:attr:`VirtualStation.accel_mm_s2` stays what it is set up with.

Form and scale: ``MachineTruth.leg_bow`` bows each leg (the sagitta of its
surface at its middle, mm, :mod:`drivers.sim.bowed_legs`; ``plane_bow`` each gauge
plane apart), so that a gauge's plunger,
touching the leg at another point of it at each posture, sees the curve;
``GaugeSpec.scale`` gives the gauges a relative scale error: each shows
(1 + S) times its plunger's travel (:class:`~drivers.sim.pty_gauges.SimIndicator`).

Out of stroke (:attr:`VirtualStation.out_of_stroke`) is counted from the
machine's trajectory, not only from the readings, and a stand can be knocked
(:meth:`VirtualStation.knock`): :mod:`drivers.sim.strokes`.

Time (``time_scale``): the whole station may run on a faster clock — the
machine's moves take their durations in its clock's seconds, that divided by the
scale in real ones, and the gauges' line time is as many times shorter — where
real time proves nothing (a whole calibration in a test: the readings at the
stops and every count do not depend on it). What is measured against the
station's real timeouts stays real: late and dropped replies, unplugging, power
cuts. Not given, it is ``ORTHOCAL_SIM_TIME_SCALE`` from the environment (default
1, real time): how the tests run every virtual station at once, those started in
a subprocess included.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from drivers.base import Vec3
from drivers.files import write_atomic
from drivers.indicator_protocols import make_protocol
from drivers.sim.controller import SimController
from drivers.sim.length_reference import VirtualReference
from drivers.sim.machine import VirtualOrthoglide
from drivers.sim.pty_gauges import SimIndicator
from drivers.sim.specs import DeviceFaults, DriveSpec, GaugeSpec, MachineTruth
from drivers.sim.strokes import OutOfStroke, StrokeWatch
from orthocal import plane_at

MOUNTS_NAME = "sim_gauges.json"
#: The environment's time scale for a station given none (module docstring, "Time").
TIME_SCALE_ENV = "ORTHOCAL_SIM_TIME_SCALE"


def default_time_scale() -> float:
    """``ORTHOCAL_SIM_TIME_SCALE`` (a number > 0), 1 when unset or empty."""
    text = os.environ.get(TIME_SCALE_ENV, "").strip()
    if not text:
        return 1.0
    try:
        scale = float(text)
    except ValueError:
        scale = math.nan
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"{TIME_SCALE_ENV} must be a number > 0, got {text!r}")
    return scale


class _PersistentMachine(VirtualOrthoglide):
    """A machine whose controller offsets and homing state survive a restart
    through a file."""

    nvram_path: Path | None = None

    def set_offsets(self, offsets: Vec3) -> None:
        super().set_offsets(offsets)
        self.save_offsets()

    def power_cycle(self, count_mm: Vec3 | None = None,
                    seed: int | None = None) -> None:
        super().power_cycle(count_mm, seed)
        self.save_offsets()

    def _set_homed(self) -> None:
        super()._set_homed()
        self.save_offsets()

    def save_offsets(self) -> None:
        if self.nvram_path is None:
            return
        write_atomic(self.nvram_path, json.dumps({
            "offsets_mm": [float(v) for v in self.offsets],
            "homed": bool(self._homed),  # not status(): this runs inside _advance
            "count_shift_mm": [float(v) for v in self.count_shift]}))

    def load(self, saved: dict[str, Any]) -> None:
        self.set_offsets(saved["offsets_mm"])
        with self._lock:
            self._homed = bool(saved.get("homed", True))
            self.count_shift = np.asarray(saved.get("count_shift_mm", [0.0] * 3), dtype=float)


class VirtualStation:
    """The virtual station (module docstring), from its specs: the machine's hidden
    ``truth``, its ``drive``, its ``gauges`` and stands, the devices' ``faults`` from
    the start (:mod:`drivers.sim.specs`; each None: the spec's defaults). ``seed``
    draws the gauges' noise, the drive's random faults and the stands' errors (None:
    fresh draws); ``nvram_path`` keeps the drive's memory and the gauges' mounting
    (module docstring); ``clock``: the machine's clock (a stepped one in tests that
    follow a move instant by instant); ``time_scale``: how many times faster than
    real time the machine's clock runs (unless ``clock`` is given) and how many
    times shorter the gauges' line time is (module docstring, "Time"; None: the
    environment's, :func:`default_time_scale`)."""

    def __init__(
        self,
        truth: MachineTruth | None = None,
        drive: DriveSpec | None = None,
        gauges: GaugeSpec | None = None,
        faults: DeviceFaults | None = None,
        *,
        seed: int | None = 0,
        nvram_path: str | Path | None = None,
        clock: Callable[[], float] | None = None,
        time_scale: float | None = None,
    ) -> None:
        self.truth = truth = truth or MachineTruth()
        self.drive_spec = drive = drive or DriveSpec()
        self.gauge_spec = gauges = gauges or GaugeSpec()
        faults = faults or DeviceFaults()
        #: Each gauge's relative scale error (name -> S); checks the gauges' spec first.
        self.gauge_scale = gauges.per_gauge_scale()
        self.geometry = truth.geometry
        scale = default_time_scale() if time_scale is None else float(time_scale)
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"time_scale must be finite and > 0, got {time_scale}")
        self.time_scale = scale
        # what the drive and the gauges are, as a description of them reads them
        self.protocol = gauges.protocol
        self.speed_mm_s, self.accel_mm_s2 = drive.speed_mm_s, drive.accel_mm_s2
        self.profile = drive.profile  # the name its map goes by (None: the map's own)
        self.mount_error_mm = gauges.mount_error_mm
        self._fixed_mounts = dict(gauges.mount_errors)
        self._seed = seed
        self._placement: str | None = None  # the caller's name of the placement, place()
        self._stand_error = 0.0  # of the mounting in progress, for source()
        #: Every mounting: (indicator, leg, direction, mount error in mm), in order.
        self.mount_log: list[tuple[str, str, str, float]] = []
        self.machine = self._machine(clock, nvram_path)
        #: The length references of the joints' own tests (drivers.sim.length_reference),
        #: read through the carriages' true positions.
        self.reference = VirtualReference(self.machine.joint_values)
        # Out-of-stroke accounting and knocks (drivers.sim.strokes).
        self._watch = StrokeWatch(self.machine, self.geometry, self._mounted_gauges)
        self.mounts_path: Path | None = None
        self._mounts: dict[str, dict[str, Any]] = {}
        #: (stroke, preload) per gauge, mm; a test may change one before a run reads it.
        self.strokes = {n: gauges.stroke_of(n) for n in gauges.names}
        # Stable paths, as /dev/serial/by-id/... gives a real USB adapter: a gauge on a
        # pty unplugged and plugged back (SimIndicator.unplug_for) keeps its port (a
        # TCP line keeps its URL by itself).
        self._link_dir = Path(tempfile.mkdtemp(prefix="orthocal-serial-by-id-")) \
            if gauges.line == "pty" else None
        self.controller = self._controller(faults)
        self.indicators: dict[str, SimIndicator] = {}
        try:
            self._start(faults, nvram_path)
        except BaseException:
            self.close()
            raise

    def _machine(self, clock: Callable[[], float] | None,
                 nvram_path: str | Path | None) -> _PersistentMachine:
        """The virtual Orthoglide with the truth's errors, moving as the drive does
        (at its own acceleration where it has one), its drive's memory in
        ``nvram_path`` (what it held before, if anything)."""
        t, d = self.truth, self.drive_spec
        machine = _PersistentMachine(
            self.geometry, t.drho, t.dl, true_tilt=t.tilt, true_gap=t.gap,
            speed_mm_s=d.speed_mm_s, accel_mm_s2=d.moving_accel_mm_s2, motion=d.motion,
            clock=clock, time_scale=1.0 if clock is not None else self.time_scale,
            backlash=t.backlash, leg_bow=t.leg_bow, plane_bow=t.plane_bow,
            joint_lead=t.joint_lead, joint_pitch=t.joint_pitch)
        if nvram_path is not None:
            path = Path(nvram_path)
            if path.exists():
                machine.load(json.loads(path.read_text()))
            machine.nvram_path = path
        return machine

    def _controller(self, faults: DeviceFaults) -> SimController:
        """The drive's Modbus server (not started), serving the spec's map."""
        d = self.drive_spec
        options = dict(d.controller_options)
        if d.register_map is not None:
            options["register_map"] = d.register_map
        return SimController(self.machine, port=d.port, faults=faults.controller,
                             seed=self._seed, **options)

    def _start(self, faults: DeviceFaults, nvram_path: str | Path | None) -> None:
        """The controller's server and a simulator per gauge, started; the gauges
        back where the saved mounting had them, or where the spec mounts them."""
        spec = self.gauge_spec
        self.controller.start()
        line_baud = spec.baud if spec.baud is not None else make_protocol(spec.protocol).baudrate
        for i, name in enumerate(spec.names):
            stroke, preload = self.strokes[name]
            sim = SimIndicator(spec.protocol, lambda: 0.0, noise_mm=spec.noise_mm,
                               baud=line_baud if spec.line_time else None,
                               faults=faults.gauges.get(name),
                               seed=None if self._seed is None else self._seed * 101 + i,
                               name=name, stroke_mm=stroke, preload_mm=preload,
                               link=None if self._link_dir is None else
                               self._link_dir / f"usb-orthocal-sim-gauge-{name}-if00",
                               time_scale=self.time_scale, scale_error=self.gauge_scale[name],
                               line=spec.line)
            sim.unmount()
            sim.at_rest = lambda: self.machine.rest_reported
            self.indicators[name] = sim
            sim.start()
        if nvram_path is not None:
            self._restore_mounts(Path(nvram_path).with_name(MOUNTS_NAME))
        # A separate process cannot be told where the operator mounted the gauges:
        # those the spec mounts stay where it puts them.
        for name, leg, direction in spec.mounted:
            self.mount(name, leg, direction)

    # --- the virtual operator's hands ---------------------------------------------------

    def source(self, leg: str, direction: str) -> Callable[[], float]:
        """What a gauge on ``leg`` along ``direction`` reads, its stand in the plane
        the mounting in progress stands in (``self._stand_error`` off the nominal L/2:
        its place along the leg and the error it was placed with)."""
        sign = -1.0 if direction.startswith("-") else 1.0
        axis = direction.lstrip("-")
        plane = self.geometry.mount_plane + self._stand_error
        read = self.machine.source(leg, axis, plane)
        return lambda: sign * read()

    def place(self, where: str | None) -> None:
        """Name the placement of the next mountings (any key the caller tells its
        placements apart by): their stand errors become a function of the seed and
        the key, so a simulated run resumed after a kill places a stand exactly
        where the uninterrupted run would have. None: a fresh draw at every
        mounting."""
        self._placement = where

    def mount(self, name: str, leg: str, direction: str, at: float = 0.5) -> None:
        """Put indicator ``name`` against ``leg`` along ``direction`` ("-y":
        reversed) at the fraction ``at`` of the leg from its carriage's joint (the
        middle by default; a second gauge plane at 0.25 or 0.75), as placed by eye
        (a new stand error at every mounting, see :meth:`place`), and zero it
        there."""
        if not 0.0 < at < 1.0:
            raise ValueError(f"a gauge's place along the leg is a fraction in (0, 1), got {at!r}")
        where = self._placement
        if name in self._fixed_mounts:
            error = float(self._fixed_mounts[name])
        else:
            error = float(self._mount_draw(name, leg, where)) * self.mount_error_mm
        self.mount_log.append((name, leg, direction, error))
        gauge = self.indicators[name]
        self._watch.flush()  # what happened so far, with the mounting it happened under
        self._watch.mounted(name)
        # where the stand stands: its plane off L/2, the placement error included
        plane = plane_at(at, self.geometry) + error
        gauge.mount(self._source_at(name, leg, direction, plane))
        self._mounts[name] = {"leg": leg, "direction": direction, "zero_mm": gauge.zero_mm,
                              "stand_error_mm": error, "plane_offset_mm": plane}
        self._save_mounts()

    def _source_at(self, name: str, leg: str, direction: str,
                   plane_offset: float) -> Callable[[], float]:
        # Through self.source(leg, direction), which tests wrap to inject knocks;
        # plus this station's own knocks of gauge ``name``. ``plane_offset``: the
        # stand's plane off L/2 (its place along the leg and its placement error).
        self._stand_error = plane_offset
        try:
            read = self.source(leg, direction)
        finally:
            self._stand_error = 0.0
        sign = float(self.indicators[name].sign)

        def knocked() -> float:
            value = read()
            return value + sign * self._watch.knock_shift(name, self.machine.now())
        return knocked

    def _mount_draw(self, name: str, leg: str, where: str | None) -> float:
        """Uniform in [-1, 1]: from (seed, placement) when both are known, else fresh."""
        if where is None or self._seed is None:
            return float(np.random.default_rng().uniform(-1.0, 1.0))
        # A stream of its own (crc32 of the placement): the gauges' noise is unchanged.
        key = zlib.crc32(f"{where}:{name}:{leg}".encode())
        return float(np.random.default_rng([self._seed, 7, key]).uniform(-1.0, 1.0))

    def mount_joint_gauge(self, name: str, axis: str, plunger: int) -> None:
        """Clamp indicator ``name`` to carriage ``axis``, its plunger along the axis
        (``plunger``: −1 pointing toward lower ρ, +1 higher) on the datum face of a
        reference beside the rail (drivers.sim.length_reference), and zero it there: the
        station's own test of the joint. Not kept across a restart (a test resumed is
        mounted again)."""
        gauge = self.indicators[name]
        self._watch.flush()
        self._watch.unmounted(name)
        if self._mounts.pop(name, None) is not None:
            self._save_mounts()
        gauge.mount(self.reference.mount(axis, plunger))

    def stand_joint_gauge(self, name: str, axis: str, plunger: int, faces_mm: list[float],
                          datum_mm: float) -> None:
        """Indicator ``name`` on carriage ``axis`` from the start, against a reference
        standing beside its rail whose face is set as the station asks
        (drivers.sim.length_reference.VirtualReference.standing): its datum's null where the
        joint counts ``datum_mm``, the gauge reading 0 at every null. For a station in
        another process (``orthocal sim``)."""
        i = "xyz".index(axis)
        x_datum = float(datum_mm) + float(self.machine.true_drho[i])
        self.indicators[name].mount(self.reference.standing(axis, plunger, list(faces_mm),
                                                            x_datum), zero_mm=0.0)

    def set_face(self, axis: str, face_mm: float) -> None:
        """The operator sets the reference's face ``face_mm`` from its datum at the
        plunger of joint ``axis``'s test."""
        self.reference.set_face(axis, face_mm)

    def remove_reference(self, axis: str) -> None:
        """The operator takes joint ``axis``'s reference off the base."""
        self.reference.remove(axis)

    def unmount(self, name: str) -> None:
        self._watch.flush()
        self.indicators[name].unmount()
        self._watch.unmounted(name)
        if self._mounts.pop(name, None) is not None:
            self._save_mounts()

    # --- knocks and the out-of-stroke count ----------------------------------------------

    def knock(self, name: str, shift_mm: float, *, on_move: int, at_fraction: float) -> None:
        """Knock gauge ``name``'s stand during the machine's move number ``on_move``
        (:meth:`drivers.sim.strokes.StrokeWatch.knock`)."""
        if name not in self.indicators:
            raise ValueError(f"no indicator {name!r} (have {', '.join(self.indicators)})")
        self._watch.knock(name, shift_mm, on_move=on_move, at_fraction=at_fraction)

    @property
    def out_of_stroke(self) -> list[OutOfStroke]:
        """Every segment so far that drove a mounted gauge's plunger past an end of
        its stroke (one per segment and gauge), whether or not a reading saw it."""
        return self._watch.out_of_stroke()

    @property
    def out_of_stroke_count(self) -> int:
        return len(self.out_of_stroke)

    def _mounted_gauges(self) -> list[tuple[str, dict[str, Any], SimIndicator | None]]:
        # a copy: mount() may change the mountings while they are evaluated
        return [(name, mount, self.indicators.get(name))
                for name, mount in list(self._mounts.items())]

    def _save_mounts(self) -> None:
        if self.mounts_path is not None:
            write_atomic(self.mounts_path, json.dumps(self._mounts))

    def _restore_mounts(self, path: Path) -> None:
        """The gauges stay on the machine while the station restarts."""
        self.mounts_path = path
        if not path.exists():
            return
        for name, m in json.loads(path.read_text()).items():
            if name in self.indicators:
                # the stand stays where it was placed, misplacement included
                src = self._source_at(name, m["leg"], m["direction"],
                                      m.get("plane_offset_mm", m.get("stand_error_mm", 0.0)))
                self._watch.mounted(name)
                self.indicators[name].mount(src, zero_mm=m["zero_mm"])
                self._mounts[name] = m

    # --- description ----------------------------------------------------------------------

    def ports(self) -> dict[str, Any]:
        return {"controller": self.controller.port if self.controller.transport == "tcp"
                else self.controller.serial_port,
                "indicators": {n: s.port for n, s in self.indicators.items()}}

    @property
    def offsets(self) -> np.ndarray:
        return self.machine.offsets

    def persist_offsets(self, path: str | Path) -> None:
        """Keep the drive's memory in ``path`` and the gauges' mounting next to it."""
        self.machine.nvram_path = Path(path)
        self.machine.save_offsets()
        self.mounts_path = Path(path).with_name(MOUNTS_NAME)
        self._save_mounts()

    def close(self) -> None:
        for sim in self.indicators.values():
            sim.close()
        self.indicators = {}
        self.controller.close()
        if self._link_dir is not None:
            shutil.rmtree(self._link_dir, ignore_errors=True)

    def __enter__(self) -> VirtualStation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
