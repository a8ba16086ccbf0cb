"""The procedure as a list of small typed steps (bluesky-style plan), checked
before anything moves.

A setup is: move to Π0, prompt the operator to mount the setup's indicators
(at Π0, the middle of the leg), read Π0, then cycles Π_i^+ → Π_i^− → Π0, each
stop settled and read. Consecutive cycles share their Π0 stop, and Π_i^+ goes
straight to Π_i^−, so no axis travels further than the postures require. With
``[procedure] strokes`` a cycle visits Π_i(s) for every stroke, in the order of
:func:`orthocal.postures.stop_order` (out along +, back through to −, home).

Stop ids are ``"{phase}:{setup}:{cycle}:{posture}"`` (phase ``m`` measurement,
``v`` verification; cycle 0 holds only the first Π0). The sequencer generates
the same steps with the same functions, so the listing and the check cover
exactly what runs, repeats and verification included (they revisit the same
postures).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

import orthocal
from orthocal import postures
from station.config import StationConfig
from station.errors import BadInput
from station.motion import real_path, waypoints

AXES = ("x", "y", "z")
# Most waypoints put on one move to keep the plungers in their strokes; each is a
# rest-to-rest sub-move (bench/cycle.py measures what they cost).
MAX_WAYPOINTS = 10
PHASES = {"m": "measurement", "v": "verification"}


def posture_label(sign: str, leg: str | None) -> str:
    if sign == "0":
        return "Π0"
    return f"Π_{leg}^{sign}" if sign in ("+", "-") else f"Π_{leg}({sign})"


def cycle_postures(config: StationConfig,
                   strokes: Sequence[float] | None = None) -> tuple[str, ...]:
    """The test postures of one cycle, in the order visited: ('+', '-') unless
    ``[procedure] strokes`` (or ``strokes``, for a design study) names others
    (orthocal.postures: '+30', '-50', ...)."""
    m = config.machine
    strokes = strokes or config.procedure.strokes or [m.rho_max, m.rho_min]
    geometry = m.geometry()
    return tuple(postures.posture_name(s, geometry) for s in postures.stop_order(strokes))


def stop_id(phase: str, setup: int, cycle: int, sign: str) -> str:
    return f"{phase}:{setup}:{cycle}:{sign}"


@dataclass(frozen=True)
class Prompt:
    setup: int
    leg: str
    indicators: tuple[tuple[str, str], ...]  # (name, direction) as mounted
    kind: str = "prompt"


@dataclass(frozen=True)
class Move:
    targets: tuple[float, float, float]
    label: str
    kind: str = "move"


@dataclass(frozen=True)
class Settle:
    seconds: float
    kind: str = "settle"


@dataclass(frozen=True)
class Read:
    stop: str
    setup: int
    cycle: int
    sign: str  # "0", "+", "-" or a stroke such as "+30"
    indicators: tuple[str, ...]
    n: int
    kind: str = "read"


@dataclass(frozen=True)
class Checkpoint:
    setup: int
    cycle: int
    label: str = "cycle complete"
    kind: str = "checkpoint"


Step = Prompt | Move | Settle | Read | Checkpoint


@dataclass
class SetupPlan:
    index: int
    leg: str
    indicators: dict[str, str]  # name -> "y" or "-y"
    postures: dict[str, tuple[float, float, float]]  # "0", "+", "-", "+30" -> joint targets
    order: tuple[str, ...] = ("+", "-")  # the test postures of a cycle, in order

    def move(self, sign: str) -> Move:
        return Move(self.postures[sign], posture_label(sign, self.leg))

    def start_steps(self, phase: str, cycle: int, settle_s: float, n: int) -> list[Step]:
        """Mount at Π0 and take the Π0 reading that opens cycle ``cycle + 1`` (0 in a
        fresh run; later when a resumed run remounts mid-setup)."""
        names = tuple(self.indicators)
        return [
            self.move("0"),
            Prompt(self.index, self.leg, tuple(self.indicators.items())),
            Settle(settle_s),
            Read(stop_id(phase, self.index, cycle, "0"), self.index, cycle, "0", names, n),
        ]

    def cycle_steps(self, phase: str, cycle: int, settle_s: float, n: int) -> list[Step]:
        names = tuple(self.indicators)
        steps: list[Step] = []
        for sign in (*self.order, "0"):
            steps += [
                self.move(sign),
                Settle(settle_s),
                Read(stop_id(phase, self.index, cycle, sign), self.index, cycle, sign, names, n),
            ]
        steps.append(Checkpoint(self.index, cycle))
        return steps


@dataclass
class Plan:
    setups: list[SetupPlan]
    cycles: int
    readings: int
    settle_s: float
    limits: tuple[list[float], list[float]] | None = None
    limits_source: str = ""
    # Per indicator and setup: (min, max) plunger travel found by the check, mm.
    travel: dict[str, tuple[float, float]] = field(default_factory=dict)
    # The controller's path model and the waypoints the check put on moves whose
    # single COMMAND 1 would take a plunger out of its stroke (see route_key).
    motion: str | None = None
    routes: dict[tuple, list[tuple[float, float, float]]] = field(default_factory=dict)
    start: tuple[float, ...] | None = None

    def waypoints_of(self) -> Iterator[tuple[Step, list[tuple[float, float, float]]]]:
        """Each step of the measurement phase with the waypoints of its move."""
        position = self.start
        for step in self.steps("m"):
            via: list[tuple[float, float, float]] = []
            if isinstance(step, Move):
                if position is not None:
                    via = self.routes.get(route_key(position, step.targets), [])
                position = step.targets
            yield step, via

    def steps(self, phase: str = "m") -> Iterator[Step]:
        """Every step of one phase at the configured number of cycles."""
        for sp in self.setups:
            yield from sp.start_steps(phase, 0, self.settle_s, self.readings)
            for cycle in range(1, self.cycles + 1):
                yield from sp.cycle_steps(phase, cycle, self.settle_s, self.readings)

    def to_json(self) -> dict:
        # Only a plan with [procedure] strokes says so: the default's JSON stays as it was.
        strokes = {} if self.setups[0].order == ("+", "-") else {
            "test_postures": list(self.setups[0].order)}
        return {
            **strokes,
            "cycles": self.cycles,
            "readings": self.readings,
            "settle_s": self.settle_s,
            "soft_limits": None if self.limits is None else
            {"lower": self.limits[0], "upper": self.limits[1], "source": self.limits_source},
            "setups": [
                {"index": sp.index, "leg": sp.leg, "indicators": sp.indicators,
                 "postures": {k: list(v) for k, v in sp.postures.items()}}
                for sp in self.setups
            ],
            "travel_mm": {k: list(v) for k, v in self.travel.items()},
            "motion": self.motion,
            "steps": [asdict(s) | ({"via": [list(w) for w in via]} if via else {})
                      for s, via in self.waypoints_of()],
        }

    def format(self) -> str:
        order = self.setups[0].order
        cycle = "Π0 → Π+ → Π− → Π0" if order == ("+", "-") else \
            " → ".join(["Π0", *(posture_label(s, "i") for s in order), "Π0"])
        lines = [
            f"plan: {len(self.setups)} setup(s) × up to {self.cycles} cycle(s) "
            f"({cycle}) × {self.readings} reading(s) per stop, "
            f"settle {self.settle_s:g} s"
        ]
        if self.limits is not None:
            lo, hi = self.limits
            source = f" ({self.limits_source})" if self.limits_source else ""
            lines.append(f"soft limits{source} (mm): " + ", ".join(
                f"ρ_{a} ∈ [{lo[i]:.3f}, {hi[i]:.3f}]" for i, a in enumerate(AXES)))
        if self.motion is not None:
            lines.append(f"controller path: {self.motion} axes" + (
                " (each axis its own trapezoid)" if self.motion == "independent"
                else " (straight line in joint space)")
                + "; a move whose path would take a plunger out of its stroke goes via "
                "waypoints, one COMMAND 1 each")
        number = 0
        for step, via in self.waypoints_of():
            number += 1
            if isinstance(step, Move):
                text = f"move {step.label:<7} ρ = (" + ", ".join(
                    f"{t:.3f}" for t in step.targets) + ")"
                if via:
                    text += f" via {len(via)} waypoint(s): " + "; ".join(
                        "(" + ", ".join(f"{t:.3f}" for t in w) + ")" for w in via)
            elif isinstance(step, Prompt):
                lines.append(f"setup {step.setup + 1}: leg {step.leg}")
                text = ("prompt: mount " + ", ".join(f"{n} ({d})" for n, d in step.indicators)
                        + f" at the middle of leg {step.leg} at Π0; remove the others")
            elif isinstance(step, Settle):
                text = f"settle {step.seconds:g} s"
            elif isinstance(step, Read):
                text = f"read {step.stop:<10} {', '.join(step.indicators)} × {step.n}"
            else:
                text = f"checkpoint: setup {step.setup + 1} cycle {step.cycle} complete"
            lines.append(f"  {number:4d}  {text}")
        if self.travel:
            lines.append("plunger travel along every move (nominal model):")
            for key, (lo_t, hi_t) in self.travel.items():
                lines.append(f"  {key}: {lo_t:+.3f} .. {hi_t:+.3f} mm")
        lines.append("plan checked: every target inside the soft limits and the workspace, "
                     "every plunger within its stroke")
        return "\n".join(lines)


def route_key(start: Sequence[float], target: Sequence[float]) -> tuple:
    """Routes are keyed by their ends (to the µm): a move with gauges mounted
    joins two postures of one leg, so it belongs to one setup."""
    return (*(round(float(v), 3) for v in start), *(round(float(v), 3) for v in target))


def build_plan(config: StationConfig, strokes: Sequence[float] | None = None) -> Plan:
    """The plan of ``config``; ``strokes`` replaces ``[procedure] strokes`` (design
    studies try strokes the config does not hold, even beyond rho_min/rho_max)."""
    geometry = config.machine.geometry()
    proc = config.procedure
    order = cycle_postures(config, strokes)
    setups = []
    for idx, setup in enumerate(config.setups):
        targets = {
            s: tuple(float(v) for v in orthocal.posture(s, setup.leg, geometry))
            for s in ("0", *order)
        }
        setups.append(SetupPlan(idx, setup.leg, dict(setup.indicators), targets,  # type: ignore[arg-type]
                                order))
    return Plan(setups, proc.cycles, proc.readings, proc.settle_s)


def effective_limits(
    config: StationConfig, controller_limits: tuple[Sequence[float], Sequence[float]]
) -> tuple[np.ndarray, np.ndarray]:
    """The controller's soft limits, narrowed (never widened) by the config.

    Where the controller cannot tell its limits (``controller_limits.source`` is
    "absent" or "nonsense", drivers.limits.SoftLimits) they come from
    ``[controller] soft_min`` / ``soft_max`` alone; with neither, BadInput names both
    ways to provide them, before anything moves (design.md, "Register map").
    """
    c = config.controller
    if getattr(controller_limits, "source", "registers") in ("absent", "nonsense"):
        missing = [k for k in ("soft_min", "soft_max") if getattr(c, k) is None]
        if missing:
            reason = getattr(controller_limits, "reason", "") or "the controller has none"
            raise BadInput(
                f"soft limits: {reason}; give them as [controller] "
                f"{' and '.join(missing)} (joint mm, x, y, z) in the config, or map the "
                "controller's soft-limit registers in [controller.registers] (SOFT_MIN_X.. "
                "SOFT_MAX_Z = address); nothing has moved")
        return (np.asarray(c.soft_min, dtype=float).copy(),
                np.asarray(c.soft_max, dtype=float).copy())
    lo = np.asarray(controller_limits[0], dtype=float).copy()
    hi = np.asarray(controller_limits[1], dtype=float).copy()
    if c.soft_min is not None:
        lo = np.maximum(lo, c.soft_min)
    if c.soft_max is not None:
        hi = np.minimum(hi, c.soft_max)
    return lo, hi


def limits_source(config: StationConfig, controller_limits: object) -> str:
    """Where the limits the plan uses come from, in words for the listing."""
    c = config.controller
    if getattr(controller_limits, "source", "registers") in ("absent", "nonsense"):
        return "from the config ([controller] soft_min/soft_max)"
    if c.soft_min is not None or c.soft_max is not None:
        return "the controller's, narrowed by the config"
    return "the controller's"


def motion_model(config: StationConfig) -> str:
    """The path model of the controller: the config's ``[controller] motion``, else
    what the register-map profile promises (design.md: COMMAND 1 promises no
    interpolation unless the profile says the axes are coordinated)."""
    if config.controller.motion is not None:
        return config.controller.motion
    from drivers.registers import PROFILES

    profile = PROFILES.get(config.controller.profile)
    if profile is None:
        raise BadInput(f"controller.profile: unknown register map "
                       f"{config.controller.profile!r}; built-in: {sorted(PROFILES)}")
    return profile.motion


class MotionChecker:
    """Checks one move along the path the controller really takes (station.motion:
    coordinated or independent axes, at the configured speed and acceleration):
    soft limits, workspace, the leg crossing each mounted indicator's plane and
    every plunger's travel. Where the path of a single COMMAND 1 would take a
    plunger out of its stroke (or inside the guard's margin of an end), the move
    is split by waypoints that put the end point at even steps on its straight
    line (station.motion.waypoints), as few as make it hold. The plan check
    runs it over every move of the plan; the sequencer runs it again before every
    physical move, from the actual position (a resumed run starts anywhere)."""

    def __init__(self, config: StationConfig,
                 controller_limits: tuple[Sequence[float], Sequence[float]]) -> None:
        self.config = config
        self.geometry = config.machine.geometry()
        self.lo, self.hi = effective_limits(config, controller_limits)
        self.motion = motion_model(config)
        self.speed = config.controller.speed_mm_s
        self.accel = config.controller.accel_mm_s2
        self.margin = config.procedure.plunger_margin_mm
        self.travel: dict[str, tuple[float, float]] = {}

    def path(self, start: Sequence[float], target: Sequence[float]) -> np.ndarray:
        return real_path(start, target, self.motion, self.speed, self.accel)

    def check(self, start: Sequence[float] | None, target: Sequence[float], label: str,
              setup: SetupPlan | None = None, mounted: dict[str, str] | None = None) -> None:
        self.route(start, target, label, setup, mounted)

    def route(self, start: Sequence[float] | None, target: Sequence[float], label: str,
              setup: SetupPlan | None = None, mounted: dict[str, str] | None = None
              ) -> list[np.ndarray]:
        """The targets of the sub-moves that reach ``target`` (waypoints, then the
        target itself); raises BadInput when no route up to MAX_WAYPOINTS holds."""
        target_v = np.asarray(target, dtype=float)
        where = "" if setup is None else f"setup {setup.index + 1} (leg {setup.leg}), "
        where += label if start is None else f"move to {label}"
        if start is None:
            self._limits(target_v[None, :], where)
            return [target_v]
        fallback: tuple[list[np.ndarray], dict[str, tuple[float, float]]] | None = None
        error: BadInput | None = None
        for n in range(MAX_WAYPOINTS + 1):
            legs = waypoints(start, target_v, n, self.geometry)
            try:
                travel, tight = self._route_travel(start, legs, where, setup, mounted)
            except BadInput as exc:
                error = exc
                if not mounted:
                    break  # limits and workspace: more waypoints only approach the line
                continue
            if not tight:
                self._commit(travel)
                return legs
            if fallback is None:
                fallback = (legs, travel)
        if fallback is not None:
            # Within the stroke, though inside the guard's margin: the guard watches.
            self._commit(fallback[1])
            return fallback[0]
        assert error is not None
        raise error

    def _route_travel(self, start: Sequence[float], legs: list[np.ndarray], where: str,
                      setup: SetupPlan | None, mounted: dict[str, str] | None
                      ) -> tuple[dict[str, tuple[float, float]], bool]:
        travel: dict[str, tuple[float, float]] = {}
        tight = False
        here = np.asarray(start, dtype=float)
        for leg in legs:
            path = self.path(here, leg)
            self._limits(path, where)
            if setup is not None and mounted:
                for key, (t_min, t_max, close) in self._travel(setup, mounted, path,
                                                               where).items():
                    old = travel.get(key, (t_min, t_max))
                    travel[key] = (min(old[0], t_min), max(old[1], t_max))
                    tight |= close
            here = leg
        return travel, tight

    def _commit(self, travel: dict[str, tuple[float, float]]) -> None:
        for key, (t_min, t_max) in travel.items():
            old = self.travel.get(key, (0.0, 0.0))
            self.travel[key] = (min(old[0], t_min), max(old[1], t_max))

    def _limits(self, points: np.ndarray, where: str) -> None:
        lo, hi = self.lo, self.hi
        for i, axis in enumerate(AXES):
            excess = np.maximum(lo[i] - points[:, i], points[:, i] - hi[i])
            if np.any(excess > 1e-9):
                value = float(points[np.argmax(excess), i])
                raise BadInput(
                    f"plan: {where}: ρ_{axis} = {value:.3f} mm is outside the soft "
                    f"limits [{lo[i]:.3f}, {hi[i]:.3f}]; nothing has moved")
        try:
            orthocal.forward(points, self.geometry)
        except ValueError:
            raise BadInput(f"plan: {where}: outside the machine's workspace; "
                           "nothing has moved") from None

    def nominal_travel(self, sp: SetupPlan, name: str, direction: str,
                       path: np.ndarray) -> np.ndarray:
        """Plunger travel (mm, + pushed in) of indicator ``name`` mounted on
        ``sp``'s leg at Π0, at each joint position of ``path``: nominal model."""
        sign = -1.0 if direction.startswith("-") else 1.0
        axis = direction.lstrip("-")
        rho0 = np.asarray(sp.postures["0"])
        zero = float(orthocal.leg_reading(rho0, sp.leg, axis, self.geometry))
        return sign * (orthocal.leg_reading(path, sp.leg, axis, self.geometry) - zero)

    def _travel(self, sp: SetupPlan, mounted: dict[str, str], path: np.ndarray,
                where: str) -> dict[str, tuple[float, float, bool]]:
        geometry = self.geometry
        mount = geometry.mount_plane
        i = AXES.index(sp.leg)
        p = orthocal.forward(path, geometry)
        # The indicator touches the leg only while the leg crosses its plane x_i = M.
        spans = (np.minimum(p[:, i], path[:, i]) <= mount) & \
            (mount <= np.maximum(p[:, i], path[:, i]))
        out: dict[str, tuple[float, float, bool]] = {}
        for name, direction in mounted.items():
            ind = self.config.indicator(name)
            if not np.all(spans):
                raise BadInput(f"plan: {where}: leg {sp.leg} no longer crosses the plane of "
                               f"indicator {name}; nothing has moved")
            travel = self.nominal_travel(sp, name, direction, path)
            low, high = -ind.preload, ind.stroke_mm - ind.preload
            t_min, t_max = float(travel.min()), float(travel.max())
            if t_max > high + 1e-9:
                raise BadInput(
                    f"plan: {where}: indicator {name} ({direction}) would be pushed "
                    f"{t_max:.3f} mm past its mounting point, beyond its stroke "
                    f"({ind.stroke_mm:g} mm, preload {ind.preload:g} mm); nothing has moved")
            if t_min < low - 1e-9:
                raise BadInput(
                    f"plan: {where}: the leg would lift off indicator {name} ({direction}) "
                    f"by {-t_min - ind.preload:.3f} mm (travel {t_min:.3f} mm, preload "
                    f"{ind.preload:g} mm); nothing has moved")
            close = t_max > high - self.margin or t_min < low + self.margin
            out[f"{name} on leg {sp.leg} (setup {sp.index + 1})"] = (t_min, t_max, close)
        return out


def check_plan(
    plan: Plan,
    config: StationConfig,
    controller_limits: tuple[Sequence[float], Sequence[float]],
    start: Sequence[float] | None = None,
) -> Plan:
    """Refuse (BadInput) a plan that leaves the soft limits or the workspace, or
    that would push a plunger past its stroke or lift it off the leg, anywhere
    along any move; name the posture, setup and indicator. Fills plan.limits and
    plan.travel. ``start``: the current joint positions, to check the first move."""
    checker = MotionChecker(config, controller_limits)
    plan.limits = (checker.lo.tolist(), checker.hi.tolist())
    plan.limits_source = limits_source(config, controller_limits)
    position = None if start is None else np.asarray(start, dtype=float)
    for sp in plan.setups:
        mounted: dict[str, str] = {}
        # The listing's order plus one extra Π+ move, which follows a cycle's
        # final Π0 when the next cycle (or a repeat) starts: all moves of a setup.
        for step in sp.start_steps("m", 0, 0.0, 1) + sp.cycle_steps("m", 1, 0.0, 1) \
                + sp.cycle_steps("m", 2, 0.0, 1)[:1]:
            if isinstance(step, Prompt):
                mounted = dict(step.indicators)
            elif isinstance(step, Move):
                legs = checker.route(position, step.targets, step.label, sp, mounted)
                if position is not None and len(legs) > 1:
                    plan.routes[route_key(position, step.targets)] = [
                        tuple(float(v) for v in leg) for leg in legs[:-1]]
                position = np.asarray(step.targets)
    plan.travel = checker.travel
    plan.motion = checker.motion
    plan.start = None if start is None else tuple(float(v) for v in start)
    return plan
