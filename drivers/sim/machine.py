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

Motion (``motion``, a :class:`DriveMotion` or its two names): "coordinated", the
three axes move together along a straight line in joint space with one profile of
the longest axis (speed, acceleration), so they arrive together; or not, each
axis runs its own profile at the commanded speed, as drives that do not
interpolate do (IAI's among them): the short moves finish first. "independent"
is the plain case, trapezoids at the machine's acceleration all starting
together; a :class:`DriveMotion` varies what real drives vary and the station
is not told: the profile's shape (trapezoid, S-curve, cosine), the
acceleration, start delays per axis, one axis after another. Every profile is
rest-to-rest, monotone and within the commanded speed, so the path between two
stops stays in the joint-space box of its ends (what design.md "Register map"
promises the station, and no more).
State is evaluated lazily from a clock, so the machine needs no thread of its
own; every public method is thread-safe.

Segments. Everything the carriages do is a sequence of motion segments (a
move, a homing, the braking after a stop); each one, when it ends (finished,
replaced by a new command, braked, frozen by an alarm, e-stop or power cut),
is handed to ``segment_listeners`` as a :class:`Segment`, whose
:meth:`Segment.sample` gives its positions densely in time. The virtual
station counts the plunger excursions of the whole trajectory from them,
whether or not anybody read a gauge meanwhile.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

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


Shape = Literal["trapezoid", "scurve", "cosine"]
SHAPES: tuple[str, ...] = ("trapezoid", "scurve", "cosine")
#: S-curve default: the acceleration ramps up in this long (jerk = accel / this).
JERK_TIME_S = 0.05
#: Dense sampling of a segment (:meth:`Segment.sample`): at most this far apart in
#: time, and at least this many samples, whichever is denser. At the simulated
#: station's 1000 mm/s, 0.5 ms is 0.5 mm of joint travel, a few µm of plunger
#: travel between samples near an excursion's peak, where the plunger is slow.
SAMPLE_DT_S = 0.0005
SAMPLE_MIN = 400


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

    def s_many(self, tau: np.ndarray) -> np.ndarray:
        """s at many τ at once (dense sampling), phase by phase as :meth:`at`."""
        out = np.full(tau.shape, self.length)
        rem = np.array(tau, dtype=float)
        done = np.zeros(tau.shape, dtype=bool)
        for d, s0, v0, a in self.phases:
            here = ~done & (rem <= d)
            t = np.maximum(rem[here], 0.0)
            out[here] = s0 + v0 * t + 0.5 * a * t * t
            done |= here
            rem = rem - d
        return out


class _Jerk:
    """1-D rest-to-rest S-curve: phases of constant jerk (duration, s0, v0, a0, j),
    the seven of a jerk-limited profile (fewer when it cannot reach the speed or
    the acceleration). Positions are clamped to [0, distance], so rounding never
    takes an axis past its target."""

    def __init__(self, phases: list[tuple[float, float, float, float, float]],
                 length: float) -> None:
        self.phases = phases
        self.duration = sum(p[0] for p in phases)
        self.length = length

    @classmethod
    def scurve(cls, distance: float, v_max: float, accel: float, jerk: float) -> _Jerk:
        """Peak speed ≤ ``v_max``, |acceleration| ≤ ``accel``, |jerk| = ``jerk``."""
        if distance <= 0:
            return cls([], 0.0)
        a_lim = accel * accel / jerk  # the speed gained by one full jerk ramp up and down

        def ramp(v: float) -> tuple[float, float, float]:
            """(jerk time, constant-acceleration time, accel-phase length) to reach v."""
            if v >= a_lim:
                tj, ta = accel / jerk, v / accel - accel / jerk
            else:
                tj, ta = math.sqrt(v / jerk), 0.0
            return tj, ta, v * (2 * tj + ta) / 2  # mean speed v/2 by symmetry

        tj, ta, d_acc = ramp(v_max)
        v_peak, cruise = v_max, 0.0
        if 2 * d_acc <= distance:
            cruise = (distance - 2 * d_acc) / v_max
        else:  # no cruise: the speed whose two ramps cover the distance
            v_peak = (distance * distance * jerk / 4.0) ** (1.0 / 3.0)
            if v_peak >= a_lim:
                b = accel * accel / jerk
                v_peak = (-b + math.sqrt(b * b + 4 * accel * distance)) / 2
            v_peak = min(v_peak, v_max)
            tj, ta, _ = ramp(v_peak)
        plan = [(tj, jerk), (ta, 0.0), (tj, -jerk), (cruise, 0.0),
                (tj, -jerk), (ta, 0.0), (tj, jerk)]
        phases: list[tuple[float, float, float, float, float]] = []
        s = v = a = 0.0
        for d, j in plan:
            if d <= 0:
                continue
            phases.append((d, s, v, a, j))
            s, v, a = (s + v * d + a * d * d / 2 + j * d ** 3 / 6,
                       v + a * d + j * d * d / 2, a + j * d)
        return cls(phases, distance)

    def at(self, tau: float) -> tuple[float, float]:
        for d, s0, v0, a0, j in self.phases:
            if tau <= d:
                t = max(tau, 0.0)
                s = s0 + v0 * t + a0 * t * t / 2 + j * t ** 3 / 6
                return min(max(s, 0.0), self.length), max(v0 + a0 * t + j * t * t / 2, 0.0)
            tau -= d
        return self.length, 0.0

    def s_many(self, tau: np.ndarray) -> np.ndarray:
        out = np.full(tau.shape, self.length)
        rem = np.array(tau, dtype=float)
        done = np.zeros(tau.shape, dtype=bool)
        for d, s0, v0, a0, j in self.phases:
            here = ~done & (rem <= d)
            t = np.maximum(rem[here], 0.0)
            out[here] = s0 + v0 * t + a0 * t * t / 2 + j * t ** 3 / 6
            done |= here
            rem = rem - d
        return np.clip(out, 0.0, self.length)


class _Cosine:
    """1-D rest-to-rest s(τ) = d·(1 − cos(πτ/T))/2: peak acceleration d·π²/(2T²),
    peak speed d·π/(2T); T is the shortest that keeps both within the limits."""

    def __init__(self, distance: float, v_max: float, accel: float) -> None:
        self.length = max(distance, 0.0)
        if self.length <= 0:
            self.duration = 0.0
        else:
            self.duration = max(math.pi * math.sqrt(self.length / (2 * accel)),
                                math.pi * self.length / (2 * v_max))

    def at(self, tau: float) -> tuple[float, float]:
        if tau >= self.duration:
            return self.length, 0.0
        w = math.pi / self.duration
        t = max(tau, 0.0)
        return (min(self.length * (1 - math.cos(w * t)) / 2, self.length),
                max(self.length * w / 2 * math.sin(w * t), 0.0))

    def s_many(self, tau: np.ndarray) -> np.ndarray:
        if self.duration <= 0:
            return np.zeros(tau.shape)
        t = np.clip(tau, 0.0, self.duration)
        return np.clip(self.length * (1 - np.cos(math.pi / self.duration * t)) / 2,
                       0.0, self.length)


_Shape1D = _Profile | _Jerk | _Cosine


def _profile(shape: str, distance: float, v_max: float, accel: float,
             jerk_time_s: float) -> _Shape1D:
    if shape == "trapezoid":
        return _Profile.trapezoid(distance, v_max, accel)
    if shape == "scurve":
        return _Jerk.scurve(distance, v_max, accel, accel / jerk_time_s)
    return _Cosine(distance, v_max, accel)


def _brake(profile: _Shape1D, tau: float, accel: float) -> _Profile:
    """Constant deceleration at ``accel`` from where ``profile`` is at τ. Any
    rest-to-rest profile whose deceleration stays within ``accel`` has at least
    v²/(2·accel) left to its end, so the brake never passes the target; a
    rounding error that says otherwise brakes the little harder it takes."""
    if tau <= 0:
        return _Profile.braking(0.0, 0.0, accel)  # not started: it stays
    s, v = profile.at(tau)
    left = profile.length - s
    if v > 0 and v * v / (2 * accel) > left:
        accel = v * v / (2 * left) if left > 0 else math.inf
        if math.isinf(accel):
            return _Profile.braking(profile.length, 0.0, 1.0)
    return _Profile.braking(s, v, accel)


def _three(value: object, what: str) -> tuple[object, object, object]:
    if isinstance(value, str) or not isinstance(value, Sequence):
        return (value, value, value)
    if len(value) != 3:
        raise ValueError(f"{what} must be one value or three (x, y, z), got {value!r}")
    return (value[0], value[1], value[2])


@dataclass(frozen=True)
class DriveMotion:
    """How the simulated drive moves its axes on COMMAND 1 (and homing): what a
    real drive decides and the station is not told (design.md, "Register map").

    ``coordinated``: one shared profile along the straight line in joint space
    (then one shape, one acceleration, no delays, no sequence). Otherwise each
    axis its own profile of ``shape`` ("trapezoid", "scurve" — jerk-limited,
    the acceleration ramping up in ``jerk_time_s`` — or "cosine"; one for all
    or an (x, y, z) triple) at ``accel_mm_s2`` (mm/s²; None: the machine's
    ``accel_mm_s2``; one or a triple), starting ``start_delay_s`` after the
    command (s, ≥ 0, a triple), all together or, with ``sequence`` (an order
    such as "zyx"), one after another: the next axis starts its delay after the
    previous one has arrived. Shape and triples are stored as triples.
    """

    coordinated: bool = False
    shape: Shape | tuple[Shape, Shape, Shape] = "trapezoid"
    accel_mm_s2: float | tuple[float | None, float | None, float | None] | None = None
    start_delay_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sequence: str | None = None
    jerk_time_s: float = JERK_TIME_S

    def __post_init__(self) -> None:
        shapes = _three(self.shape, "shape")
        for sh in shapes:
            if sh not in SHAPES:
                raise ValueError(f"shape must be one of {', '.join(SHAPES)}, got {sh!r}")
        accels: list[float | None] = []
        for a in _three(self.accel_mm_s2, "accel_mm_s2"):
            if a is not None and not (isinstance(a, int | float) and math.isfinite(a) and a > 0):
                raise ValueError(f"accel_mm_s2 must be > 0 mm/s² (or None), got {a!r}")
            accels.append(None if a is None else float(a))
        delays: list[float] = []
        for d in _three(self.start_delay_s, "start_delay_s"):
            if not (isinstance(d, int | float) and math.isfinite(d) and d >= 0):
                raise ValueError(f"start_delay_s must be >= 0 s, got {self.start_delay_s!r}")
            delays.append(float(d))
        seq = self.sequence
        if seq is not None and (not isinstance(seq, str) or sorted(seq) != ["x", "y", "z"]):
            raise ValueError(f"sequence must order x, y and z once each (e.g. 'zyx'), "
                             f"got {seq!r}")
        if not (math.isfinite(self.jerk_time_s) and self.jerk_time_s > 0):
            raise ValueError(f"jerk_time_s must be > 0 s, got {self.jerk_time_s!r}")
        if self.coordinated and (len(set(shapes)) > 1 or len(set(accels)) > 1
                                 or any(delays) or seq is not None):
            raise ValueError("a coordinated drive has one shape and one acceleration, "
                             "no start delays and no sequence")
        # Frozen, so stored through object.__setattr__: always triples from here on.
        object.__setattr__(self, "shape", shapes)
        object.__setattr__(self, "accel_mm_s2", tuple(accels))
        object.__setattr__(self, "start_delay_s", tuple(delays))

    @classmethod
    def named(cls, name: str) -> DriveMotion:
        """The two plain drives: "coordinated" and "independent" (trapezoids at the
        machine's acceleration, all axes starting together)."""
        if name not in ("coordinated", "independent"):
            raise ValueError(f"motion must be 'coordinated' or 'independent', got {name!r}")
        return cls(coordinated=name == "coordinated")

    @property
    def name(self) -> str:
        """The station's word for it: "coordinated" or "independent" (any timing)."""
        return "coordinated" if self.coordinated else "independent"

    @property
    def shapes(self) -> tuple[str, str, str]:
        return self.shape  # type: ignore[return-value]  # a triple after __post_init__

    def accels(self, default: float) -> tuple[float, float, float]:
        """Per-axis acceleration, ``default`` where none is given."""
        given = _three(self.accel_mm_s2, "accel_mm_s2")
        x, y, z = (default if a is None else float(a) for a in given)  # type: ignore[arg-type]
        return (x, y, z)


@dataclass
class _Motion:
    """Axis i at start_i + scale_i·s_i(τ − offset_i), s_i from profiles[i].
    Coordinated: one shared profile, scale = the unit direction (longest axis ±1);
    otherwise each axis its own profile over its own distance, scale ±1, starting
    ``offsets[i]`` after ``t0`` (its start delay, or its turn in a sequence)."""

    t0: float
    start: np.ndarray
    scale: np.ndarray
    profiles: list[_Shape1D]
    end: np.ndarray
    homing: bool = False
    offsets: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def duration(self) -> float:
        return max(off + p.duration for off, p in zip(self.offsets, self.profiles, strict=True))

    def position(self, now: float) -> tuple[np.ndarray, bool]:
        """(position, finished) at ``now``."""
        tau = now - self.t0
        # t0 + duration - t0 can fall a rounding error short of duration.
        if tau >= self.duration - _EPS:
            return self.end.copy(), True
        s = np.array([p.at(tau - off)[0]
                      for off, p in zip(self.offsets, self.profiles, strict=True)])
        return self.start + self.scale * s, False

    def positions(self, times: np.ndarray) -> np.ndarray:
        """Positions (n, 3) at many instants (as :meth:`position`, vectorised)."""
        tau = np.asarray(times, dtype=float) - self.t0
        s = np.stack([p.s_many(tau - off)
                      for off, p in zip(self.offsets, self.profiles, strict=True)], axis=1)
        out = self.start + self.scale * s
        out[tau >= self.duration - _EPS] = self.end
        return out

    def braking(self, now: float, accels: Sequence[float]) -> _Motion:
        """Each axis decelerates at its acceleration from where it is at ``now`` to
        rest (coordinated axes share s and v, so they stay on their line); an axis
        that has not started stays where it is."""
        tau = now - self.t0
        brakes = [_brake(p, tau - off, a)
                  for off, p, a in zip(self.offsets, self.profiles, accels, strict=True)]
        end = self.start + self.scale * np.array([b.length for b in brakes])
        return _Motion(now, self.start, self.scale, list(brakes), end, homing=False)


@dataclass(frozen=True)
class Segment:
    """One piece of the machine's trajectory, from ``t_from`` to ``t_to`` (clock
    time): ``kind`` "move", "home" or "brake" (after a stop), ``index`` its
    number (pieces of one segment cut at a mounting share it), ``move`` the
    :attr:`VirtualOrthoglide.moves_started` count of the move it belongs to
    (the braked one for a brake; None for a homing)."""

    index: int
    kind: str
    motion: _Motion
    t_from: float
    t_to: float
    move: int | None = None

    def sample(self, max_dt_s: float = SAMPLE_DT_S, min_samples: int = SAMPLE_MIN,
               extra_times: Sequence[float] = ()) -> tuple[np.ndarray, np.ndarray]:
        """(times (n,), machine-scale carriage positions (n, 3)) densely over the
        piece: at most ``max_dt_s`` apart and at least ``min_samples`` (both ends
        included), plus ``extra_times`` that fall within it (a knocked stand)."""
        span = max(self.t_to - self.t_from, 0.0)
        n = max(min_samples, math.ceil(span / max_dt_s) + 1) if span > 0 else 1
        times = np.linspace(self.t_from, self.t_to, n)
        inside = [t for t in extra_times if self.t_from <= t <= self.t_to]
        if inside:
            times = np.sort(np.concatenate([times, inside]))
        return times, self.motion.positions(times)


class VirtualOrthoglide:
    """The machine behind the simulated controller.

    ``true_drho``/``true_dl``: hidden joint offsets Δρ and leg-length errors ΔL
    (mm, 3-vectors); ``true_tilt``: hidden actuator axis tilts (tilt_yx, tilt_zx,
    tilt_zy, mrad; model.md "Extended model"); or pass ``true_params`` as the 6- or
    9-vector of :data:`orthocal.PARAM_NAMES`. ``offsets``: the controller's zero offsets at
    delivery (o_initial). ``start``: initial controller positions ρ (default Π0).
    ``motion``: a :class:`DriveMotion`, or "coordinated" / "independent"
    (:meth:`DriveMotion.named`); ``accel_mm_s2`` is the acceleration of every axis
    the drive motion gives none for.

    ``segment_listeners`` are called with each :class:`Segment` as it ends and
    ``move_listeners`` with (move number, start time, duration) as a move starts,
    both under the machine's lock: they must be quick and must not call back into
    the machine.
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
        motion: str | DriveMotion = "coordinated",
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
        self.drive = motion if isinstance(motion, DriveMotion) else DriveMotion.named(motion)
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
            self._rest = pos
            self._motion = None
        return pos

    def _freeze(self, t: float) -> None:
        if self._motion is not None:
            pos, done = self._motion.position(t)
            self._close_segment(min(t, self._motion.t0 + self._motion.duration))
            if done and self._motion.homing:
                self._set_homed()
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

    def sample_segment(self, segment: Segment, max_dt_s: float = SAMPLE_DT_S,
                       min_samples: int = SAMPLE_MIN, extra_times: Sequence[float] = ()
                       ) -> tuple[np.ndarray, np.ndarray]:
        """(times, joint values (n, 3)) of ``segment`` sampled densely (as
        :meth:`Segment.sample`), the joints as :func:`orthocal.leg_reading` takes
        them with ``drho=self.true_drho`` (ρ from the delivered offsets, see "Frames")."""
        times, carriage = segment.sample(max_dt_s, min_samples, extra_times)
        return times, carriage - self.offsets_initial

    def _accels(self) -> tuple[float, float, float]:
        return self.drive.accels(self.accel_mm_s2)

    def _set_homed(self) -> None:
        self._homed = True
        self.count_shift = np.asarray(self.home_error_mm, dtype=float).copy()

    def _start(self, target_m: np.ndarray, now: float, homing: bool = False,
               move: int | None = None) -> float:
        start = self._advance(now)
        self._close_segment(now)  # a move in progress is replaced
        delta = target_m - start
        dist = float(np.max(np.abs(delta)))
        self._target_m = target_m.copy()
        if dist <= _EPS:
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
            shared = _profile(drive.shapes[0], dist, self._speed, min(accels),
                              drive.jerk_time_s)
            profiles: list[_Shape1D] = [shared] * 3
            scale = delta / dist
        else:
            profiles = [_profile(sh, abs(float(d)), self._speed, a, drive.jerk_time_s)
                        for sh, d, a in zip(drive.shapes, delta, accels, strict=True)]
            scale = np.where(delta < 0, -1.0, 1.0)
            offsets = _start_offsets(drive, profiles)
        self._motion = _Motion(now, start, scale, profiles, target_m.copy(), homing, offsets)
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
            duration = self._start(rho + self._o + self.count_shift, now,
                                   move=self.moves_started)
            for listener in self.move_listeners:
                listener(self.moves_started, now, duration)
            return duration

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
            self._motion = self._motion.braking(now, accels)
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


def _start_offsets(drive: DriveMotion, profiles: Sequence[_Shape1D]) -> tuple[float, float, float]:
    """When each axis starts after the command: its delay, and with a sequence
    its delay after the previous axis in the order has arrived."""
    delays = drive.start_delay_s
    if drive.sequence is None:
        return (delays[0], delays[1], delays[2])
    offsets = [0.0, 0.0, 0.0]
    t = 0.0
    for axis in drive.sequence:
        i = "xyz".index(axis)
        offsets[i] = t + delays[i]
        t = offsets[i] + profiles[i].duration
    return (offsets[0], offsets[1], offsets[2])


def _vec(values: Sequence[float] | np.ndarray, n: int, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be {n} finite numbers, got {values!r}")
    return arr.copy()
