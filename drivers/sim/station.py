"""The whole virtual station in-process: a simulated controller (real Modbus TCP
server on 127.0.0.1, ephemeral port) and simulated dial indicators on ptys, all
looking at one :class:`~drivers.sim.machine.VirtualOrthoglide` with hidden
errors. ``config()`` describes it as a station config (a plain dict in the
shape of station.toml, so drivers does not import station).

The drive serves any register map (``register_map``, default "orthocal-generic"),
as a drive of that layout would (:mod:`drivers.sim.drive`), so a new map can be
rehearsed before the machine is touched: ``config()`` then names it ``profile``
(or the map's name), gives the map's default unit id, and, for a map without
soft-limit registers, the limits the drive enforces as ``soft_min``/``soft_max``.

Two setup styles: ``indicator_count=2`` (A and B moved from leg to leg; the
operator — here :meth:`mount` — re-mounts them before each setup) and
``indicator_count=6`` (A..F, two per leg; one of them mounted reversed to
exercise the sign convention).

Stand misplacement (``mount_error_mm``): an operator sets each indicator stand
"at the middle of the leg" by eye, so each mounting puts the indicator's plane
x_i = M_i off the nominal L/2 by a hidden error drawn uniform in
±``mount_error_mm`` (docs/model.md, "Where the indicator plane is"); every mounting
draws anew, as a real operator places the stand again. ``mount_errors`` fixes
them instead (name -> mm), for figures that need a given misplacement.

The virtual controller's offsets can be persisted to a file after every write
(``nvram_path``), like a real drive's non-volatile memory, so a resumed or
rolled-back simulated run sees what was written before. The same file keeps
whether the drive is homed and how its count relates to the carriages (a power
cut loses both until homing), and a second file next to it
(``sim_gauges.json``) where the operator's gauges sit and where they were
zeroed: a station restarted for ``resume`` finds the machine and the gauges as
the interrupted run left them.

The drive (``motion``): "coordinated", "independent" or a
:class:`~drivers.sim.motion.DriveMotion` (profile shape, acceleration, start
delays, one axis after another), and ``drive_accel_mm_s2`` an acceleration of its
own: what a real drive does without telling the station. ``config()`` says only
what an integrator would write: ``motion = "coordinated"`` for a drive that
interpolates, nothing otherwise (the profile's default, any timing), and the
``accel_mm_s2`` the station was given, not the drive's.

Form and scale: ``leg_bow`` bows each leg (the sagitta of its
surface at its middle, mm, :mod:`drivers.sim.form`), so that a gauge's plunger,
touching the leg at another point of it at each posture, sees the curve;
``gauge_scale`` gives the gauges a relative scale error (one for all, or one per
gauge in the order of ``config()``'s indicators, or by name): each shows
(1 + S) times its plunger's travel (:class:`~drivers.sim.indicators.SimIndicator`).

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
1, real time): how the tests run every virtual station at once, those of
``orthocal run --simulate`` and ``orthocal sim`` in a subprocess included.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from drivers.base import Vec3
from drivers.files import write_atomic
from drivers.indicator_protocols import make_protocol
from drivers.registers import RegisterMap
from drivers.sim.controller import SimController
from drivers.sim.faults import Faults, IndicatorFaults
from drivers.sim.indicators import SimIndicator
from drivers.sim.machine import VirtualOrthoglide
from drivers.sim.motion import DriveMotion
from drivers.sim.strokes import OutOfStroke, StrokeWatch
from orthocal import Geometry, plane_at

STANDARD_STROKE_MM = 12.5  # station.config's default stroke_mm (preload: half)

# Fast but physical: moves still take time, so in-position waits are real.
SIM_SPEED_MM_S = 1000.0
SIM_ACCEL_MM_S2 = 20000.0
# How far off the leg's middle an operator sets a stand by eye (docs/model.md: 5-10 mm);
# the command line's default, so that a default simulated run shows the closed loop.
DEFAULT_MOUNT_ERROR_MM = 5.0

TWO_SETUPS: list[dict[str, Any]] = [
    {"leg": "x", "indicators": {"A": "y", "B": "z"}},
    {"leg": "y", "indicators": {"A": "x", "B": "z"}},
    {"leg": "z", "indicators": {"A": "x", "B": "y"}},
]
SIX_SETUPS: list[dict[str, Any]] = [
    {"leg": "x", "indicators": {"A": "y", "B": "z"}},
    {"leg": "y", "indicators": {"C": "x", "D": "-z"}},
    {"leg": "z", "indicators": {"E": "x", "F": "y"}},
]


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


def _per_gauge(values: float | Sequence[float] | Mapping[str, float],
               names: list[str]) -> dict[str, float]:
    """One value per gauge of ``names`` from one for all, one per name in order, or
    a mapping by name (those it leaves out: 0)."""
    if isinstance(values, Mapping):
        unknown = sorted(set(values) - set(names))
        if unknown:
            raise ValueError(f"no gauge {', '.join(unknown)} (have {', '.join(names)})")
        return {n: float(values.get(n, 0.0)) for n in names}
    if isinstance(values, (int, float)):
        return {n: float(values) for n in names}
    listed = [float(v) for v in values]
    if len(listed) == 1:
        listed *= len(names)
    if len(listed) != len(names):
        raise ValueError(f"expected one value or {len(names)} (one per gauge, "
                         f"{', '.join(names)}), got {len(listed)}")
    return dict(zip(names, listed, strict=True))


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
    """The virtual station (module docstring). ``motion``: the drive's
    (:class:`~drivers.sim.motion.DriveMotion` or its name); ``accel_mm_s2`` what
    the config tells the station, ``drive_accel_mm_s2`` what the drive does if it
    differs; ``clock``: the machine's clock (a stepped one in tests that follow a
    move instant by instant); ``time_scale``: how many times faster than real time
    the machine's clock runs (unless ``clock`` is given) and how many times shorter
    the gauges' line time is (module docstring, "Time"; None: the environment's,
    :func:`default_time_scale`); ``register_map``: what the drive serves (None: the
    generic map) and ``profile`` the name ``config()`` gives it (None: the map's)."""

    def __init__(
        self,
        true_drho: Sequence[float] = (0.0, 0.0, 0.0),
        true_dl: Sequence[float] = (0.0, 0.0, 0.0),
        noise_mm: float = 0.002,
        seed: int | None = 0,
        *,
        true_tilt: Sequence[float] = (0.0, 0.0, 0.0),
        true_gap: Sequence[float] = (0.0, 0.0, 0.0),
        geometry: Geometry | None = None,
        speed_mm_s: float = SIM_SPEED_MM_S,
        accel_mm_s2: float = SIM_ACCEL_MM_S2,
        protocol: str = "mitutoyo",
        baud: int | None = None,
        line_time: bool = True,
        indicator_count: int = 2,
        port: int = 0,
        controller_faults: Faults | None = None,
        indicator_faults: dict[str, IndicatorFaults] | None = None,
        nvram_path: str | Path | None = None,
        mount_all: bool = False,
        mount_error_mm: float = 0.0,
        mount_errors: dict[str, float] | None = None,
        motion: str | DriveMotion = "coordinated",
        strokes: dict[str, tuple[float, float]] | None = None,
        controller_options: dict[str, Any] | None = None,
        drive_accel_mm_s2: float | None = None,
        clock: Callable[[], float] | None = None,
        time_scale: float | None = None,
        backlash: Sequence[float] = (0.0, 0.0, 0.0),
        register_map: RegisterMap | None = None,
        profile: str | None = None,
        leg_bow: Sequence[float] = (0.0, 0.0, 0.0),
        gauge_scale: float | Sequence[float] | Mapping[str, float] = 0.0,
    ) -> None:
        if indicator_count not in (2, 6):
            raise ValueError("indicator_count must be 2 (moved leg to leg) or 6 (two per leg)")
        self.geometry = geometry or Geometry()
        scale = default_time_scale() if time_scale is None else float(time_scale)
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"time_scale must be finite and > 0, got {time_scale}")
        self.time_scale = scale
        self.protocol = protocol
        self.speed_mm_s = speed_mm_s
        self.accel_mm_s2 = accel_mm_s2
        self.setups = TWO_SETUPS if indicator_count == 2 else SIX_SETUPS
        if not (np.isfinite(mount_error_mm) and mount_error_mm >= 0):
            raise ValueError(f"mount_error_mm must be >= 0, got {mount_error_mm}")
        self.mount_error_mm = float(mount_error_mm)
        self._fixed_mounts = dict(mount_errors or {})
        self._seed = seed
        self._placement: str | None = None  # the operator's "phase:setup", see place()
        self._stand_error = 0.0  # of the mounting in progress, for source()
        #: Every mounting: (indicator, leg, direction, mount error in mm), in order.
        self.mount_log: list[tuple[str, str, str, float]] = []
        if drive_accel_mm_s2 is not None and not (
                math.isfinite(drive_accel_mm_s2) and drive_accel_mm_s2 > 0):
            raise ValueError(f"drive_accel_mm_s2 must be > 0, got {drive_accel_mm_s2}")
        # The drive's own acceleration where it differs from what config() tells
        # the station (accel_mm_s2).
        self.machine = _PersistentMachine(
            self.geometry, true_drho, true_dl, true_tilt=true_tilt, true_gap=true_gap,
            speed_mm_s=speed_mm_s,
            accel_mm_s2=accel_mm_s2 if drive_accel_mm_s2 is None else drive_accel_mm_s2,
            motion=motion, clock=clock, time_scale=1.0 if clock is not None else scale,
            backlash=backlash, leg_bow=leg_bow)
        # Out-of-stroke accounting and knocks (drivers.sim.strokes).
        self._watch = StrokeWatch(self.machine, self.geometry, self._mounted_gauges)
        if nvram_path is not None:
            path = Path(nvram_path)
            if path.exists():
                self.machine.load(json.loads(path.read_text()))
            self.machine.nvram_path = path
        self.mounts_path: Path | None = None
        self._mounts: dict[str, dict[str, Any]] = {}
        names = sorted({n for s in self.setups for n in s["indicators"]})
        #: Each gauge's relative scale error (name -> S).
        self.gauge_scale = _per_gauge(gauge_scale, names)
        # (stroke, preload) per gauge: standard 12.5 mm gauges pushed in by half unless
        # given (the config's defaults).
        self.strokes = {n: (STANDARD_STROKE_MM, STANDARD_STROKE_MM / 2) for n in names}
        self.strokes.update(strokes or {})
        # Stable paths, as /dev/serial/by-id/... gives a real USB adapter: a gauge
        # unplugged and plugged back (SimIndicator.unplug_for) keeps its port.
        self._link_dir = Path(tempfile.mkdtemp(prefix="orthocal-serial-by-id-"))
        # controller_options: further SimController keywords (transport,
        # soft_limit_registers, ...) for a station that differs from the default drive.
        options = dict(controller_options or {})
        if register_map is not None:
            options["register_map"] = register_map
        #: the profile name config() gives the station (None: the map's name)
        self.profile = profile
        self.controller = SimController(self.machine, port=port, faults=controller_faults,
                                        seed=seed, **options)
        self.indicators: dict[str, SimIndicator] = {}
        try:
            self.controller.start()
            for i, name in enumerate(names):
                faults = (indicator_faults or {}).get(name)
                line_baud = baud if baud is not None else make_protocol(protocol).baudrate
                sim = SimIndicator(protocol, lambda: 0.0, noise_mm=noise_mm,
                                   baud=line_baud if line_time else None, faults=faults,
                                   seed=None if seed is None else seed * 101 + i, name=name,
                                   stroke_mm=self.strokes[name][0],
                                   preload_mm=self.strokes[name][1],
                                   link=self._link_dir / f"usb-orthocal-sim-gauge-{name}-if00",
                                   time_scale=scale, scale_error=self.gauge_scale[name])
                sim.unmount()
                self.indicators[name] = sim
                sim.start()
            if nvram_path is not None:
                self._restore_mounts(Path(nvram_path).with_name(MOUNTS_NAME))
            if mount_all:
                # A separate process cannot be told where the operator mounted
                # the gauges: all six stay where their setups put them.
                for setup in self.setups:
                    for name, direction in setup["indicators"].items():
                        self.mount(name, setup["leg"], direction)
        except BaseException:
            self.close()
            raise

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
        """Name the placement of the next mountings (the operator's "phase:setup"):
        their stand errors become a function of the seed and the placement, so a
        simulated run resumed after a kill places a stand exactly where the
        uninterrupted run would have. None: a fresh draw at every mounting."""
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

    def config(self) -> dict[str, Any]:
        """What this station's hardware is, in station.toml's shape: the machine's
        geometry, the controller's link and limits, the gauges' ports, protocol and
        strokes, and where they are mounted (its setups). The procedure and the
        write-back are the station's to choose (station.commands.simulation)."""
        g = self.geometry
        ctl = self.controller
        # A map without soft-limit registers: the config tells the station the limits
        # the drive enforces, so that it can plan.
        limits = {} if ctl.map.has_role("SOFT_MIN") else {
            "soft_min": [float(v) for v in ctl.soft_min],
            "soft_max": [float(v) for v in ctl.soft_max]}
        return {
            "machine": {"leg_length": g.leg_length, "rho_min": g.rho_min, "rho_max": g.rho_max},
            # TCP: host and port; RTU: the pty the client opens and its baud rate.
            "controller": {**ctl.client_kwargs(), "profile": self.profile or ctl.map.name,
                           "device_id": ctl.device_id, **limits, "timeout_s": 1.0,
                           "speed_mm_s": self.speed_mm_s, "accel_mm_s2": self.accel_mm_s2,
                           # What an integrator would write: that the drive interpolates,
                           # if it does; else nothing (the profile's default: any timing).
                           # Never the drive's shape, delays or own acceleration.
                           **({"motion": "coordinated"} if self.machine.drive.coordinated
                              else {})},
            "indicators": [{"name": n, "port": s.port, "protocol": self.protocol,
                            "stroke_mm": self.strokes[n][0], "preload_mm": self.strokes[n][1]}
                           for n, s in self.indicators.items()],
            "setups": [dict(s) for s in self.setups],
        }

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
        shutil.rmtree(self._link_dir, ignore_errors=True)

    def __enter__(self) -> VirtualStation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
