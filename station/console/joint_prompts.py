"""What the station's own test of a joint asks of the operator, in words (docs/design.md,
"Joints"; the set-up is docs/model.md's, "The station's own joint test"): the
mounting, each face set at the plunger, the gauge and the reference taken off. The
picture the mounting names is station.report.joint_picture's."""

from __future__ import annotations

from collections.abc import Sequence

from station.plan.joint_test_plan import FaceSet, JointMount, JointTestPlan, JointUnmount

JointPrompt = JointMount | FaceSet | JointUnmount


def _toward(test: JointTestPlan) -> str:
    return "lower ρ" if test.sign < 0 else "higher ρ"


def datum_words(test: JointTestPlan) -> str:
    """The datum face, as the kind of reference has it."""
    return {"gauge blocks": "a stop (a block clamped to the base, its face square to the "
                            "axis): the stacks stand on it",
            "step gauge": "the step gauge, clamped to the base parallel to the axis, its "
                          "first face at the plunger",
            "length bar": "a stop (a block clamped to the base, its face square to the "
                          "axis): the bar stands on it"}[test.reference]


def face_words(test: JointTestPlan, step: FaceSet) -> str:
    """What the operator does to put ``step``'s face at the plunger."""
    closing = step.target >= len(test.targets)
    what = {"gauge blocks": (f"a stack of gauge blocks of {step.face_mm:.3f} mm on the stop"
                             if step.face_mm else "no stack: the plunger on the stop"),
            "step gauge": f"the step gauge's face at {step.face_mm:.3f} mm under the plunger",
            "length bar": (f"the length bar ({step.face_mm:.3f} mm) on the stop"
                           if step.face_mm else "the length bar out: the plunger on the stop")
            }[test.reference]
    count = ("the datum again, read for the drift" if closing
             else f"target {step.target} of {len(test.targets) - 1}")
    return (f"joint {test.axis}, {count}: lift the plunger, set {what}, lower the plunger "
            f"onto it (ρ_{test.axis} = {test.face_side(step.target % len(test.targets)):.3f} "
            "mm now)")


def joint_instruction(step: JointPrompt, test: JointTestPlan, others: Sequence[str],
                      picture: str | None = None) -> str:
    """The prompt of ``step`` of joint ``test.axis``'s own test, a few short lines;
    ``others``: the gauges to take off at the mounting; ``picture``: its file."""
    a = test.axis
    if isinstance(step, FaceSet):
        return face_words(test, step)
    if isinstance(step, JointUnmount):
        return (f"joint {a}'s own test is done: take gauge {test.gauge} off carriage {a} "
                f"and the {test.reference} off the base")
    remove = f" Take {', '.join(others)} off." if others else ""
    lines = [f"joint {a}'s own test: the machine is at ρ_{a} = {test.targets[0]:.3f} mm (its "
             f"datum), the other joints at Π0.{remove}"]
    if picture:
        lines.append(f"picture: {picture}")
    lines.append(f"reference: {datum_words(test)}, beside carriage {a}'s rail, on its "
                 f"{_toward(test)} side")
    window = "" if test.window is None else \
        f"; push in {test.window[0]:.2f}–{test.window[1]:.2f} mm"
    lines.append(f"gauge {test.gauge}: clamped to carriage {a}, its plunger along the axis "
                 f"pointing toward {_toward(test)}, onto the datum face{window}")
    lines.append(f"then {len(test.targets) - 1} face(s) in turn, each asked for; the joint "
                 f"alone moves, from ρ_{a} = {min(test.targets):.3f} to "
                 f"{max(test.targets):.3f} mm")
    return "\n  ".join(lines)
