"""How the simulated drive moves its axes: the motion profiles (trapezoid,
S-curve, cosine, the braking after a stop), :class:`DriveMotion` (what a real
drive decides and the station is not told), :class:`Motion` (one move of the
three axes, evaluated at any instant) and :class:`Segment` (a finished piece of
the trajectory, sampled densely). The virtual machine (:mod:`drivers.sim.machine`)
runs them; the rest-to-rest trapezoid itself lives in :mod:`drivers.profiles`,
shared with the real driver's move deadlines.

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
stops stays in the joint-space box of its ends (what docs/design.md "Register map"
promises the station, and no more).

Segments. Everything the carriages do is a sequence of motion segments (a
move, a homing, the braking after a stop); each one, when it ends (finished,
replaced by a new command, braked, frozen by an alarm, e-stop or power cut),
is handed to the machine's ``segment_listeners`` as a :class:`Segment`, whose
:meth:`Segment.sample` gives its positions densely in time. The virtual
station counts the plunger excursions of the whole trajectory from them,
whether or not anybody read a gauge meanwhile.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from drivers.profiles import AccelProfile

#: Band within which the drive reports IN_POSITION (one count of µm).
EPS = 1e-9

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


Profile1D = AccelProfile | _Jerk | _Cosine


def make_profile(shape: str, distance: float, v_max: float, accel: float,
                 jerk_time_s: float) -> Profile1D:
    """The 1-D profile of one axis (or of a coordinated line) for ``shape``."""
    if shape == "trapezoid":
        return AccelProfile.trapezoid(distance, v_max, accel)
    if shape == "scurve":
        return _Jerk.scurve(distance, v_max, accel, accel / jerk_time_s)
    return _Cosine(distance, v_max, accel)


def _brake(profile: Profile1D, tau: float, accel: float) -> AccelProfile:
    """Constant deceleration at ``accel`` from where ``profile`` is at τ. Any
    rest-to-rest profile whose deceleration stays within ``accel`` has at least
    v²/(2·accel) left to its end, so the brake never passes the target; a
    rounding error that says otherwise brakes the little harder it takes. At τ = 0
    the profile is where it starts (a brake braked again at once: where it brakes
    from, not the start of the move it braked)."""
    if tau < 0:
        return AccelProfile.braking(0.0, 0.0, accel)  # not started: it stays
    s, v = profile.at(tau)
    left = profile.length - s
    if v > 0 and v * v / (2 * accel) > left:
        accel = v * v / (2 * left) if left > 0 else math.inf
        if math.isinf(accel):
            return AccelProfile.braking(profile.length, 0.0, 1.0)
    return AccelProfile.braking(s, v, accel)


def _three(value: object, what: str) -> tuple[object, object, object]:
    if isinstance(value, str) or not isinstance(value, Sequence):
        return (value, value, value)
    if len(value) != 3:
        raise ValueError(f"{what} must be one value or three (x, y, z), got {value!r}")
    return (value[0], value[1], value[2])


@dataclass(frozen=True)
class DriveMotion:
    """How the simulated drive moves its axes on COMMAND 1 (and homing): what a
    real drive decides and the station is not told (docs/design.md, "Register map").

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
        # _three types its items object; here each is the field's float | None
        x, y, z = (default if a is None else float(a) for a in given)  # type: ignore[arg-type]
        return (x, y, z)


@dataclass
class Motion:
    """Axis i at start_i + scale_i·s_i(τ − offset_i), s_i from profiles[i].
    Coordinated: one shared profile, scale = the unit direction (longest axis ±1);
    otherwise each axis its own profile over its own distance, scale ±1, starting
    ``offsets[i]`` after ``t0`` (its start delay, or its turn in a sequence)."""

    t0: float
    start: np.ndarray
    scale: np.ndarray
    profiles: list[Profile1D]
    end: np.ndarray
    homing: bool = False
    offsets: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: Where the carriages (the load, behind a joint's lost motion) were as the
    #: motion began; each axis is monotone within a motion, so they follow the
    #: motor through their dead band from there (VirtualOrthoglide's backlash).
    carriage0: np.ndarray | None = None

    @property
    def duration(self) -> float:
        return max(off + p.duration for off, p in zip(self.offsets, self.profiles, strict=True))

    def position(self, now: float) -> tuple[np.ndarray, bool]:
        """(position, finished) at ``now``."""
        tau = now - self.t0
        # t0 + duration - t0 can fall a rounding error short of duration.
        if tau >= self.duration - EPS:
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
        out[tau >= self.duration - EPS] = self.end
        return out

    def braking(self, now: float, accels: Sequence[float]) -> Motion:
        """Each axis decelerates at its acceleration from where it is at ``now`` to
        rest (coordinated axes share s and v, so they stay on their line); an axis
        that has not started stays where it is."""
        tau = now - self.t0
        brakes = [_brake(p, tau - off, a)
                  for off, p, a in zip(self.offsets, self.profiles, accels, strict=True)]
        end = self.start + self.scale * np.array([b.length for b in brakes])
        return Motion(now, self.start, self.scale, list(brakes), end, homing=False,
                      carriage0=self.carriage0)


@dataclass(frozen=True)
class Segment:
    """One piece of the machine's trajectory, from ``t_from`` to ``t_to`` (clock
    time): ``kind`` "move", "home" or "brake" (after a stop), ``index`` its
    number (pieces of one segment cut at a mounting share it), ``move`` the
    :attr:`VirtualOrthoglide.moves_started` count of the move it belongs to
    (the braked one for a brake; None for a homing)."""

    index: int
    kind: str
    motion: Motion
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


def start_offsets(drive: DriveMotion, profiles: Sequence[Profile1D]
                  ) -> tuple[float, float, float]:
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
