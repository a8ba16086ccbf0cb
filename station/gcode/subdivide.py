"""Each motion cut into straight segments that a controller with the machine's
nominal kinematics can be sent, so that the identified machine's tool stays within
the tolerance of the programmed curve along the whole path, between the points sent
as well as at them (orthocal/compensation.py: (K2) and its inverse).

The method, adaptive bisection with a conservative chord check:

1. Every motion starts as one segment of its curve C(t); an arc as equal pieces of
   at most 45° whose chords stand off the arc by 90 % of what step 2 allows. A
   segment [ta, tb] sends the controller its end points p' = FK_nominal(IK_c(C(t))),
   rounded to the output format as they will be written.
2. Between two points sent, the nominal controller interpolates a straight line s(f),
   f from 0 to 1, and commands the joints ρ(f) = IK_nominal(s(f)); the identified
   machine's tool is then at FK_c(ρ(f)) (``nominal_path``). At f = 0, 1/8, ..., 1
   this is compared with the programmed curve at the same fraction,
   C(ta + f·(tb − ta)). The distance to the same fraction is never less than the
   distance to the curve, so the measure is conservative; the segment is kept when its
   largest is within 90 % of the tolerance (the rest for what lies between the
   fractions), else it is halved in t and both halves are judged again.
3. Every segment kept has its joints ρ(f) checked against the controller's soft
   limits, so the limits hold along the whole path, not only at the block's ends. A
   point of the programmed path beyond a leg's reach, or a chord the nominal
   kinematics cannot follow, is refused naming its line.

With the joints' tables (``CompensatedMachine.joints``, docs/design.md "Joint tables in the
controller") the motions are first cut where a joint turns back
(station.gcode.directions), so that on each piece every joint moves one way, and each
piece carries its joints' directions. A point is then sent where the joints counted
c = (J5) of q = IK_c(p) in those directions put a nominal controller
(p' = FK_nominal(c)), and the tool between points stands where the joints counted
ρ(f) put it: FK_c(ρ(f) + ε(ρ(f), dir)), ε linear between the table's targets as the
joint's own error is taken to be. Where a joint turns back, its count must change by
its reversal while the tool stays: the point is written twice, reached with the old
directions' counts and left with the new ones (:func:`subdivide` returns both).

All motions of a program are judged together, in chunks, each step vectorised
over their points.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from orthocal import Geometry, JointErrors
from orthocal.compensation import compensated_points, controller_joints, landed
from orthocal.joint_compensation import counted_joints, standing
from orthocal.kinematics import forward
from station.gcode.directions import piece_directions, turning_points
from station.gcode.paths import Curves
from station.gcode.reach import Bounds, guarded, guarded_with, joints_at, refusal, why_out
from station.gcode.words import GcodeError

FRACTIONS = np.linspace(0.0, 1.0, 9)
#: A segment is kept within this share of the tolerance (the rest: between fractions).
MARGIN = 0.9
#: The most segments one motion may need before compensate says it cannot.
MAX_SEGMENTS = 100_000
_CHUNK = 2048  # segments judged per call: 18 000 points, a few MB per array
_MAX_ARC_PIECE = math.pi / 4
_FIRST_SAGITTA = 0.9


@dataclass(frozen=True)
class CompensatedMachine:
    """The identified machine a program is compensated for: its nominal geometry and
    θ_c, the 12-vector of PARAM_NAMES a nominal controller is not told; ``joints``:
    each joint's table in the joints the controller commands (None: exact joints)."""

    geometry: Geometry
    theta_c: np.ndarray
    joints: JointErrors | None = None

    def needed(self, p: np.ndarray) -> np.ndarray:
        """q = IK_c(p): the joints the identified machine needs at machine points p."""
        return controller_joints(p, self.geometry, self.theta_c)

    def sent(self, p: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Where to send a nominal controller for machine points ``p`` (m, k, 3),
        each joint approached in ``dirs`` (m, 3): FK_nominal of the counts (J5)."""
        if self.joints is None:
            return compensated_points(p, self.geometry, self.theta_c)
        q = self.needed(p)
        c = counted_joints(self.joints, q, np.broadcast_to(dirs[:, None, :], q.shape))
        return forward(c, self.geometry)

    def tool(self, rho: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Where the identified machine's tool stands for joints counted ``rho``
        (m, k, 3) moving in ``dirs`` (m, 3)."""
        if self.joints is not None:
            rho = standing(self.joints, rho, np.broadcast_to(dirs[:, None, :], rho.shape))
        return landed(rho, self.geometry, self.theta_c)


@dataclass(frozen=True)
class JointLimits:
    """The controller's soft limits of joint ρ (mm; ±inf where none), and whence."""

    lower: np.ndarray
    upper: np.ndarray
    source: str


@dataclass(frozen=True)
class WriteGrid:
    """How points are written: the work offset (mm, where the program's origin sits
    in machine coordinates) and, per motion, mm per program unit and 10^decimals."""

    offset: np.ndarray
    scale: np.ndarray
    factor: np.ndarray

    def written(self, ci: np.ndarray, sent: np.ndarray) -> np.ndarray:
        """Machine points ``sent`` (m, k, 3) as written: program units, rounded."""
        f = self.factor[ci][:, None, None]
        return np.rint((sent - self.offset) / self.scale[ci][:, None, None] * f) / f

    def machine(self, ci: np.ndarray, written: np.ndarray) -> np.ndarray:
        return written * self.scale[ci][:, None, None] + self.offset


@dataclass
class _Pending:
    ci: np.ndarray
    ta: np.ndarray
    tb: np.ndarray
    dirs: np.ndarray  # (m, 3): each joint's direction on the segment (0: no tables)


def subdivide(curves: Curves, grid: WriteGrid, machine: CompensatedMachine, limits: JointLimits,
              tolerance: float, labels: Sequence[tuple[int, str]]) -> list[np.ndarray]:
    """Per motion, the points to send (program units, rounded; the segments' ends in
    order, its start not repeated; where a joint turns back, the turning point once
    more, with the new directions' counts, before the segment that leaves it).
    GcodeError naming the line where the path leaves the workspace, the soft limits or
    a joint's table, or cannot be kept within ``tolerance`` (mm)."""
    if not len(curves):
        return []
    pending = _initial(curves, tolerance)
    if machine.joints is not None:
        pending = _directed(pending, curves, grid, machine)
    kept: list[tuple[np.ndarray, ...]] = []
    while len(pending.ci):
        ok = np.zeros(len(pending.ci), dtype=bool)
        ends = np.empty((len(pending.ci), 2, 3))
        for lo in range(0, len(pending.ci), _CHUNK):
            part = slice(lo, lo + _CHUNK)
            ok[part], ends[part] = _judge(curves, grid, machine, limits, tolerance, labels,
                                          pending.ci[part], pending.ta[part],
                                          pending.tb[part], pending.dirs[part])
        kept.append((pending.ci[ok], pending.ta[ok], ends[ok], pending.dirs[ok]))
        pending = _halve(pending, ~ok, labels, tolerance)
    ci, ta, end, dirs = (np.concatenate(a) for a in zip(*kept, strict=True))
    order = np.lexsort((ta, ci))
    ci, end, dirs = ci[order], end[order], dirs[order]
    turned = np.zeros(len(ci), dtype=bool)
    turned[1:] = np.any(dirs[1:] != dirs[:-1], axis=1)  # a joint turns back here
    points = [[] for _ in range(len(curves))]  # type: list[list[np.ndarray]]
    for k in range(len(ci)):
        if turned[k]:
            points[ci[k]].append(end[k, 0])
        points[ci[k]].append(end[k, 1])
    return [np.array(p) for p in points]


def _initial(curves: Curves, tolerance: float) -> _Pending:
    """The first cut of each motion: a line whole; an arc in equal pieces of at most
    45° whose chords stand off the arc by 90 % of what a segment may (the arc's own
    sagitta r·(1 − cos(Δθ/2)) is most of a small arc's deviation), so that most
    pieces are kept at once and halving is left for the rest."""
    radius = np.maximum(curves.r0, curves.r1)
    sagitta = min(_FIRST_SAGITTA * MARGIN * tolerance, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        step = np.where(radius > sagitta, 2.0 * np.arccos(1.0 - sagitta / radius), np.pi)
    step = np.minimum(step, _MAX_ARC_PIECE)
    pieces = np.maximum(1, np.ceil(np.abs(curves.theta) / step)).astype(int)
    ci = np.repeat(np.arange(len(curves)), pieces)
    first = np.cumsum(pieces) - pieces
    k = np.arange(len(ci)) - np.repeat(first, pieces)
    n = pieces[ci]
    return _Pending(ci, k / n, np.where(k + 1 == n, 1.0, (k + 1) / n),
                    np.zeros((len(ci), 3)))


def _directed(pending: _Pending, curves: Curves, grid: WriteGrid,
              machine: CompensatedMachine) -> _Pending:
    """The first cut cut again where a joint turns back, each piece with its joints'
    directions (station.gcode.directions)."""
    turns = turning_points(curves, grid.offset,
                           lambda p: guarded(machine.needed, p[:, None, :])[:, 0])
    ci, ta, tb = [], [], []
    for c, a, b in zip(pending.ci, pending.ta, pending.tb, strict=True):
        inner = turns[c][(turns[c] > a) & (turns[c] < b)]
        cuts = np.concatenate([[a], inner, [b]])
        ci += [c] * (len(cuts) - 1)
        ta += cuts[:-1].tolist()
        tb += cuts[1:].tolist()
    ci_a, ta_a, tb_a = np.array(ci, dtype=int), np.array(ta), np.array(tb)
    at = curves.at(ci_a, np.stack([ta_a, tb_a], axis=1)) + grid.offset
    q = guarded(machine.needed, at)
    dirs = piece_directions(q[:, 0], q[:, 1])
    assert machine.joints is not None
    tabled = [machine.joints.table(a) is not None for a in "xyz"]
    # a joint without a table errs alike both ways: its turns change nothing written
    return _Pending(ci_a, ta_a, tb_a, np.where(tabled, dirs, 0.0))


def _halve(bad: _Pending, mask: np.ndarray, labels: Sequence[tuple[int, str]],
           tolerance: float) -> _Pending:
    """The segments not kept, each halved in t (its directions kept: a joint that moves
    one way over a segment moves so over its halves)."""
    ci, ta, tb, dirs = bad.ci[mask], bad.ta[mask], bad.tb[mask], bad.dirs[mask]
    if len(ci) and np.min(tb - ta) * MAX_SEGMENTS < 1.0:
        lineno, label = labels[int(ci[np.argmin(tb - ta)])]
        raise GcodeError(lineno, label, f"the path cannot be kept within {tolerance:g} mm "
                         f"with {MAX_SEGMENTS} segments: it leaves what the nominal "
                         "kinematics can follow, or the tolerance is too tight")
    mid = (ta + tb) / 2.0
    return _Pending(np.concatenate([ci, ci]), np.concatenate([ta, mid]),
                    np.concatenate([mid, tb]), np.concatenate([dirs, dirs]))


def _judge(curves: Curves, grid: WriteGrid, machine: CompensatedMachine, limits: JointLimits,
           tolerance: float, labels: Sequence[tuple[int, str]], ci: np.ndarray, ta: np.ndarray,
           tb: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which segments keep the tool within the tolerance (and, those kept, within the
    soft limits), and each segment's start and end points as written (m, 2, 3)."""
    g = machine.geometry
    bounds = _bounds(machine, limits)
    ends = curves.at(ci, np.stack([ta, tb], axis=1)) + grid.offset
    if machine.joints is not None:
        _check_tables(ends, ci, machine, labels)
    sent = guarded_with(machine.sent, ends, dirs)
    beyond = np.isnan(sent).any(axis=(1, 2))
    if beyond.any():
        k = int(np.argmax(beyond))
        _refuse_point(curves, grid, bounds, labels, int(ci[k]), ends[k])
    written = grid.written(ci, sent)
    sent = grid.machine(ci, written)
    chord = sent[:, :1] + FRACTIONS[None, :, None] * (sent[:, 1:] - sent[:, :1])
    rho = guarded(lambda s: controller_joints(s, g, None), chord)
    tool = guarded_with(machine.tool, rho, dirs)
    fractions = ta[:, None] + FRACTIONS[None, :] * (tb - ta)[:, None]
    wanted = curves.at(ci, fractions) + grid.offset
    deviation = np.linalg.norm(tool - wanted, axis=2).max(axis=1)
    ok = deviation <= MARGIN * tolerance  # NaN (a chord beyond reach): halved
    _check_limits(curves, grid, bounds, rho[ok], ci[ok], wanted[ok], labels)
    return ok, written


def _bounds(machine: CompensatedMachine, limits: JointLimits) -> Bounds:
    return Bounds(machine.geometry, machine.theta_c, limits.lower, limits.upper,
                  limits.source)


def _check_tables(ends: np.ndarray, ci: np.ndarray, machine: CompensatedMachine,
                  labels: Sequence[tuple[int, str]]) -> None:
    """GcodeError for the first segment end where a joint would stand outside its
    table: its error there is not known (a table is never extrapolated). The ends hold
    every joint's extremes: the motions are cut where a joint turns back."""
    assert machine.joints is not None
    q = guarded(machine.needed, ends)
    for i, axis in enumerate("xyz"):
        table = machine.joints.table(axis)
        if table is None:
            continue
        lo, hi = table.span
        with np.errstate(invalid="ignore"):
            out = np.any((q[..., i] < lo - 1e-9) | (q[..., i] > hi + 1e-9), axis=1)
        if out.any():
            k = int(np.argmax(out))
            lineno, word = labels[int(ci[k])]
            value = q[k, :, i][np.argmax(np.abs(q[k, :, i] - (lo + hi) / 2))]
            raise GcodeError(lineno, word, f"joint {axis} would stand at {value:.3f} mm, "
                             f"outside its table ({lo:.3f} to {hi:.3f} mm, the run's joint "
                             "test): its error there is not known")


def _refuse_point(curves: Curves, grid: WriteGrid, bounds: Bounds,
                  labels: Sequence[tuple[int, str]], ci: int, ends: np.ndarray) -> None:
    """A segment with an end the identified machine cannot reach: the program's first
    point out of reach named (station.gcode.reach), not the segment's start."""
    beyond = np.isnan(joints_at(ends[None], bounds)[0]).any(axis=1)
    point = ends[int(np.argmax(beyond))]
    raise refusal(curves, grid.offset, bounds, labels, ci, point,
                  "the path leaves the workspace, beyond a leg's reach,")


def _check_limits(curves: Curves, grid: WriteGrid, bounds: Bounds, rho: np.ndarray,
                  ci: np.ndarray, wanted: np.ndarray,
                  labels: Sequence[tuple[int, str]]) -> None:
    """GcodeError for the first point out of reach where a segment's joints leave the
    soft limits (``rho``, ``wanted``: its chord's joints and programmed points)."""
    # per segment (numpy's stubs type a reduction over axes as maybe a scalar)
    with np.errstate(invalid="ignore"):
        out = np.asarray(((rho < bounds.lower) | (rho > bounds.upper)).any(axis=2))
    if not out.any():
        return
    k = int(np.argmax(np.asarray(out.any(axis=1))))
    j = int(np.argmax(out[k]))
    raise refusal(curves, grid.offset, bounds, labels, int(ci[k]), wanted[k, j],
                  why_out(rho[k, j], bounds))
