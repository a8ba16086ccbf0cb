"""Path safety: every move checked over every joint position the controller may
pass through, before anything moves (docs/design.md, "Register map"; station.plan.motion
says what is assumed of the drive), with the fewest waypoints that keep every
mounted plunger within its stroke; the soft limits the plan uses.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping

import numpy as np

import orthocal
from drivers.base import Vec3
from orthocal.measurement import reading_at
from orthocal.postures import plane_at
from station.config import StationConfig
from station.errors import BadInput
from station.plan import motion
from station.plan.gauges import Gauges, NotCrossing
from station.plan.limits import effective_limits, motion_model
from station.plan.steps import AXES, SetupPlan

# Most waypoints put on one move to keep the plungers in their strokes; each is a
# rest-to-rest sub-move (bench/cycle.py measures what they cost).
MAX_WAYPOINTS = 16
# A move that starts this close to the start of a route already found reuses its
# waypoints (the first sub-move is checked again from the actual start).
START_REUSE_MM = 0.05
# Sub-move bounds a checker remembers before it starts afresh (a design search
# bounds tens of thousands; each entry is a few hundred bytes).
BOUND_CACHE_SIZE = 200_000
# Added on both sides of a measured signal (station.engine.guard_monitor) when a move is routed
# with it: a reading's noise, the error of carrying it to a stop not yet read.
SIGNAL_PAD_MM = 0.05


class MotionChecker:
    """Checks one move over every joint position the controller may pass through
    (station.plan.motion: the joint-space box of the move's ends for independent axes,
    the straight line for coordinated ones): soft limits, workspace, the leg
    crossing each mounted indicator's plane and every plunger's travel. Where one
    COMMAND 1 could take a plunger out of its stroke (or inside the guard's margin
    of an end), the move is split by waypoints on the end point's straight line
    (station.plan.motion.route), as few as make it hold. The plan check runs it over
    every move of the plan; the sequencer runs it again before every physical
    move, from the actual position (a resumed run starts anywhere), and the guard
    after it stopped the axes, with the travel it measured (``signal``)."""

    def __init__(self, config: StationConfig,
                 controller_limits: tuple[Vec3, Vec3],
                 spread: bool = True) -> None:
        """``spread`` False: routes with the fewest waypoints as found, not spread for
        the largest slack (a search that asks only whether a plan holds)."""
        self.config = config
        self.spread = spread
        self.geometry = config.machine.geometry()
        self.lo, self.hi = effective_limits(config, controller_limits)
        self.motion = motion_model(config)
        self.margin = config.procedure.plunger_margin_mm
        self.travel: dict[str, tuple[float, float]] = {}
        # Routes already found, by (target, mounting, setup): a start within
        # START_REUSE_MM of a cached one reuses its waypoints where all still hold.
        self._routes: dict[tuple, list[tuple[np.ndarray, list[np.ndarray]]]] = {}
        # Nominal travel bounds of sub-moves already bounded (_segment_bound).
        self._bounds: dict[tuple, motion.Bound | type[Exception]] = {}
        # Each mounting's reading at Π0 (nominal_travel).
        self._zeros: dict[tuple, float] = {}
        # Per gauge, the travel its plunger already stands at at Π0 from where it was
        # mounted (a mounting kept across a write-back: station.engine.kept): it sits
        # as if mounted with that much more preload.
        self.preload_shift: dict[str, float] = {}

    def check(self, start: Vec3 | None, target: Vec3, label: str,
              setup: SetupPlan | None = None, mounted: dict[str, str] | None = None) -> None:
        self.route(start, target, label, setup, mounted)

    def fresh(self) -> bool:
        """Nothing checked yet: what a check does depends on its arguments alone."""
        return not (self.travel or self._routes or self._bounds)

    def state(self) -> tuple[dict, dict, dict]:
        """Copies of the travel, routes and bounds found so far (station.plan.check
        keeps them for an identical check)."""
        return (dict(self.travel), {k: list(v) for k, v in self._routes.items()},
                dict(self._bounds))

    def resume_from(self, state: tuple[dict, dict, dict]) -> None:
        """Go on from :meth:`state` of an identical checker (copies taken here)."""
        travel, routes, bounds = state
        self.travel = dict(travel)
        self._routes = {k: list(v) for k, v in routes.items()}
        self._bounds = dict(bounds)

    def route(self, start: Vec3 | None, target: Vec3, label: str,
              setup: SetupPlan | None = None, mounted: dict[str, str] | None = None,
              signal: Mapping[str, tuple[float, float]] | None = None,
              max_waypoints: int = MAX_WAYPOINTS, strict: bool = False,
              margin: float | None = None, travel: bool = True,
              approach: Vec3 | None = None) -> list[np.ndarray]:
        """The targets of the sub-moves that reach ``target`` (waypoints, then the
        target itself); raises BadInput when no route of up to ``max_waypoints``
        holds. ``signal``: per mounted gauge, the travel beyond the nominal model
        (measured by the guard) at the start and at the target, taken to change
        linearly along the move, widened by SIGNAL_PAD_MM and, away from its ends,
        by up to SIGNAL_BULGE × that change. A route keeps
        out of the guard's margin where it can, else (unless ``strict``: the guard's
        own re-plan) within the stroke, the guard watching what comes that close.
        ``margin``: instead of plunger_margin_mm (a re-plan from where a plunger
        already stands closer to its end: no closer than that). ``travel``: the
        route's plunger travel goes into ``travel`` (the plan listing's); a run's
        moves need only the decision (a sharp bound of every sub-move from wherever
        the axes stand costs tens of ms). ``approach``: the point the last short leg
        starts from ([procedure] approach: every joint runs from there toward its
        target from one side): the route goes to it, then to the target, both
        checked alike."""
        if approach is not None:
            return self._approached(start, target, approach, label, setup, mounted, signal,
                                    max_waypoints, strict, margin, travel)
        keep = self.margin if margin is None else margin
        target_v = np.asarray(target, dtype=float)
        where = "" if setup is None else f"setup {setup.index + 1} (leg {setup.leg}), "
        where += label if start is None else f"move to {label}"
        if start is None:
            self._limits(target_v[None, :], where)
            return [target_v]
        start_v = np.asarray(start, dtype=float)
        self._limits(np.vstack([start_v, target_v]), where)
        gauges = self._gauges(setup, mounted, signal, start_v, target_v)
        # A route found before for this target and mounting, from (nearly) here, is
        # reused when every sub-move of it holds now, with this signal and margin:
        # a move repeated every cycle is routed once.
        key = (tuple(round(float(v), 3) for v in target_v),
               tuple(sorted((mounted or {}).items())), None if setup is None else setup.index)
        reusable = [legs for cached_start, legs in self._routes.get(key, [])
                    if np.max(np.abs(cached_start - start_v)) <= START_REUSE_MM
                    and len(legs) - 1 <= max_waypoints]
        for legs in sorted(reusable, key=len):
            here = start_v
            for leg in legs:
                if not self._feasible(gauges, here, leg, keep, where):
                    break
                here = leg
            else:
                if travel:
                    self._commit(self._route_travel(gauges, start_v, legs, where))
                return [leg.copy() for leg in legs]
        routed: list[np.ndarray] | None = None
        for kept in (keep,) if strict else (keep, 0.0):
            def feasible(a: np.ndarray, b: np.ndarray, slack: float, m: float = kept) -> bool:
                return self._feasible(gauges, a, b, m + slack, where)

            routed = motion.route(feasible, start_v, target_v, self.geometry, max_waypoints,
                                  max_slack=self._room(gauges, kept) if self.spread else 0.0)
            if routed is not None:
                break
        if routed is None:
            raise self._refusal(gauges, start_v, target_v, where, max_waypoints,
                                keep if strict else 0.0)
        if margin is None:  # a re-plan's route (its own margin) is no route to reuse
            self._routes.setdefault(key, []).append(
                (start_v.copy(), [leg.copy() for leg in routed]))
        if travel:
            self._commit(self._route_travel(gauges, start_v, routed, where))
        return routed

    def _approached(self, start: Vec3 | None, target: Vec3,
                    approach: Vec3, label: str, setup: SetupPlan | None,
                    mounted: dict[str, str] | None,
                    signal: Mapping[str, tuple[float, float]] | None, max_waypoints: int,
                    strict: bool, margin: float | None, travel: bool) -> list[np.ndarray]:
        """The route to ``target`` whose last short leg starts at ``approach``: the
        waypoints of the route to the target (on the end point's line to it, where the
        leg is parallel), then the approach point instead of the target, then the
        target; both short sub-moves checked as any is. Where the last waypoint cannot
        reach the approach point in one COMMAND 1, the route goes to it instead."""
        p = np.asarray(approach, dtype=float)
        legs = self.route(start, target, label, setup, mounted, signal, max_waypoints,
                          strict, margin, travel)
        before = legs[-2] if len(legs) > 1 else start
        short = f"{label} (its approach)"
        # Near the target the signal is the target's: the short legs carry it flat (the
        # move's ramp would be read along their own chords, from their starts).
        near = None if signal is None else \
            {n: (s1, s1) for n, (_s0, s1) in signal.items()}
        try:
            to_p = self.route(before, p, short, setup, mounted,
                              near if len(legs) > 1 else signal, 0, strict, margin, travel)
        except BadInput:
            to_p = self.route(start, p, short, setup, mounted, signal, max_waypoints, strict,
                              margin, travel)
            before = None  # the route to the approach point replaces the target's
        head = (legs[:-1] if before is not None else []) + to_p
        return [*head, self.route(p, target, short, setup, mounted, near, 0, strict,
                                  margin, travel)[-1]]

    # --- one sub-move -----------------------------------------------------------------

    def _gauges(self, setup: SetupPlan | None, mounted: dict[str, str] | None,
                signal: Mapping[str, tuple[float, float]] | None,
                start: np.ndarray | None = None, target: np.ndarray | None = None
                ) -> Gauges | None:
        if setup is None or not mounted:
            return None
        names = list(mounted)
        inds = [self.config.indicator(n) for n in names]
        sig = signal or {}
        preload = np.array([i.preload + self.preload_shift.get(n, 0.0)
                            for n, i in zip(names, inds, strict=True)])
        return Gauges(
            setup, names, [mounted[n] for n in names],
            low=-preload,
            high=np.array([i.stroke_mm for i in inds]) - preload,
            sig0=np.array([sig.get(n, (0.0, 0.0))[0] for n in names]),
            sig1=np.array([sig.get(n, (0.0, 0.0))[1] for n in names]),
            pad=SIGNAL_PAD_MM if signal else 0.0,
            chord=None if start is None or target is None or not signal else (start, target))

    def _room(self, gauges: Gauges | None, margin: float) -> float:
        """The largest slack any route could have: half the stroke left inside the margin."""
        if gauges is None:
            return 0.0
        return max(0.0, float(np.min(gauges.high - gauges.low)) / 2.0 - margin)

    def _values(self, gauges: Gauges | None, where: str) -> Callable[[np.ndarray], np.ndarray]:
        """(n, 3) joints -> (n, m) nominal plunger travel of the mounted gauges; raises
        ValueError outside the workspace and NotCrossing when the leg leaves a plane."""
        geometry = self.geometry

        def values(points: np.ndarray) -> np.ndarray:
            p = orthocal.forward(points, geometry)
            if gauges is None:
                return p
            i = AXES.index(gauges.setup.leg)
            mount = self.plane(gauges.setup)
            if not np.all((np.minimum(p[:, i], points[:, i]) <= mount)
                          & (mount <= np.maximum(p[:, i], points[:, i]))):
                raise NotCrossing(where)
            return np.stack([self.nominal_travel(gauges.setup, n, d, points, p)
                             for n, d in zip(gauges.names, gauges.directions, strict=True)],
                            axis=-1)

        return values

    def _bound(self, gauges: Gauges | None, a: np.ndarray, b: np.ndarray, where: str,
               margin: float | None) -> motion.Bound | None:
        """Bound of the travel (signal included) over the sub-move; with ``margin``
        None if it leaves the stroke less that margin (a decision: as sharp as it
        needs, motion.segment_bound). Without gauges, only the workspace is checked
        (a coarse grid: the workspace ends far from the stops)."""
        f = self._values(gauges, where)
        if gauges is None:
            try:
                f(motion.reachable_points(a, b, self.motion))
            except ValueError:
                raise motion.OutsideWorkspace(where) from None
            return motion.Bound(np.zeros(0), np.zeros(0))
        # The signal over this sub-move: the ramp at the extremes of the progress any
        # point of its set has along the move (the same pairing of worst nominal
        # travel and worst signal as the guard makes ahead of the axes).
        sig_lo, sig_hi = gauges.signal_range(a, b, self.motion)
        low = high = None
        if margin is not None:
            low = gauges.low + margin - sig_lo
            high = gauges.high - margin - sig_hi
        bound = self._segment_bound(gauges, f, a, b, low, high, where)
        if not bound.within(low, high):
            return None
        return motion.Bound(bound.lo + sig_lo, bound.hi + sig_hi)

    def _segment_bound(self, gauges: Gauges, f: Callable[[np.ndarray], np.ndarray],
                       a: np.ndarray, b: np.ndarray, low: np.ndarray | None,
                       high: np.ndarray | None, where: str,
                       max_depth: int = motion.MAX_DEPTH) -> motion.Bound:
        """motion.segment_bound, remembered: the nominal travel of a mounting over a
        sub-move is a pure function of the leg, its gauges' plane, its Π0, the gauges
        and the two ends,
        and the same sub-moves come back (every cycle, every re-check of a reused
        route, the waypoint search trying slack after slack, every candidate of
        ``orthocal design``'s search). What one search learned (a bound, values
        attained) answers a later decision against other limits where it can; where
        it cannot, the set is searched again and both are kept (Bound.merge)."""
        def key_of(v: np.ndarray | None) -> bytes | None:
            return None if v is None else np.asarray(v, dtype=float).tobytes()

        key = (gauges.setup.leg, gauges.setup.at, key_of(np.asarray(gauges.setup.postures["0"])),
               tuple(gauges.names), tuple(gauges.directions), key_of(a), key_of(b),
               max_depth)
        known = self._bounds.get(key)
        if isinstance(known, type):  # it raised: again, for this move's words
            raise known(where)
        if known is not None:
            deciding = low is not None or high is not None
            if known.sharp or (deciding and (known.within(low, high)
                                             or known.refutes(low, high))):
                return known
        if len(self._bounds) >= BOUND_CACHE_SIZE:
            self._bounds.clear()
        try:
            found = motion.segment_bound(f, a, b, self.motion, low, high,
                                         max_depth=max_depth)
        except (motion.OutsideWorkspace, NotCrossing) as exc:
            self._bounds[key] = type(exc)
            raise
        bound = found if known is None else known.merge(found)
        self._bounds[key] = bound
        return bound

    def _feasible(self, gauges: Gauges | None, a: np.ndarray, b: np.ndarray, margin: float,
                  where: str) -> bool:
        try:
            return self._bound(gauges, a, b, where, margin) is not None
        except (motion.OutsideWorkspace, NotCrossing):
            return False

    def _route_travel(self, gauges: Gauges | None, start: np.ndarray,
                      legs: list[np.ndarray], where: str) -> dict[str, tuple[float, float]]:
        travel: dict[str, tuple[float, float]] = {}
        if gauges is None:
            return travel
        here = start
        for leg in legs:
            bound = self._bound(gauges, here, leg, where, None)
            assert bound is not None
            for k, name in enumerate(gauges.names):
                key = f"{name} on leg {gauges.setup.leg} (setup {gauges.setup.index + 1})"
                old = travel.get(key, (float(bound.lo[k]), float(bound.hi[k])))
                travel[key] = (min(old[0], float(bound.lo[k])), max(old[1], float(bound.hi[k])))
            here = leg
        return travel

    def travel_bound(self, sp: SetupPlan, mounted: Mapping[str, str], a: Vec3,
                     b: Vec3, coarse: bool = False) -> dict[str, tuple[float, float]]:
        """Nominal (min, max) travel of each mounted gauge over every position one
        COMMAND 1 from a to b may pass through (the guard's look ahead). ``coarse``:
        one round of the branch and bound (for a set of a few mm, such as a poll's
        window spans, exact to microns)."""
        found = self._travel(sp, mounted, a, b, None, 1 if coarse else motion.MAX_DEPTH)
        if found is None:  # outside the workspace: nothing is bounded
            return {n: (-np.inf, np.inf) for n in mounted}
        return found

    def travel_keeps(self, sp: SetupPlan, mounted: Mapping[str, str], a: Vec3,
                     b: Vec3, within: Mapping[str, tuple[float, float]]
                     ) -> dict[str, tuple[float, float]] | None:
        """Whether the nominal travel of each mounted gauge keeps within its (low,
        high) of ``within`` over every position one COMMAND 1 from a to b may pass
        through: its bound, as sharp as that decision needed, or None where it may
        not (or the set leaves the workspace)."""
        return self._travel(sp, mounted, a, b, within, motion.MAX_DEPTH)

    def _travel(self, sp: SetupPlan, mounted: Mapping[str, str], a: Vec3,
                b: Vec3, within: Mapping[str, tuple[float, float]] | None,
                max_depth: int) -> dict[str, tuple[float, float]] | None:
        gauges = self._gauges(sp, dict(mounted), None)
        if gauges is None:
            return {}
        low = None if within is None else np.array([within[n][0] for n in gauges.names])
        high = None if within is None else np.array([within[n][1] for n in gauges.names])
        try:
            bound = self._segment_bound(
                gauges, self._values(gauges, ""), np.asarray(a, dtype=float),
                np.asarray(b, dtype=float), low, high, "", max_depth)
        except (motion.OutsideWorkspace, NotCrossing):
            return None
        if not bound.within(low, high):
            return None
        return {n: (float(bound.lo[k]), float(bound.hi[k]))
                for k, n in enumerate(gauges.names)}

    def _refusal(self, gauges: Gauges | None, start: np.ndarray, target: np.ndarray,
                 where: str, max_waypoints: int, margin: float) -> BadInput:
        """Why no route holds, said of the worst sub-move of the most split one tried
        (the even split into max_waypoints + 1 sub-moves)."""
        at = motion.line_point(start, target, self.geometry)
        cuts = np.linspace(0.0, 1.0, max_waypoints + 2)
        legs = [at(float(t)) for t in cuts]
        via = f" (even via {max_waypoints} waypoints)" if max_waypoints else ""
        timing = ", for some timing of the axes" if self.motion == "independent" else ""
        worst: tuple[float, str, str, bool] | None = None
        for a, b in itertools.pairwise(legs):
            try:
                bound = self._bound(gauges, a, b, where, None)
            except motion.OutsideWorkspace:
                return BadInput(f"plan: {where}: the axes could leave the machine's workspace "
                                f"on the way{via}; nothing has moved")
            except NotCrossing:
                name = "" if gauges is None else f" of indicator {gauges.names[0]}"
                return BadInput(f"plan: {where}: leg {gauges.setup.leg if gauges else '?'} "
                                f"could leave the plane{name}{via}; nothing has moved")
            if gauges is None or bound is None:
                continue
            for k, name in enumerate(gauges.names):
                ind = self.config.indicator(name)
                d = gauges.directions[k]
                over = float(bound.hi[k] - (gauges.high[k] - margin))
                under = float((gauges.low[k] + margin) - bound.lo[k])
                within = f" (margin {margin:g} mm)" if margin else ""
                if over > 0 and (worst is None or over > worst[0]):
                    worst = (over, name, (
                        f"indicator {name} ({d}) could be pushed {float(bound.hi[k]):.3f} mm "
                        f"past its mounting point, beyond its stroke{within} "
                        f"({ind.stroke_mm:g} mm, preload {ind.preload:g} mm)"), True)
                if under > 0 and (worst is None or under > worst[0]):
                    worst = (under, name, (
                        f"the leg could lift off indicator {name} ({d}) by "
                        f"{float(-bound.lo[k] - ind.preload):.3f} mm{within} (travel "
                        f"{float(bound.lo[k]):.3f} mm, preload {ind.preload:g} mm)"), False)
        if worst is None:
            return PathRefused(f"plan: {where}: no route keeps every plunger in its stroke"
                               f"{via}{timing}; nothing has moved", None, False, "")
        detail = f"{worst[2]}{via}{timing}"
        return PathRefused(f"plan: {where}: {detail}; nothing has moved", worst[1], worst[3],
                           detail)

    def _commit(self, travel: dict[str, tuple[float, float]]) -> None:
        for key, (t_min, t_max) in travel.items():
            old = self.travel.get(key, (0.0, 0.0))
            self.travel[key] = (min(old[0], t_min), max(old[1], t_max))

    def _limits(self, points: np.ndarray, where: str) -> None:
        """The ends of a move within the soft limits: then so is every point of the
        box (or line) between them, the limits being a box themselves."""
        lo, hi = self.lo, self.hi
        for i, axis in enumerate(AXES):
            excess = np.maximum(lo[i] - points[:, i], points[:, i] - hi[i])
            if (excess > 1e-9).any():
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
                       path: np.ndarray, end_points: np.ndarray | None = None) -> np.ndarray:
        """Plunger travel (mm, + pushed in) of indicator ``name`` mounted on
        ``sp``'s leg at Π0, at each joint position of ``path``: nominal model.
        ``end_points``: the forward kinematics of ``path``, when the caller has it."""
        sign = -1.0 if direction.startswith("-") else 1.0
        i, j = AXES.index(sp.leg), AXES.index(direction.lstrip("-"))
        path = np.asarray(path, dtype=float)
        p = orthocal.forward(path, self.geometry) if end_points is None else end_points
        plane = self.plane(sp)
        # The reading at Π0 (the gauge's zero): one per mounting, asked for at every
        # bound of every sub-move.
        key = (tuple(sp.postures["0"]), i, j, plane)
        zero = self._zeros.get(key)
        if zero is None:
            rho0 = np.asarray(sp.postures["0"], dtype=float)
            zero = self._zeros[key] = float(reading_at(
                rho0, orthocal.forward(rho0, self.geometry), i, j, np.zeros(3), plane))
        return sign * (reading_at(path, p, i, j, np.zeros(3), plane) - zero)

    def plane(self, sp: SetupPlan) -> float:
        """x_leg of the plane ``sp``'s gauges read in: the middle of the leg at Π0
        (L/2), or the fraction ``sp.at`` of it from the carriage's joint."""
        return self.geometry.mount_plane + plane_at(sp.at, self.geometry)


class PathRefused(BadInput):
    """No route keeps the plungers in their strokes: ``indicator`` (None: none in
    particular), ``pushed`` (toward its stop, else lifted off), ``detail`` (why)."""

    def __init__(self, message: str, indicator: str | None, pushed: bool,
                 detail: str) -> None:
        super().__init__(message)
        self.indicator = indicator
        self.pushed = pushed
        self.detail = detail
