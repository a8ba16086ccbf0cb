"""The station's own test of each joint against a length reference, planned as steps and
checked before anything moves (docs/design.md, "Joints"; docs/model.md, "The station's
own joint test").

Per joint i of ``[joints] station_test`` (x, y, z in that order), before the
calibration's first measurement, joint i alone moving, the others at Π0's L:

1. move to the datum ρ_0; the operator mounts the test's gauge on carriage i, its
   plunger along the axis on the reference's datum face (``[joints.reference]``
   ``plunger``: "-" toward lower ρ), and removes every other gauge;
2. for each target ρ_k = ρ_0 − s·f_k (model.md (J9); k = 0 the datum): move to the
   face's side of it (where the larger stack fits under the lifted plunger), the
   operator sets face k; then ``station_repeats`` times, approach ρ_k from that side
   and from the other, each from ``[procedure] approach_overrun_mm`` beyond, settle
   and read;
3. face 0 (the datum) again, approached and read as at the start: the drift;
4. the operator takes the gauge and the reference off.

The targets span the travel the run needs (station.plan.joint_travel.needed_travel:
the workspace box through the inverse kinematics, within the soft limits, and the
test postures). A side whose approach would leave the soft limits is not taken (a
target on a soft limit is approached from inside; its other side is inferred,
orthocal.joint_test). The check routes every move through the plan's
:class:`~station.plan.checker.MotionChecker` (soft limits, the machine's workspace;
no leg gauge is on) and follows the test gauge's plunger along the joint: at every
reading in contact and clear of its stop, and never past its stop on any move, for
a joint off by up to :data:`WORST_ERROR_UM_PER_M` from its count: the preload window
the prompt names.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from drivers.base import Vec3
from orthocal.joint_test import iso_targets, plunger_sign
from station.config import StationConfig
from station.config.joint_reference import ReferenceConfig
from station.errors import BadInput
from station.plan.checker import MotionChecker
from station.plan.joint_travel import needed_travel
from station.plan.steps import Move, Plan, Settle, joint_triple

#: What the check leaves room for beyond the nominal travel: a joint off its count by
#: up to this (µm per metre from the datum), ten times a rolled screw's worst (ISO
#: 3408-3 class C10, 210 µm per 300 mm): the plunger's travel is never bet on a model
#: of the joint the test is there to measure.
WORST_ERROR_UM_PER_M = 1000.0
#: A gauge-block stack's length is built to the µm.
STACK_STEP_MM = 0.001
SIDES = ("forward", "reverse")


@dataclass(frozen=True)
class JointMount:
    """The operator mounts ``gauge`` on carriage ``axis`` against the reference's datum
    face, the joint at its datum, and removes every other gauge."""

    axis: str
    gauge: str
    kind: str = "joint-mount"


@dataclass(frozen=True)
class FaceSet:
    """The operator sets face ``face_mm`` (from the datum) at the plunger: target
    ``target``'s (the test's count of targets: the datum again, at the end)."""

    axis: str
    target: int
    face_mm: float
    kind: str = "joint-face"


@dataclass(frozen=True)
class JointRead:
    """``n`` readings of ``gauge`` at target ``target`` approached from ``side``
    ("forward": from below), the ``repeat``-th time; ``stop`` names them in the journal."""

    stop: str
    axis: str
    target: int
    side: str
    repeat: int
    gauge: str
    n: int
    kind: str = "joint-read"


@dataclass(frozen=True)
class JointUnmount:
    """The operator takes ``gauge`` off carriage ``axis`` and the reference off the base."""

    axis: str
    gauge: str
    kind: str = "joint-unmount"


TestStep = Move | Settle | JointMount | FaceSet | JointRead | JointUnmount


def read_stop(axis: str, target: int | str, side: str, repeat: int) -> str:
    """A test reading's stop id: ``j:x:3:f2`` (target 3 from below, its second time)."""
    return f"j:{axis}:{target}:{side[0]}{repeat}"


@dataclass
class JointTestPlan:
    """One joint's test: its gauge and reference, the targets ρ_k in the order read (the
    datum first) and the faces f_k set at them (mm from the datum face), which sides
    each is approached from (forward, reverse), the overrun, repeats, readings per
    approach and settling; ``home`` the joints at Π0; the travel it must span
    (``needed``: lo, hi); filled by the check: the plunger's travel from its mounting
    (``travel``: least and most, mm pushed in) and the preload ``window``."""

    axis: str
    gauge: str
    reference: str
    plunger: str
    home: tuple[float, float, float]
    targets: tuple[float, ...]
    faces: tuple[float, ...]
    sides: tuple[tuple[bool, bool], ...]
    overrun: float
    repeats: int
    readings: int
    settle_s: float
    needed: tuple[float, float]
    limits: tuple[float, float]
    travel: tuple[float, float] | None = None
    window: tuple[float, float] | None = None

    @property
    def index(self) -> int:
        return "xyz".index(self.axis)

    @property
    def sign(self) -> int:
        return plunger_sign(self.plunger)

    def point(self, rho: float) -> tuple[float, float, float]:
        """The joints with joint i at ``rho``, the others at Π0's."""
        p = list(self.home)
        p[self.index] = float(rho)
        return joint_triple(p)

    def face_side(self, k: int) -> float:
        """Where joint i stands while face k is set: the overrun beyond ρ_k on the side
        away from the reference (the larger stack fits under the lifted plunger),
        within the soft limits."""
        lo, hi = self.limits
        return float(min(max(self.targets[k] - self.sign * self.overrun, lo), hi))

    def _approaches(self, k: int, label: str) -> list[TestStep]:
        """Every approach of target k (the test's count of targets: the datum again)."""
        rho = self.targets[k if k < len(self.targets) else 0]
        fwd, rev = self.sides[k if k < len(self.targets) else 0]
        # first from the face's side, where the joint stands, then from the other
        order = ["reverse", "forward"] if self.sign < 0 else ["forward", "reverse"]
        out: list[TestStep] = []
        for repeat in range(1, self.repeats + 1):
            for side in order:
                if not (fwd if side == "forward" else rev):
                    continue
                start = rho - self.overrun if side == "forward" else rho + self.overrun
                out += [Move(self.point(rho), label, approach=self.point(start)),
                        Settle(self.settle_s),
                        JointRead(read_stop(self.axis, "c" if k == len(self.targets) else k,
                                            side, repeat), self.axis, k, side, repeat,
                                  self.gauge, self.readings)]
        return out

    def steps(self) -> list[TestStep]:
        """The joint's whole test, in order."""
        a = self.axis
        out: list[TestStep] = [Move(self.point(self.targets[0]), f"joint {a} datum"),
                               JointMount(a, self.gauge)]
        for k, rho in enumerate(self.targets):
            label = f"joint {a} ρ={rho:.3f}"
            if k:
                out += [Move(self.point(self.face_side(k)), f"{label} (face {k})"),
                        FaceSet(a, k, self.faces[k])]
            out += self._approaches(k, label)
        n = len(self.targets)
        out.append(FaceSet(a, n, self.faces[0]))
        out += self._approaches(n, f"joint {a} datum again")
        out.append(JointUnmount(a, self.gauge))
        return out

    def to_json(self) -> dict[str, object]:
        return {"axis": self.axis, "gauge": self.gauge, "reference": self.reference,
                "plunger": self.plunger, "targets_mm": list(self.targets),
                "faces_mm": list(self.faces),
                "sides": [[f, r] for f, r in self.sides], "overrun_mm": self.overrun,
                "repeats": self.repeats, "readings": self.readings,
                "needed_mm": list(self.needed),
                "travel_mm": None if self.travel is None else list(self.travel),
                "window_mm": None if self.window is None else list(self.window)}

    def lines(self) -> list[str]:
        """The test in the plan listing: its set-up, then one line per target."""
        s = "lower" if self.sign < 0 else "higher"
        head = (f"joint {self.axis}'s own test: gauge {self.gauge} on carriage {self.axis}, "
                f"plunger toward {s} ρ, against the {self.reference}; ρ_{self.axis} from "
                f"{min(self.targets):.3f} to {max(self.targets):.3f} mm (the run needs "
                f"{self.needed[0]:.3f}..{self.needed[1]:.3f}), the others at Π0, "
                f"{self.repeats} approach(es) from each side × {self.readings} reading(s)")
        if self.window is not None:
            head += f"; preload {self.window[0]:.2f}–{self.window[1]:.2f} mm"
        out = [head]
        for k, (rho, face) in enumerate(zip(self.targets, self.faces, strict=True)):
            fwd, rev = self.sides[k]
            sides = "both sides" if fwd and rev else ("from below only" if fwd
                                                      else "from above only")
            out.append(f"  target {k}: ρ = {rho:.3f} mm, face {face:.3f} mm, {sides}")
        out.append("  then the datum again (drift), the gauge and the reference off")
        return out


@dataclass
class StationTest:
    """The station's test of every joint ``[joints] station_test`` names, in x, y, z
    order (station.plan.steps.Plan.station_test)."""

    joints: list[JointTestPlan] = field(default_factory=list)

    def of(self, axis: str) -> JointTestPlan:
        return next(j for j in self.joints if j.axis == axis)

    def to_json(self) -> dict[str, object]:
        return {"joints": [j.to_json() for j in self.joints]}

    def lines(self) -> list[str]:
        return [line for j in self.joints for line in j.lines()]


# --- the targets ----------------------------------------------------------------------


def _faces(ref: ReferenceConfig, span: float, count: int, where: str) -> list[float]:
    """The faces from the datum a test spanning ``span`` mm reads: gauge blocks, ISO
    230-2's irregular targets built to the µm, the last exactly ``span``; a step gauge
    or a length bar, its own up to the first that reaches ``span``."""
    if ref.kind == "gauge blocks":
        t = iso_targets(0.0, span, count)
        faces = [round(float(v) / STACK_STEP_MM) * STACK_STEP_MM for v in t[:-1]] + [span]
        return [float(v) for v in faces]
    given = ref.faces()
    assert given is not None  # a step gauge or a length bar has them
    faces = given
    reach = [n for n, f in enumerate(faces) if f >= span - 1e-9]
    if not reach:
        raise BadInput(f"joints.reference: the {ref.kind} spans {faces[-1]:g} mm; {where} "
                       f"needs {span:.3f} mm; nothing has moved")
    return faces[:reach[0] + 1]


def _datum(s: int, last_face: float, needed: tuple[float, float],
           limits: tuple[float, float], where: str) -> float:
    """ρ_0 such that the targets cover ``needed`` within ``limits`` (the middle of the
    datums that do)."""
    lo, hi = needed
    soft_lo, soft_hi = limits
    if s < 0:  # targets ρ_0 + f, ascending
        a, b = max(hi - last_face, soft_lo), min(lo, soft_hi - last_face)
    else:  # targets ρ_0 − f, descending
        a, b = max(hi, soft_lo + last_face), min(lo + last_face, soft_hi)
    if a > b + 1e-9:
        raise BadInput(f"plan: {where}: a reference of {last_face:g} mm cannot span "
                       f"{lo:.3f}..{hi:.3f} mm within the soft limits [{soft_lo:.3f}, "
                       f"{soft_hi:.3f}]; nothing has moved")
    return a if b - a <= 1e-9 else 0.5 * (a + b)


def joint_plan(config: StationConfig, axis: str, needed: tuple[float, float],
               limits: tuple[float, float]) -> JointTestPlan:
    """Joint ``axis``'s test (unchecked): its targets over ``needed`` (lo, hi) within the
    soft ``limits`` (lo, hi) of the joint."""
    j, proc = config.joints, config.procedure
    ref = j.reference
    assert ref is not None  # the config requires one with station_test
    where = f"the station's test of joint {axis}"
    s = plunger_sign(ref.plunger)
    faces = _faces(ref, needed[1] - needed[0], j.station_targets, where)
    datum = _datum(s, faces[-1], needed, limits, where)
    targets = [datum - s * f for f in faces]
    o = proc.approach_overrun_mm
    sides = tuple((t - o >= limits[0] - 1e-9, t + o <= limits[1] + 1e-9) for t in targets)
    for t, (fwd, rev) in zip(targets, sides, strict=True):
        if not (fwd or rev):
            raise BadInput(f"plan: {where}: ρ_{axis} = {t:.3f} mm cannot be approached "
                           f"from either side within the soft limits; nothing has moved")
    L = config.machine.leg_length
    return JointTestPlan(axis, j.gauge_of(axis, config.indicators[0].name), ref.kind,
                         ref.plunger, (L, L, L), tuple(targets), tuple(faces), sides, o,
                         j.station_repeats, proc.readings, proc.settle_s,
                         (float(needed[0]), float(needed[1])), limits)


# --- the check --------------------------------------------------------------------------


def plunger_travel(jp: JointTestPlan) -> tuple[np.ndarray, np.ndarray, float]:
    """The test gauge's push-in from its mounting (nominal: the joint where it is
    counted), at each reading (its ρ and push-in) and the most on any move while it is
    on: push-in = s·(ρ − ρ_f), ρ_f the null of the face set (only joint i moves: each
    sub-move is monotone, its extremes at its ends)."""
    s, i = jp.sign, jp.index
    face = jp.targets[0]
    here = jp.targets[0]
    reads: list[tuple[float, float]] = []
    most = 0.0
    for step in jp.steps()[2:]:  # from the mounting on
        if isinstance(step, Move):
            path = [here] + ([] if step.approach is None else [step.approach[i]]) + \
                [step.targets[i]]
            most = max(most, *(s * (p - face) for p in path))
            here = step.targets[i]
        elif isinstance(step, FaceSet):
            face = jp.targets[step.target if step.target < len(jp.targets) else 0]
        elif isinstance(step, JointRead):
            reads.append((here, s * (here - face)))
    r = np.asarray(reads, dtype=float)
    return r[:, 0], r[:, 1], most


def check_joint(jp: JointTestPlan, config: StationConfig, checker: MotionChecker,
                start: Vec3 | None) -> Vec3:
    """Refuse (BadInput) a test that would leave the soft limits or the workspace on any
    move, or push its gauge past its stroke or off its face; fill ``travel`` and
    ``window``. Returns where the test leaves the axes."""
    where = f"the station's test of joint {jp.axis}"
    position = None if start is None else np.asarray(start, dtype=float)
    for step in jp.steps():
        if isinstance(step, Move):
            checker.route(position, step.targets, f"{step.label}, in {where}",
                          approach=step.approach, travel=False)
            position = np.asarray(step.targets, dtype=float)
    rho, push, most = plunger_travel(jp)
    pad = 1e-6 * WORST_ERROR_UM_PER_M * np.abs(rho - jp.targets[0])
    ind = config.indicator(jp.gauge)
    m = config.procedure.plunger_margin_mm
    low = float(np.max(m + pad - push))
    high = float(ind.stroke_mm - m - max(float(np.max(pad)), 0.0) - max(most, float(np.max(push))))
    jp.travel = (float(np.min(push - pad)), float(max(most, float(np.max(push + pad)))))
    jp.window = (low, high)
    if not low <= ind.preload <= high:
        said = (f"the window is empty ({low:.3f} > {high:.3f} mm)" if low > high else
                f"its preload {ind.preload:g} mm ([[indicators]] preload_mm) is outside "
                f"{low:.3f}–{high:.3f} mm")
        raise BadInput(f"plan: {where}: gauge {jp.gauge} (stroke {ind.stroke_mm:g} mm) "
                       f"must stay on its face at every reading and off its stop on every "
                       f"move, the joint off its count by up to {WORST_ERROR_UM_PER_M:g} "
                       f"µm/m, with the overrun of {jp.overrun:g} mm ([procedure] "
                       f"approach_overrun_mm) and the margin of {m:g} mm: {said}; nothing "
                       "has moved")
    assert position is not None
    return joint_triple(position)


def plan_station_test(config: StationConfig, plan: Plan,
                      controller_limits: tuple[Vec3, Vec3], checker: MotionChecker,
                      start: Vec3 | None = None) -> StationTest | None:
    """The station's test of the joints ``[joints] station_test`` names, checked
    (module docstring); None where it names none."""
    names: Sequence[str] = config.joints.station_test
    if not names:
        return None
    lo, hi, _why = needed_travel(config, plan, controller_limits)
    test = StationTest()
    position: Vec3 | None = start
    for axis in sorted(names):
        i = "xyz".index(axis)
        jp = joint_plan(config, axis, (float(lo[i]), float(hi[i])),
                        (float(checker.lo[i]), float(checker.hi[i])))
        position = check_joint(jp, config, checker, position)
        test.joints.append(jp)
    return test
