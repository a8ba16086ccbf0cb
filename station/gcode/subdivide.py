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

All motions of a program are judged together, in chunks, each step vectorised
over their points.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from orthocal import Geometry
from orthocal.compensation import compensated_points, controller_joints, landed
from station.gcode.paths import Curves
from station.gcode.reach import Bounds, guarded, joints_at, refusal, why_out
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
class Machine:
    """The identified machine a program is compensated for: its nominal geometry and
    θ_c, the 12-vector of PARAM_NAMES a nominal controller is not told."""

    geometry: Geometry
    theta_c: np.ndarray


@dataclass(frozen=True)
class Limits:
    """The controller's soft limits of joint ρ (mm; ±inf where none), and whence."""

    lower: np.ndarray
    upper: np.ndarray
    source: str


@dataclass(frozen=True)
class Grid:
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


def subdivide(curves: Curves, grid: Grid, machine: Machine, limits: Limits,
              tolerance: float, labels: Sequence[tuple[int, str]]) -> list[np.ndarray]:
    """Per motion, the points to send (program units, rounded; the segments' ends in
    order, its start not repeated). GcodeError naming the line where the path leaves
    the workspace or the soft limits, or cannot be kept within ``tolerance`` (mm)."""
    if not len(curves):
        return []
    pending = _initial(curves, tolerance)
    kept_ci, kept_ta, kept_end = [], [], []
    while len(pending.ci):
        ok = np.zeros(len(pending.ci), dtype=bool)
        ends = np.empty((len(pending.ci), 3))
        for lo in range(0, len(pending.ci), _CHUNK):
            part = slice(lo, lo + _CHUNK)
            ok[part], ends[part] = _judge(curves, grid, machine, limits, tolerance, labels,
                                          pending.ci[part], pending.ta[part],
                                          pending.tb[part])
        kept_ci.append(pending.ci[ok])
        kept_ta.append(pending.ta[ok])
        kept_end.append(ends[ok])
        pending = _halve(pending, ~ok, labels, tolerance)
    ci, ta, end = (np.concatenate(a) for a in (kept_ci, kept_ta, kept_end))
    order = np.lexsort((ta, ci))
    counts = np.bincount(ci, minlength=len(curves))
    return np.split(end[order], np.cumsum(counts)[:-1])


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
    return _Pending(ci, k / n, np.where(k + 1 == n, 1.0, (k + 1) / n))


def _halve(bad: _Pending, mask: np.ndarray, labels: Sequence[tuple[int, str]],
           tolerance: float) -> _Pending:
    """The segments not kept, each halved in t."""
    ci, ta, tb = bad.ci[mask], bad.ta[mask], bad.tb[mask]
    if len(ci) and np.min(tb - ta) * MAX_SEGMENTS < 1.0:
        lineno, label = labels[int(ci[np.argmin(tb - ta)])]
        raise GcodeError(lineno, label, f"the path cannot be kept within {tolerance:g} mm "
                         f"with {MAX_SEGMENTS} segments: it leaves what the nominal "
                         "kinematics can follow, or the tolerance is too tight")
    mid = (ta + tb) / 2.0
    return _Pending(np.concatenate([ci, ci]), np.concatenate([ta, mid]),
                    np.concatenate([mid, tb]))


def _judge(curves: Curves, grid: Grid, machine: Machine, limits: Limits, tolerance: float,
           labels: Sequence[tuple[int, str]], ci: np.ndarray, ta: np.ndarray,
           tb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which segments keep the tool within the tolerance (and, those kept, within the
    soft limits), and each segment's end point as written."""
    g, theta = machine.geometry, machine.theta_c
    bounds = _bounds(machine, limits)
    ends = curves.at(ci, np.stack([ta, tb], axis=1)) + grid.offset
    sent = guarded(lambda p: compensated_points(p, g, theta), ends)
    beyond = np.isnan(sent).any(axis=(1, 2))
    if beyond.any():
        k = int(np.argmax(beyond))
        _refuse_point(curves, grid, bounds, labels, int(ci[k]), ends[k])
    written = grid.written(ci, sent)
    sent = grid.machine(ci, written)
    chord = sent[:, :1] + FRACTIONS[None, :, None] * (sent[:, 1:] - sent[:, :1])
    rho = guarded(lambda s: controller_joints(s, g, None), chord)
    tool = guarded(lambda r: landed(r, g, theta), rho)
    fractions = ta[:, None] + FRACTIONS[None, :] * (tb - ta)[:, None]
    wanted = curves.at(ci, fractions) + grid.offset
    deviation = np.linalg.norm(tool - wanted, axis=2).max(axis=1)
    ok = deviation <= MARGIN * tolerance  # NaN (a chord beyond reach): halved
    _check_limits(curves, grid, bounds, rho[ok], ci[ok], wanted[ok], labels)
    return ok, written[:, 1]


def _bounds(machine: Machine, limits: Limits) -> Bounds:
    return Bounds(machine.geometry, machine.theta_c, limits.lower, limits.upper,
                  limits.source)


def _refuse_point(curves: Curves, grid: Grid, bounds: Bounds,
                  labels: Sequence[tuple[int, str]], ci: int, ends: np.ndarray) -> None:
    """A segment with an end the identified machine cannot reach: the program's first
    point out of reach named (station.gcode.reach), not the segment's start."""
    beyond = np.isnan(joints_at(ends[None], bounds)[0]).any(axis=1)
    point = ends[int(np.argmax(beyond))]
    raise refusal(curves, grid.offset, bounds, labels, ci, point,
                  "the path leaves the workspace, beyond a leg's reach,")


def _check_limits(curves: Curves, grid: Grid, bounds: Bounds, rho: np.ndarray,
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
