"""A virtual Orthoglide: three linear axes that take time to move, with hidden
geometric errors (docs/design.md, "Writing the offsets back"; docs/model.md, "Machine and
parameters").

Frames. The carriage of axis i sits at ``m_i`` on the machine's own scale. The
controller counts ``ρ_i = m_i − o_i`` (``o`` = its zero offsets, the OFFSET
registers), so a commanded ρ_i puts the carriage at ρ_i + o_i. The kinematic
joint value of model (1) is

    q_i = m_i − o_initial_i + Δρ_true_i = ρ_i + (o_i − o_initial_i) + Δρ_true_i ,

i.e. with the offsets the machine was delivered with, commanding ρ gives
q = ρ + Δρ_true; after the station writes o_i ← o_i − Δρ̂_i the machine behaves
nominally. Leg lengths are L + ΔL_true. All kinematics come from :mod:`orthocal`.

Counting: a drive counts its position from the reference homing found. A
power cut (:meth:`VirtualOrthoglide.power_cycle`) stops the carriages where they
are and loses that reference: HOMED clears, the count restarts from a value
unrelated to the carriage (``count_shift``), and moves are refused with
:data:`ALARM_NOT_HOMED` until :meth:`home` re-establishes it (``home_error_mm``:
how far the new reference lies from the old one, 0 for a repeatable switch).

Motion: the drive's (``motion``, a :class:`~drivers.sim.drive_motion.DriveMotion`
or its two names), run from :mod:`drivers.sim.drive_motion`; everything the
carriages do is handed to ``segment_listeners`` as
:class:`~drivers.sim.drive_motion.Segment` pieces as it ends.

Lost motion (``backlash``, mm per joint: ISO 230-2's reversal value B): the
drive counts its motor; the carriage follows it through a dead band of width
B, a play operator (docs/model.md, "Lost motion"): after a move up it sits B/2 below
where the count puts the band's middle, after a move down B/2 above. Within a
move each axis is monotone, so the carriage is clamp(c_start, m − B/2, m + B/2).
The controller reports the count; the legs, the gauges and the end point see
the carriage. Screws (``joint_lead`` µm/m per joint, ``joint_pitch`` (amplitude
µm, period mm), :mod:`drivers.sim.screws`): the band follows the nut, the motor
plus each joint's positioning error counted from home (homed at Π0 by default).

Bowed legs (``leg_bow``, mm per leg: the sagitta h of each leg's surface at its
middle, :mod:`drivers.sim.bowed_legs`; ``plane_bow``, mm per gauge plane, each plane's
own sagitta added to its leg's): a gauge's coordinate gets 4·h·t·(1 − t), t
being where along the leg its plane touches it; the end point does not move
(the bow is the leg's form, not its length).

State is evaluated lazily from a clock, so the machine needs no thread of its
own; every public method is thread-safe. The clock may run faster than real time
(``time_scale``, :func:`scaled_clock`): a move then takes its duration in clock
seconds and that divided by the scale in real ones, and nothing else changes —
what the test of a whole calibration waits for, where real time proves nothing.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

import orthocal
from drivers.base import Vec3
from drivers.sim.drive_motion import (
    EPS,
    DriveMotion,
    Motion,
    Profile1D,
    Segment,
    make_profile,
    start_offsets,
)
from drivers.sim.legs import GaugeView
from drivers.sim.screws import Screws
from orthocal import Geometry

#: Alarm raised by a move commanded before homing (IAI drives do the same).
ALARM_NOT_HOMED = 83


def scaled_clock(scale: float) -> Callable[[], float]:
    """time.monotonic(), from now on running ``scale`` times faster (1: itself)."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"time scale must be finite and > 0, got {scale}")
    if scale == 1.0:
        return time.monotonic
    t0 = time.monotonic()
    return lambda: t0 + (time.monotonic() - t0) * scale


@dataclass(frozen=True)
class MachineStatus:
    homed: bool
    moving: bool
    in_position: bool
    alarm: bool
    estop: bool
    alarm_code: int


class VirtualOrthoglide(GaugeView):
    """The machine behind the simulated controller.

    ``true_drho``/``true_dl``: hidden joint offsets Δρ and leg-length errors ΔL
    (mm, 3-vectors); ``true_tilt``: hidden actuator axis tilts (tilt_yx, tilt_zx,
    tilt_zy, mrad; docs/model.md "Extended model"); ``true_gap``: how far the axes pass
    each other (gap_xy, gap_xz, gap_yz, mm; docs/model.md "Axes that do not meet"); or
    pass ``true_params`` as the 6-, 9- or 12-vector of :data:`orthocal.PARAM_NAMES`;
    ``leg_bow``, ``plane_bow``: its legs' hidden bows (mm), ``joint_lead``, ``joint_pitch``: its
    screws' errors (module docstring). ``offsets``: the controller's zero offsets at
    delivery (o_initial). ``start``: initial controller positions ρ (default Π0).
    ``motion``: a :class:`DriveMotion`, or "coordinated" / "independent"
    (:meth:`DriveMotion.named`); ``accel_mm_s2`` is the acceleration of every axis
    the drive motion gives none for. ``clock``: the machine's time (a stepped one
    in tests that follow a move instant by instant); without one, real time
    running ``time_scale`` times faster (:func:`scaled_clock`). ``time_scale``
    stays readable: who turns the machine's durations into real waits (the
    simulated controller's faults "halfway through a move") divides by it.

    ``segment_listeners`` are called with each :class:`Segment` as it ends and
    ``move_listeners`` with (move number, start time, duration) as a move starts,
    both under the machine's lock: they must be quick and must not call back into
    the machine.
    """

    def __init__(
        self,
        geometry: Geometry | None = None,
        true_drho: Vec3 | None = None,
        true_dl: Vec3 | None = None,
        *,
        true_params: Sequence[float] | None = None,
        true_tilt: Vec3 | None = None,
        true_gap: Vec3 | None = None,
        offsets: Sequence[float] = (0.0, 0.0, 0.0),
        speed_mm_s: float = 50.0,
        accel_mm_s2: float = 500.0,
        start: Sequence[float] | None = None,
        home_position: Sequence[float] | None = None,
        homed: bool = True,
        in_position_band_mm: float = 0.001,
        clock: Callable[[], float] | None = None,
        motion: str | DriveMotion = "coordinated",
        time_scale: float = 1.0,
        backlash: Sequence[float] | None = None,
        leg_bow: Sequence[float] | None = None,
        plane_bow: Sequence[float] | None = None,
        joint_lead: Sequence[float] | None = None,
        joint_pitch: Sequence[float] | None = None,
    ) -> None:
        self.geometry = geometry or Geometry()
        if true_params is not None:
            if any(v is not None for v in (true_drho, true_dl, true_tilt, true_gap)):
                raise ValueError("give true_params or true_drho/true_dl/true_tilt/true_gap, "
                                 "not both")
            p = orthocal.geometry.full_params(np.asarray(true_params, dtype=float))
            true_drho, true_dl, true_tilt, true_gap = p[:3], p[3:6], p[6:9], p[9:]
        self.true_drho = _vec(true_drho if true_drho is not None else (0, 0, 0), 3, "true_drho")
        self.true_dl = _vec(true_dl if true_dl is not None else (0, 0, 0), 3, "true_dl")
        self.true_tilt = _vec(true_tilt if true_tilt is not None else (0, 0, 0), 3, "true_tilt")
        self.true_gap = _vec(true_gap if true_gap is not None else (0, 0, 0), 3, "true_gap")
        self.offsets_initial = _vec(offsets, 3, "offsets")
        if speed_mm_s <= 0 or accel_mm_s2 <= 0:
            raise ValueError("speed and acceleration must be > 0")
        self.accel_mm_s2 = float(accel_mm_s2)
        self.drive = motion if isinstance(motion, DriveMotion) else DriveMotion.named(motion)
        self._speed = float(speed_mm_s)
        self._band = float(in_position_band_mm)
        if not (math.isfinite(time_scale) and time_scale > 0):
            raise ValueError(f"time_scale must be finite and > 0, got {time_scale}")
        #: Clock seconds per real second (1 for a custom ``clock``, unless told).
        self.time_scale = float(time_scale)
        self._clock = clock if clock is not None else scaled_clock(self.time_scale)
        self._lock = threading.RLock()
        pi0 = orthocal.posture("0", None, self.geometry)
        rho0 = _vec(start, 3, "start") if start is not None else pi0
        home_rho = _vec(home_position, 3, "home_position") if home_position is not None else pi0
        self._o = self.offsets_initial.copy()
        self._rest = rho0 + self._o  # machine-scale motor positions at rest (the count)
        b = _vec(backlash if backlash is not None else (0, 0, 0), 3, "backlash")
        if np.any(b < 0):
            raise ValueError(f"backlash must be >= 0 mm, got {backlash!r}")
        #: Each joint's lost motion B (mm): the carriage lags the motor by up to B/2.
        self.backlash = b
        self._half_band = 0.5 * b
        #: Each leg's bow: the sagitta of its surface at its middle (mm, x, y, z).
        self.leg_bow = _vec(leg_bow if leg_bow is not None else (0, 0, 0), 3, "leg_bow")
        #: Each gauge plane's own bow on top (mm; orthocal.stands.GAUGES: xy, xz, … zy).
        self.plane_bow = _vec(plane_bow if plane_bow is not None else (0,) * 6, 6, "plane_bow")
        self._home_m = home_rho + self.offsets_initial  # the home switches do not move
        #: Each joint's screw: where its nut is for its motor's count from home.
        self.screws = Screws.of(joint_lead, joint_pitch, self._home_m)
        self._carriage_rest = self.screws.nut(self._rest.copy())  # the carriages at rest
        self._target_m = self._rest.copy()
        self._motion: Motion | None = None
        self._homed = bool(homed)
        self._alarm = 0
        self._estop = False
        self._pending_alarm: tuple[float, int] | None = None
        self.moves_started = 0
        #: False from a motion's start until the controller has shown the station a
        #: status with it over (drivers.sim.drive): what the station reads meanwhile
        #: it reads with the axes moving as far as it knows, as often as its polls fit
        #: into the motion (SimIndicator.at_rest).
        self.rest_reported = True
        self.segment_listeners: list[Callable[[Segment], None]] = []
        self.move_listeners: list[Callable[[int, float, float], None]] = []
        # the segment in progress: (index, kind, start of this piece, move number)
        self._segment: tuple[int, str, float, int | None] | None = None
        self._segments = 0
        # controller count = m − o − count_shift; 0 while the homing reference holds
        self.count_shift = np.zeros(3)
        #: where the next homing puts the reference relative to the first (mm, 3)
        self.home_error_mm = np.zeros(3)

    # --- evaluation -------------------------------------------------------------------------

    def _advance(self, now: float) -> np.ndarray:
        """Bring the lazy state up to ``now``; returns machine-scale positions."""
        if self._pending_alarm is not None and now >= self._pending_alarm[0]:
            t_alarm, code = self._pending_alarm
            self._pending_alarm = None
            self._freeze(t_alarm)
            self._alarm = code
        if self._motion is None:
            return self._rest.copy()
        pos, done = self._motion.position(now)
        if done:
            self._close_segment(self._motion.t0 + self._motion.duration)
            if self._motion.homing:
                self._set_homed()
            self._carriage_rest = self._play(pos)
            self._rest = pos
            self._motion = None
        return pos

    def _play(self, motor: np.ndarray) -> np.ndarray:
        """Where the carriages are with the motors at ``motor`` (machine scale, (3,)
        or (n, 3) within the motion in progress): through each joint's dead band
        from where they stood as the motion began (at rest: where they stand)."""
        c0 = self._carriage_rest if self._motion is None or self._motion.carriage0 is None \
            else self._motion.carriage0
        nut = self.screws.nut(motor)
        return np.clip(c0, nut - self._half_band, nut + self._half_band)

    def _carriage(self, now: float) -> np.ndarray:
        """Machine-scale carriage positions at ``now``."""
        return self._play(self._advance(now))

    def _freeze(self, t: float) -> None:
        if self._motion is not None:
            pos, done = self._motion.position(t)
            self._close_segment(min(t, self._motion.t0 + self._motion.duration))
            if done and self._motion.homing:
                self._set_homed()
            self._carriage_rest = self._play(pos)
            self._rest = pos
            self._motion = None

    # --- segments ---------------------------------------------------------------------------

    def _open_segment(self, kind: str, now: float, move: int | None) -> None:
        self._segment = (self._segments, kind, now, move)
        self._segments += 1

    def _close_segment(self, t: float, keep: bool = False) -> None:
        """Hand the piece of the segment in progress up to ``t`` to the listeners;
        ``keep``: the segment goes on (a new piece of it starts at ``t``)."""
        if self._segment is None or self._motion is None:
            self._segment = None
            return
        index, kind, t_from, move = self._segment
        piece = Segment(index, kind, self._motion, t_from, max(t, t_from), move)
        self._segment = (index, kind, max(t, t_from), move) if keep else None
        for listener in self.segment_listeners:
            listener(piece)

    def flush_segment(self) -> None:
        """Hand the listeners what the segment in progress did up to now (the rest
        follows as further pieces of the same segment): for who must account for
        the trajectory so far, e.g. before a gauge is mounted or taken off."""
        with self._lock:
            now = self._clock()
            self._advance(now)
            if self._motion is not None:
                self._close_segment(now, keep=True)

    def now(self) -> float:
        """The machine's clock."""
        return self._clock()

    def _accels(self) -> tuple[float, float, float]:
        return self.drive.accels(self.accel_mm_s2)

    def _set_homed(self) -> None:
        self._homed = True
        self.count_shift = np.asarray(self.home_error_mm, dtype=float).copy()

    def _start(self, target_m: np.ndarray, now: float, homing: bool = False,
               move: int | None = None) -> float:
        start = self._advance(now)
        carriage = self._play(start)  # where the carriages are as this motion begins
        self._close_segment(now)  # a move in progress is replaced
        delta = target_m - start
        dist = float(np.max(np.abs(delta)))
        self._target_m = target_m.copy()
        if dist <= EPS:
            nut = self.screws.nut(target_m)
            self._carriage_rest = np.clip(carriage, nut - self._half_band,
                                          nut + self._half_band)
            self._rest = target_m.copy()
            self._motion = None
            if homing:
                self._set_homed()
            return 0.0
        drive, accels = self.drive, self._accels()
        offsets = (0.0, 0.0, 0.0)
        if drive.coordinated:
            # One profile for the line, the longest axis ±1: no axis beyond its own
            # acceleration (all equal here, see DriveMotion).
            shared = make_profile(drive.shapes[0], dist, self._speed, min(accels),
                              drive.jerk_time_s)
            profiles: list[Profile1D] = [shared] * 3
            scale = delta / dist
        else:
            profiles = [make_profile(sh, abs(float(d)), self._speed, a, drive.jerk_time_s)
                        for sh, d, a in zip(drive.shapes, delta, accels, strict=True)]
            scale = np.where(delta < 0, -1.0, 1.0)
            offsets = start_offsets(drive, profiles)
        self._motion = Motion(now, start, scale, profiles, target_m.copy(), homing, offsets,
                              carriage0=carriage)
        self.rest_reported = False
        self._open_segment("home" if homing else "move", now, move)
        return self._motion.duration

    # --- what the controller sees ---------------------------------------------------------

    @property
    def motion(self) -> str:
        """"coordinated" or "independent" (a drive that does not interpolate)."""
        return self.drive.name

    @property
    def speed_mm_s(self) -> float:
        with self._lock:
            return self._speed

    @speed_mm_s.setter
    def speed_mm_s(self, value: float) -> None:
        if not value > 0:
            raise ValueError(f"speed must be > 0, got {value}")
        with self._lock:
            self._speed = float(value)

    @property
    def offsets(self) -> np.ndarray:
        """The controller's zero offsets o (mm)."""
        with self._lock:
            return self._o.copy()

    def set_offsets(self, offsets: Vec3) -> None:
        """Change o. The carriage stays where it is; the controller's count ρ = m − o
        changes, as on a real drive."""
        o = _vec(offsets, 3, "offsets")
        with self._lock:
            self._advance(self._clock())
            self._o = o

    def actual(self) -> np.ndarray:
        """Joint positions ρ as the controller counts them (mm)."""
        with self._lock:
            return self._advance(self._clock()) - self._o - self.count_shift

    def targets(self) -> np.ndarray:
        """The last commanded targets ρ (controller counts, mm)."""
        with self._lock:
            return self._target_m - self._o - self.count_shift

    def status(self) -> MachineStatus:
        with self._lock:
            pos = self._advance(self._clock())
            moving = self._motion is not None
            in_pos = (not moving and not self._alarm and not self._estop
                      and bool(np.all(np.abs(pos - self._target_m) <= self._band + EPS)))
            return MachineStatus(self._homed, moving, in_pos, self._alarm != 0,
                                 self._estop, self._alarm)

    def move_to(self, targets: Vec3) -> float:
        """Start a move of all axes to controller targets ρ; returns its duration (s).

        Ignored (returns 0) in alarm or e-stop, like a drive that is not enabled; a
        move before homing raises :data:`ALARM_NOT_HOMED`. A move commanded while
        moving starts afresh from the current position (no velocity blending).
        """
        rho = _vec(targets, 3, "targets")
        with self._lock:
            now = self._clock()
            self._advance(now)
            if self._alarm or self._estop:
                return 0.0
            if not self._homed:
                self._alarm = ALARM_NOT_HOMED
                return 0.0
            self.moves_started += 1
            duration = self._start(rho + self._o + self.count_shift, now,
                                   move=self.moves_started)
            for listener in self.move_listeners:
                listener(self.moves_started, now, duration)
            return duration

    def power_cycle(self, count_mm: Vec3 | None = None,
                    seed: int | None = None) -> None:
        """Power lost and back: the carriages stop where they are, the alarm and any
        pending fault clear, HOMED clears and the count restarts at ``count_mm``
        (3 values; None: random within ±100 mm, as an encoder that powers up anywhere)."""
        with self._lock:
            now = self._clock()
            self._advance(now)
            self._freeze(now)
            self._target_m = self._rest.copy()
            self._pending_alarm = None
            self._alarm = 0
            self._homed = False
            if count_mm is None:
                count = np.random.default_rng(seed).uniform(-100.0, 100.0, 3)
            else:
                count = _vec(count_mm, 3, "count_mm")
            self.count_shift = self._rest - self._o - count

    def home(self) -> float:
        """Start homing: clears HOMED, moves to the home position, sets HOMED."""
        with self._lock:
            now = self._clock()
            self._advance(now)
            if self._alarm or self._estop:
                return 0.0
            self._homed = False
            return self._start(self._home_m.copy(), now, homing=True)

    def stop(self) -> None:
        """Each moving axis decelerates to rest at its acceleration; an axis that
        has not started (a start delay, a sequence) does not start."""
        with self._lock:
            now = self._clock()
            self._advance(now)
            if self._motion is None:
                return
            move = self._segment[3] if self._segment is not None else None
            self._close_segment(now)
            # An interrupted homing leaves the axis un-homed, as on a real drive.
            accels = self._accels()
            if self.drive.coordinated:
                accels = (min(accels),) * 3
            carriage = self._play(self._advance(now))
            self._motion = self._motion.braking(now, accels)
            self._motion.carriage0 = carriage
            self._open_segment("brake", now, move)

    def reset_alarm(self) -> bool:
        """Clear the alarm (not while the e-stop is engaged); True if cleared."""
        with self._lock:
            self._advance(self._clock())
            if self._estop:
                return False
            self._alarm = 0
            self._pending_alarm = None
            return True

    def raise_alarm(self, code: int, delay_s: float = 0.0) -> None:
        """Fault the drive with ``code`` now or ``delay_s`` from now: motion stops
        where it is at that moment (an instantaneous servo stop)."""
        if code <= 0:
            raise ValueError("alarm code must be > 0")
        with self._lock:
            now = self._clock()
            self._advance(now)
            if delay_s > 0:
                self._pending_alarm = (now + delay_s, int(code))
            else:
                self._freeze(now)
                self._alarm = int(code)

    def set_estop(self, engaged: bool) -> None:
        """Engage (motion stops at once) or release the emergency stop."""
        with self._lock:
            now = self._clock()
            self._advance(now)
            if engaged and not self._estop:
                self._freeze(now)
                self._pending_alarm = None
            self._estop = bool(engaged)


def _vec(values: Sequence[float] | np.ndarray, n: int, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be {n} finite numbers, got {values!r}")
    return arr.copy()
