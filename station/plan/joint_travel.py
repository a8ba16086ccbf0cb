"""The travel each joint's test must span, checked with the plan before anything moves
(docs/design.md, "Joints"): the workspace box through the nominal inverse kinematics
(within the controller's soft limits: the tool is stated nowhere beyond them) and every
posture the plan visits. A test that stops short is one line naming its file and the
line of its first or last target, exit 2: a table is never extrapolated."""

from __future__ import annotations

import numpy as np

from drivers.base import Vec3
from orthocal import inverse, workspace_grid, workspace_joint_range
from station.config import StationConfig
from station.config.joint_tests import read_joint_tests
from station.errors import BadInput
from station.plan.steps import Plan

#: How far a test may stop short of a needed end (mm): a target written to the µm.
SLACK_MM = 0.0005


def needed_travel(config: StationConfig, plan: Plan | None = None,
                  soft_limits: tuple[Vec3, Vec3] | None = None
                  ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(lo, hi) per joint x, y, z (mm) the run needs a joint's error over, and what sets
    each end ("the workspace" or "the test postures") as lo's and hi's words."""
    geometry = config.machine.geometry()
    box = np.asarray(config.machine.workspace_box(), dtype=float)
    try:
        lo, hi = workspace_joint_range(box, geometry)
    except ValueError:  # a box beyond a leg's reach: the grid's reachable nodes
        rho = np.asarray(inverse(workspace_grid(box, 7, geometry).points, geometry))
        lo, hi = rho.min(axis=0), rho.max(axis=0)
    if soft_limits is not None:
        lo = np.maximum(lo, np.asarray(soft_limits[0], dtype=float))
        hi = np.minimum(hi, np.asarray(soft_limits[1], dtype=float))
    targets = [list(t) for sp in (plan.setups if plan else []) for t in sp.postures.values()]
    postures = np.array(targets or [[geometry.leg_length] * 3])
    p_lo, p_hi = postures.min(axis=0), postures.max(axis=0)
    # where both reach an end, the postures name it: the run's own moves
    why = ["the test postures" if pl <= w else "the workspace box through the inverse "
           "kinematics" for pl, w in zip(p_lo, lo, strict=True)]
    why += ["the test postures" if ph >= w else "the workspace box through the inverse "
            "kinematics" for ph, w in zip(p_hi, hi, strict=True)]
    return np.minimum(lo, p_lo), np.maximum(hi, p_hi), why


def check_joint_tests(config: StationConfig, plan: Plan | None = None,
                      soft_limits: tuple[Vec3, Vec3] | None = None) -> None:
    """Refuse (BadInput: the file, the line, what needs the travel) a joint test of
    ``[joints] tests`` that does not span what :func:`needed_travel` says."""
    tests = read_joint_tests(config.joints.tests)
    if not tests:
        return
    lo, hi, why = needed_travel(config, plan, soft_limits)
    L = config.machine.leg_length
    said = (f"target_mm is the joint coordinate as the station commands it, absolute, Π0 "
            f"at ρ = L = {L:g} mm")
    for axis, test in tests.items():
        i = "xyz".index(axis)
        first, last = test.targets_mm[0], test.targets_mm[-1]
        if first > lo[i] + SLACK_MM:
            raise BadInput(f"{test.source}: line {test.lines[0]}: the test of joint {axis} "
                           f"starts at {first:g} mm; the run needs it from {lo[i]:.3f} mm "
                           f"({why[i]}) to {hi[i]:.3f} mm ({said})")
        if last < hi[i] - SLACK_MM:
            raise BadInput(f"{test.source}: line {test.lines[-1]}: the test of joint {axis} "
                           f"ends at {last:g} mm; the run needs it up to {hi[i]:.3f} mm "
                           f"({why[3 + i]}) from {lo[i]:.3f} mm ({said})")
