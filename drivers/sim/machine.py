"""A virtual Orthoglide: three linear axes that take time to move, with hidden
geometric errors (design.md, "Writing the offsets back"; model.md, "Machine and
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

Motion (``motion``): "coordinated", the three axes move together along a
straight line in joint space with a trapezoidal profile of the longest axis
(speed, acceleration), so they arrive together; or "independent", each axis
runs its own trapezoid at the commanded speed and acceleration, as drives that
do not interpolate do (IAI's among them): the short moves finish first.
State is evaluated lazily from a clock, so the machine needs no thread of its
own; every public method is thread-safe.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

import orthocal
from orthocal import Geometry

#: Alarm raised by a move commanded before homing (IAI drives do the same).
ALARM_NOT_HOMED = 83
#: Band within which the drive reports IN_POSITION (one count of µm).
_EPS = 1e-9


@dataclass(frozen=True)
class MachineStatus:
    homed: bool
    moving: bool
    in_position: bool
    alarm: bool
    estop: bool
    alarm_code: int


class _Profile:
    """1-D path s(τ) as phases of constant acceleration: (duration, s0, v0, a)."""

    def __init__(self, phases: list[tuple[float, float, float, float]]) -> None:
        self.phases = phases
        self.duration = sum(p[0] for p in phases)
        if phases:
            d, s0, v0, a = phases[-1]
            self.length = s0 + v0 * d + 0.5 * a * d * d
        else:
            self.length = 0.0

    @classmethod
    def trapezoid(cls, distance: float, v_max: float, accel: float) -> _Profile:
        """Rest-to-rest over ``distance`` (a triangle when too short to cruise)."""
        if distance <= 0:
            return cls([])
        t_acc = v_max / accel
        d_acc = 0.5 * v_max * t_acc
        if 2 * d_acc >= distance:
            v_peak = math.sqrt(distance * accel)
            t = v_peak / accel
            return cls([(t, 0.0, 0.0, accel), (t, distance / 2, v_peak, -accel)])
        cruise = (distance - 2 * d_acc) / v_max
        return cls([(t_acc, 0.0, 0.0, accel), (cruise, d_acc, v_max, 0.0),
                    (t_acc, distance - d_acc, v_max, -accel)])

    @classmethod
    def braking(cls, s0: float, v0: float, accel: float) -> _Profile:
        """Decelerate from (s0, v0) to rest."""
        if v0 <= 0:
            return cls([(0.0, s0, 0.0, 0.0)])
        return cls([(v0 / accel, s0, v0, -accel)])

    def at(self, tau: float) -> tuple[float, float]:
        """(s, v) at time τ after the start; rest at the end after the last phase."""
        for d, s0, v0, a in self.phases:
            if tau <= d:
                t = max(tau, 0.0)
                return s0 + v0 * t + 0.5 * a * t * t, v0 + a * t
            tau -= d
        return self.length, 0.0


@dataclass
class _Motion:
    """Axis i at start_i + scale_i·s_i(τ), s_i from profiles[i]. Coordinated: one
    shared profile, scale = the unit direction (longest axis ±1); independent:
    each axis its own profile over its own distance, scale ±1."""

    t0: float
    start: np.ndarray
    scale: np.ndarray
    profiles: list[_Profile]
    end: np.ndarray
    homing: bool = False

    @property
    def duration(self) -> float:
        return max(p.duration for p in self.profiles)

    def position(self, now: float) -> tuple[np.ndarray, bool]:
        """(position, finished) at ``now``."""
        tau = now - self.t0
        # t0 + duration - t0 can fall a rounding error short of duration.
        if tau >= self.duration - _EPS:
            return self.end.copy(), True
        s = np.array([p.at(tau)[0] for p in self.profiles])
        return self.start + self.scale * s, False

    def braking(self, now: float, accel: float) -> _Motion:
        """Each axis decelerates from where it is at ``now`` to rest (coordinated
        axes share s and v, so they stay on their line)."""
        tau = now - self.t0
        brakes = [_Profile.braking(*p.at(tau), accel) for p in self.profiles]
        end = self.start + self.scale * np.array([b.length for b in brakes])
        return _Motion(now, self.start, self.scale, brakes, end, homing=False)


class VirtualOrthoglide:
    """The machine behind the simulated controller.

    ``true_drho``/``true_dl``: hidden joint offsets Δρ and leg-length errors ΔL
    (mm, 3-vectors); ``true_tilt``: hidden actuator axis tilts (tilt_yx, tilt_zx,
    tilt_zy, mrad; model.md "Extended model"); or pass ``true_params`` as the 6- or
    9-vector of :data:`orthocal.PARAM_NAMES`. ``offsets``: the controller's zero offsets at
    delivery (o_initial). ``start``: initial controller positions ρ (default Π0).
    """

    def __init__(
        self,
        geometry: Geometry | None = None,
        true_drho: Sequence[float] | None = None,
        true_dl: Sequence[float] | None = None,
        *,
        true_params: Sequence[float] | None = None,
        true_tilt: Sequence[float] | None = None,
        offsets: Sequence[float] = (0.0, 0.0, 0.0),
        speed_mm_s: float = 50.0,
        accel_mm_s2: float = 500.0,
        start: Sequence[float] | None = None,
        home_position: Sequence[float] | None = None,
        homed: bool = True,
        in_position_band_mm: float = 0.001,
        clock: Callable[[], float] = time.monotonic,
        motion: str = "coordinated",
    ) -> None:
        self.geometry = geometry or Geometry()
        if true_params is not None:
            if true_drho is not None or true_dl is not None or true_tilt is not None:
                raise ValueError("give true_params or true_drho/true_dl/true_tilt, not both")
            p = orthocal.geometry.full_params(np.asarray(true_params, dtype=float))
            true_drho, true_dl, true_tilt = p[:3], p[3:6], p[6:]
        self.true_drho = _vec(true_drho if true_drho is not None else (0, 0, 0), 3, "true_drho")
        self.true_dl = _vec(true_dl if true_dl is not None else (0, 0, 0), 3, "true_dl")
        self.true_tilt = _vec(true_tilt if true_tilt is not None else (0, 0, 0), 3, "true_tilt")
        self.offsets_initial = _vec(offsets, 3, "offsets")
        if speed_mm_s <= 0 or accel_mm_s2 <= 0:
            raise ValueError("speed and acceleration must be > 0")
        self.accel_mm_s2 = float(accel_mm_s2)
        if motion not in ("coordinated", "independent"):
            raise ValueError(f"motion must be 'coordinated' or 'independent', got {motion!r}")
        self.motion = motion
        self._speed = float(speed_mm_s)
        self._band = float(in_position_band_mm)
        self._clock = clock
        self._lock = threading.RLock()
        pi0 = orthocal.posture("0", None, self.geometry)
        rho0 = _vec(start, 3, "start") if start is not None else pi0
        home_rho = _vec(home_position, 3, "home_position") if home_position is not None else pi0
        self._o = self.offsets_initial.copy()
        self._rest = rho0 + self._o  # machine-scale carriage positions at rest
        self._target_m = self._rest.copy()
        self._home_m = home_rho + self.offsets_initial  # the home switches do not move
        self._motion: _Motion | None = None
        self._homed = bool(homed)
        self._alarm = 0
        self._estop = False
        self._pending_alarm: tuple[float, int] | None = None
        self.moves_started = 0
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
            if self._motion.homing:
                self._set_homed()
            self._rest = pos
            self._motion = None
        return pos

    def _freeze(self, t: float) -> None:
        if self._motion is not None:
            pos, done = self._motion.position(t)
            if done and self._motion.homing:
                self._set_homed()
            self._rest = pos
            self._motion = None

    def _set_homed(self) -> None:
        self._homed = True
        self.count_shift = np.asarray(self.home_error_mm, dtype=float).copy()

    def _start(self, target_m: np.ndarray, now: float, homing: bool = False) -> float:
        start = self._advance(now)
        delta = target_m - start
        dist = float(np.max(np.abs(delta)))
        self._target_m = target_m.copy()
        if dist <= _EPS:
            self._rest = target_m.copy()
            self._motion = None
            if homing:
                self._set_homed()
            return 0.0
        if self.motion == "coordinated":
            shared = _Profile.trapezoid(dist, self._speed, self.accel_mm_s2)
            profiles, scale = [shared] * 3, delta / dist
        else:
            profiles = [_Profile.trapezoid(abs(float(d)), self._speed, self.accel_mm_s2)
                        for d in delta]
            scale = np.where(delta < 0, -1.0, 1.0)
        self._motion = _Motion(now, start, scale, profiles, target_m.copy(), homing)
        return self._motion.duration

    # --- what the controller sees ---------------------------------------------------------

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

    def set_offsets(self, offsets: Sequence[float]) -> None:
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
                      and bool(np.all(np.abs(pos - self._target_m) <= self._band + _EPS)))
            return MachineStatus(self._homed, moving, in_pos, self._alarm != 0,
                                 self._estop, self._alarm)

    def move_to(self, targets: Sequence[float]) -> float:
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
            return self._start(rho + self._o + self.count_shift, now)

    def power_cycle(self, count_mm: Sequence[float] | None = None,
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
        """Decelerate to rest at the configured acceleration."""
        with self._lock:
            now = self._clock()
            self._advance(now)
            if self._motion is None:
                return
            # An interrupted homing leaves the axis un-homed, as on a real drive.
            self._motion = self._motion.braking(now, self.accel_mm_s2)

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

    # --- what the indicators see --------------------------------------------------------

    def joint_values(self) -> np.ndarray:
        """Kinematic joint values q (model (1)) at this instant."""
        with self._lock:
            return self._advance(self._clock()) - self.offsets_initial + self.true_drho

    def _rho_kin(self) -> np.ndarray:
        return self._advance(self._clock()) - self.offsets_initial

    def leg_reading(self, leg: str, direction: str, mount: float | None = None) -> float:
        """What a dial indicator on ``leg`` measuring along ``direction`` reads (mm):
        :func:`orthocal.leg_reading` at the instantaneous joint values, true ΔL, its
        stand in the plane x_leg = ``mount`` (default: the nominal L/2)."""
        with self._lock:
            rho = self._rho_kin()
        return float(orthocal.leg_reading(rho, leg, direction, self.geometry,
                                          self.true_drho, self.true_dl, mount=mount,
                                          tilt=self.true_tilt))

    def source(self, leg: str, direction: str,
               mount: float | None = None) -> Callable[[], float]:
        """A zero-argument callable for a simulated indicator's ``source``."""
        return lambda: self.leg_reading(leg, direction, mount)

    def end_point(self) -> np.ndarray:
        """The end point P (mm) at this instant."""
        with self._lock:
            rho = self._rho_kin()
        return orthocal.forward(rho, self.geometry, self.true_drho, self.true_dl, self.true_tilt)


def _vec(values: Sequence[float] | np.ndarray, n: int, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be {n} finite numbers, got {values!r}")
    return arr.copy()
