"""The whole plan checked before anything moves: every move of every setup through
a :class:`~station.plan.checker.MotionChecker`, the plan's limits, routes and
plunger travel filled in.

A check made with a fresh checker is a pure function of the plan, the config, the
controller's soft limits, the start and what it is asked (travel, spread): it fills
the plan's limits, routes and travel and the checker's caches, and nothing else. So
the process keeps the last few such checks, and an identical one (``orthocal
resume`` after ``run`` in one long-lived process, the test suite's hundreds of
runs of a few configs) gets both back as the first check left them: the same plan
and the same checker state, everything after it running exactly as it would have
after the check itself. A check that refused its plan is not kept (it raises again,
saying why), nor one made with a checker that had already worked (its result
depends on what that checker did before).
"""

from __future__ import annotations

import json
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.base import Vec3
from station.config import StationConfig
from station.plan.checker import MotionChecker
from station.plan.joint_test_plan import plan_station_test
from station.plan.joint_travel import check_joint_tests
from station.plan.limits import limits_source
from station.plan.steps import Move, Plan, Prompt, joint_triple, route_key

#: Checks kept (a run checks one plan, or two: from its postures, then from where the
#: axes stand).
KEPT = 8


@dataclass(frozen=True)
class _Checked:
    """What a check left: the plan's fields it filled, and the checker's state."""

    limits: tuple[list[float], list[float]]
    limits_source: str
    routes: dict[tuple, list[tuple[float, float, float]]]
    start: tuple[float, ...] | None
    checker: tuple[dict, dict, dict]


_kept: OrderedDict[str, _Checked] = OrderedDict()


def check_plan(
    plan: Plan,
    config: StationConfig,
    controller_limits: tuple[Vec3, Vec3],
    start: Vec3 | None = None,
    checker: MotionChecker | None = None,
    travel: bool = True,
) -> Plan:
    """Refuse (BadInput) a plan that leaves the soft limits or the workspace, or
    that would push a plunger past its stroke or lift it off the leg, anywhere
    along any move; name the posture, setup and indicator. Fills plan.limits and
    plan.travel. ``start``: the current joint positions, to check the first move.
    ``checker``: one made for this config and these limits, shared by the checks of
    many plans (its bounds remembered; plan.travel then spans all of them).
    ``travel`` False: only whether the plan holds (a search over candidate plans),
    not the sharp plunger travel of every sub-move that plan.travel lists. A joint
    test ([joints] tests) must span the travel the plan and the workspace need; the
    station's own ([joints] station_test) is planned and checked here too
    (plan.station_test), unless ``travel`` is False."""
    check_joint_tests(config, plan, controller_limits)
    checker = checker or MotionChecker(config, controller_limits)
    key = _key(plan, config, controller_limits, start, travel, checker) \
        if checker.fresh() else None
    if key is not None and key in _kept:
        _kept.move_to_end(key)
        _restore(_kept[key], plan, checker)
    else:
        _check_moves(plan, config, controller_limits, start, checker, travel)
        if key is not None:
            _keep(key, plan, checker)
    plan.travel = checker.travel
    plan.motion = checker.motion
    # the station's own test of the joints, before the first measurement, from where
    # the axes stand (station.plan.joint_test_plan); not in a search over candidate
    # plans, which asks only whether their moves hold
    if travel:
        plan.station_test = plan_station_test(config, plan, controller_limits, checker, start)
    return plan


def _check_moves(plan: Plan, config: StationConfig,
                 controller_limits: tuple[Vec3, Vec3],
                 start: Vec3 | None, checker: MotionChecker, travel: bool) -> None:
    """Every move of every setup through ``checker``: the plan's limits, routes and
    start filled in (its travel is the checker's)."""
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
                legs = checker.route(position, step.targets, step.label, sp, mounted,
                                     approach=step.approach, travel=travel)
                # the waypoints: the sub-moves' targets before the target (and before
                # the approach point, which the move itself names)
                via = legs[:-2] if step.approach is not None else legs[:-1]
                if position is not None and via:
                    plan.routes[route_key(position, step.targets)] = [
                        joint_triple(leg) for leg in via]
                position = np.asarray(step.targets)
    plan.start = None if start is None else tuple(float(v) for v in start)


#: What a check reads of a config: the machine, the controller's profile, limits and
#: motion, the gauges' names and strokes, the setups and the procedure. Not where the
#: devices are reached nor how long to wait for them (a simulated station's ports
#: change from run to run; the plan check does not).
_SECTIONS = {"machine", "controller", "indicators", "setups", "procedure"}
_CONNECTION = {"host", "port", "baudrate", "bytesize", "parity", "stopbits", "serial",
               "timeout_s", "reconnect_s", "reopen_s", "home_timeout_s"}


def _config_doc(config: StationConfig) -> dict[str, Any]:
    doc = config.model_dump(mode="json", include=_SECTIONS)
    for part in (doc["controller"], *doc["indicators"]):
        for name in _CONNECTION & set(part):
            del part[name]
    return doc


def _key(plan: Plan, config: StationConfig,
         controller_limits: tuple[Vec3, Vec3],
         start: Vec3 | None, travel: bool, checker: MotionChecker) -> str:
    """Everything a check with a fresh checker depends on, as text (the checker's
    own config and limits too: a caller may have made it for others)."""
    doc: list[Any] = [plan.to_json(), plan.routes and sorted(map(str, plan.routes.items())),
                      _config_doc(config),
                      [[float(v) for v in side] for side in controller_limits],
                      # where the controller's limits came from (absent ones are the
                      # config's), as station.plan.limits reads it
                      str(getattr(controller_limits, "source", None)),
                      str(getattr(controller_limits, "reason", None)),
                      None if start is None else [float(v) for v in start], travel,
                      checker.config is config or _config_doc(checker.config),
                      checker.lo.tolist(), checker.hi.tolist(), checker.motion,
                      checker.margin, checker.spread]
    return json.dumps(doc, sort_keys=True, default=str)


def _keep(key: str, plan: Plan, checker: MotionChecker) -> None:
    """Keep copies of what the check left (the run goes on changing its own)."""
    assert plan.limits is not None  # filled by _check_moves
    _kept[key] = _Checked((list(plan.limits[0]), list(plan.limits[1])), plan.limits_source,
                          {k: list(v) for k, v in plan.routes.items()}, plan.start,
                          checker.state())
    while len(_kept) > KEPT:
        _kept.popitem(last=False)


def _restore(done: _Checked, plan: Plan, checker: MotionChecker) -> None:
    """Put copies of a kept check into ``plan`` and ``checker``."""
    checker.resume_from(done.checker)
    plan.limits = (list(done.limits[0]), list(done.limits[1]))
    plan.limits_source = done.limits_source
    plan.routes = {k: list(v) for k, v in done.routes.items()}
    plan.start = done.start
