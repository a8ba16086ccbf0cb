"""The station's own joint test as planned and checked before anything moves
(station.plan.joint_test_plan; docs/design.md, "The station's own joint test"): its
config, its targets over the travel the run needs, its steps, the listing and the
journal's plan record, the plan check's refusals, the prompts' words and the picture."""

from __future__ import annotations

from typing import Any
from xml.etree import ElementTree

import numpy as np
import pytest
from builders import station_config, station_data

from station.config import parse_config
from station.console.joint_prompts import joint_instruction
from station.errors import BadInput
from station.plan.check import check_plan
from station.plan.checker import MotionChecker
from station.plan.joint_test_plan import (
    FaceSet,
    JointMount,
    JointRead,
    JointTestPlan,
    JointUnmount,
    StationTest,
    plan_station_test,
    plunger_travel,
)
from station.plan.steps import Move, build_plan
from station.record.journal_plan import PlanRecord
from station.report.joint_picture import draw

L = 310.25
LIMITS = (np.full(3, 200.25), np.full(3, 380.25))  # the simulated drive's soft limits
BLOCKS = {"kind": "gauge blocks", "u_mm": 0.0005}


def config(reference: dict[str, Any] | None = None, joints: tuple[str, ...] = ("x", "y", "z"),
           indicators: dict[str, Any] | None = None, **procedure: Any):
    data = station_data(controller={"motion": "coordinated"}, procedure=procedure,
                        joints={"station_test": list(joints), "station_repeats": 2,
                                "reference": reference or BLOCKS})
    if indicators:
        data["indicators"][0].update(indicators)
    return parse_config(data)


def planned(cfg, limits=LIMITS, start=(L, L, L)) -> StationTest:
    plan = check_plan(build_plan(cfg), cfg, limits, start=list(start))
    assert isinstance(plan.station_test, StationTest)
    return plan.station_test


# --- the config ---------------------------------------------------------------------------


@pytest.mark.parametrize(("joints", "said"), [
    ({"station_test": ["x"]}, "joints.station_test: needs [joints.reference]"),
    ({"station_test": ["x"], "station_gauge": "Q", "reference": BLOCKS},
     "joints.station_gauge: no indicator 'Q' (have A, B)"),
    ({"station_test": ["x", "y"], "station_gauge": {"x": "A"}, "reference": BLOCKS},
     "joints.station_gauge: no gauge for joint(s) y"),
    ({"station_test": ["x", "x"], "reference": BLOCKS}, "joints.station_test: a joint named twice"),
    ({"station_test": ["x"], "reference": {"kind": "step gauge", "u_mm": 0.0005}},
     "joints.reference: a step gauge needs faces_mm"),
    ({"station_test": ["x"], "reference": {"kind": "step gauge", "faces_mm": [0, 20, 20],
                                           "u_mm": 0.0005}},
     "faces_mm: must be finite and strictly increasing"),
    ({"station_test": ["x"], "reference": {"kind": "length bar", "length_mm": 150.0,
                                           "u_mm": [0.0005, 0.0006, 0.0007]}},
     "u_mm: one value, or one per face"),
    ({"station_test": ["x"], "reference": {"kind": "gauge blocks", "faces_mm": [0, 10],
                                           "u_mm": 0.0005}},
     "gauge blocks take neither faces_mm nor length_mm"),
    ({"station_test": ["x"], "station_repeats": 1, "reference": BLOCKS},
     "joints.station_repeats: must be >= 2"),
])
def test_a_wrong_station_test_is_one_line_naming_its_key(joints: dict, said: str) -> None:
    with pytest.raises(BadInput) as caught:
        parse_config(station_data(joints=joints), "s.toml")
    message = str(caught.value)
    assert message.startswith("s.toml: ") and said in message and "\n" not in message


def test_a_config_without_the_test_dumps_as_before() -> None:
    assert station_config().model_dump()["joints"] == {"tests": {}}
    dumped = config().model_dump()["joints"]
    assert dumped["station_test"] == ["x", "y", "z"] and dumped["station_repeats"] == 2
    assert parse_config({**station_data(), "joints": dumped}).joints == config().joints


# --- the targets and the steps ---------------------------------------------------------------


def test_gauge_blocks_span_the_travel_the_run_needs_with_irregular_stacks() -> None:
    test = planned(config())
    assert [j.axis for j in test.joints] == ["x", "y", "z"]
    for jp in test.joints:
        # the workspace box through the inverse kinematics, within the soft limits
        assert jp.needed == pytest.approx((200.25, 370.25))
        assert jp.targets[0] == 200.25 and jp.targets[-1] == pytest.approx(370.25, abs=1e-9)
        assert len(jp.targets) == 8 and np.all(np.diff(jp.targets) > 0)
        assert jp.faces[0] == 0.0 and all(round(f, 3) == pytest.approx(f) for f in jp.faces)
        steps = np.diff(jp.faces)
        assert len({round(v, 3) for v in steps}) >= 4  # irregular
        # the datum on the soft limit: from above only; every other target both ways
        assert jp.sides[0] == (False, True) and all(s == (True, True) for s in jp.sides[1:])
        assert jp.window == pytest.approx((0.37, 12.08))
        assert jp.travel == pytest.approx((-0.17, 0.17))


def test_only_the_joint_under_test_moves_and_every_face_is_set_once() -> None:
    jp = planned(config(joints=("y",))).of("y")
    steps = jp.steps()
    assert isinstance(steps[0], Move) and steps[0].targets == (L, 200.25, L)
    assert isinstance(steps[1], JointMount) and isinstance(steps[-1], JointUnmount)
    for step in steps[1:]:
        if isinstance(step, Move):
            assert step.targets[0] == L and step.targets[2] == L
            if step.approach is not None:
                assert abs(step.approach[1] - step.targets[1]) == pytest.approx(0.05)
    faces = [s for s in steps if isinstance(s, FaceSet)]
    assert [f.target for f in faces] == list(range(1, 9)) and faces[-1].face_mm == 0.0
    reads = [s for s in steps if isinstance(s, JointRead)]
    # 2 repeats from both sides at 7 targets, from above only at the datum (twice)
    assert len(reads) == 2 * (2 * 7 + 1 + 1)
    assert {r.stop for r in reads} >= {"j:y:0:r1", "j:y:3:f2", "j:y:c:r2"}
    assert len({r.stop for r in reads}) == len(reads)
    # each face is set at the overrun above its target (plunger "-"), then read from
    # above first: the plunger never pushed past the face's null by more than the overrun
    rho, push, most = plunger_travel(jp)
    assert rho[0] == jp.targets[0] and rho[-1] == jp.targets[0]  # the datum last
    assert np.max(np.abs(push)) == pytest.approx(0.0, abs=1e-9) and most == pytest.approx(0.05)


def test_a_plunger_toward_higher_rho_puts_the_datum_at_the_top() -> None:
    jp = planned(config(reference={**BLOCKS, "plunger": "+"}, joints=("z",))).of("z")
    assert jp.targets[0] == pytest.approx(370.25) and jp.targets[-1] == pytest.approx(200.25)
    assert np.all(np.diff(jp.targets) < 0)
    assert jp.sides[-1] == (False, True)  # the lowest target sits on the soft limit
    assert jp.face_side(3) == pytest.approx(jp.targets[3] - 0.05)


def test_a_step_gauge_uses_its_faces_up_to_the_first_that_spans_the_travel() -> None:
    faces = [0.0, 20.0, 40.0, 60.0, 80.0, 100.0, 120.0, 140.0, 160.0, 180.0, 200.0]
    jp = planned(config(reference={"kind": "step gauge", "faces_mm": faces, "u_mm": 0.001},
                        joints=("x",))).of("x")
    assert jp.faces == tuple(faces[:10])
    # the datum in the middle of those that cover [200.25, 370.25] within the limits
    assert jp.targets[0] == pytest.approx(200.25) and jp.targets[-1] == pytest.approx(380.25)
    assert jp.sides[-1] == (True, False)
    bar = planned(config(reference={"kind": "length bar", "length_mm": 175.0, "u_mm": 0.001},
                         joints=("x",))).of("x")
    # the only datum that covers the travel: on the lower limit, approached from above
    assert bar.faces == (0.0, 175.0) and bar.targets == pytest.approx((200.25, 375.25))
    assert bar.sides == ((False, True), (True, True))


def test_the_listing_and_the_journal_hold_the_test() -> None:
    cfg = config()
    plan = check_plan(build_plan(cfg), cfg, LIMITS, start=[L, L, L])
    text = plan.format()
    assert "joint x's own test: gauge A on carriage x, plunger toward lower ρ, against the " \
           "gauge blocks; ρ_x from 200.250 to 370.250 mm" in text
    assert "target 0: ρ = 200.250 mm, face 0.000 mm, from above only" in text
    doc = plan.to_json()
    record = PlanRecord.model_validate(doc)
    assert record.station_test is not None and len(record.station_test.joints) == 3
    assert record.station_test.joints[1].axis == "y"
    # a plan without the test says nothing of it: its JSON stays as it was
    plain = station_config(controller={"motion": "coordinated"})
    assert "station_test" not in check_plan(build_plan(plain), plain, LIMITS).to_json()


# --- the check's refusals -------------------------------------------------------------------


def test_a_preload_that_leaves_the_face_or_meets_the_stop_is_refused() -> None:
    with pytest.raises(BadInput) as caught:
        planned(config(indicators={"stroke_mm": 8.0, "preload_mm": 7.9}))
    said = str(caught.value)
    assert said.startswith("plan: the station's test of joint x: gauge A (stroke 8 mm)")
    assert "its preload 7.9 mm ([[indicators]] preload_mm) is outside 0.370–7.580 mm" in said
    assert said.endswith("nothing has moved")
    with pytest.raises(BadInput, match=r"approach_overrun_mm\) and the margin of 0.2 mm: the "
                                       r"window is empty"):
        planned(config(indicators={"stroke_mm": 1.0, "preload_mm": 0.5},
                       approach_overrun_mm=0.5))


def test_a_reference_that_cannot_span_the_travel_is_refused() -> None:
    short = {"kind": "step gauge", "faces_mm": [0, 40, 80, 120, 160], "u_mm": 0.001}
    with pytest.raises(BadInput, match=r"^joints.reference: the step gauge spans 160 mm; the "
                                       r"station's test of joint x needs 170.000 mm"):
        planned(config(reference=short))
    long = {"kind": "length bar", "length_mm": 400.0, "u_mm": 0.001}
    with pytest.raises(BadInput, match=r"a reference of 400 mm cannot span 200.250..370.250 mm "
                                       r"within the soft limits \[200.250, 380.250\]"):
        planned(config(reference=long))


def test_a_test_that_would_leave_the_soft_limits_is_refused() -> None:
    cfg = config()
    plan = build_plan(cfg)
    with pytest.raises(BadInput, match=r"^plan: move to joint x datum, in the station's test "
                                       r"of joint x: ρ_x = 150.000 mm is outside the soft "
                                       r"limits"):
        plan_station_test(cfg, plan, LIMITS, MotionChecker(cfg, LIMITS), start=(150.0, L, L))


def test_a_test_that_would_leave_the_workspace_is_refused() -> None:
    # a short-legged machine and a bar longer than its travel: joint x alone 150 mm
    # out from Π0, the others at L, takes the end point beyond the legs' reach
    data = station_data(machine={"leg_length": 200.0, "workspace": [[-60, 60]] * 3},
                        controller={"motion": "coordinated"},
                        joints={"station_test": ["x"], "reference": {
                            "kind": "length bar", "length_mm": 300.0, "u_mm": 0.0005}})
    cfg = parse_config(data)
    wide = ([0.0] * 3, [1000.0] * 3)
    with pytest.raises(BadInput, match=r"^plan: move to joint x ρ=350.000 \(face 1\), in the "
                                       r"station's test of joint x: outside the machine's "
                                       r"workspace; nothing has moved"):
        plan_station_test(cfg, build_plan(cfg), wide, MotionChecker(cfg, wide),
                          start=(200.0, 200.0, 200.0))


# --- the operator's words and the picture -------------------------------------------------------


def test_the_prompts_say_what_to_do_at_each_step() -> None:
    jp = planned(config(joints=("x",))).of("x")
    steps = jp.steps()
    mount = joint_instruction(steps[1], jp, ["B"], "run/joint-test-x.svg")
    assert mount.startswith("joint x's own test: the machine is at ρ_x = 200.250 mm (its "
                            "datum), the other joints at Π0. Take B off.")
    assert "picture: run/joint-test-x.svg" in mount
    assert "gauge A: clamped to carriage x, its plunger along the axis pointing toward " \
           "lower ρ, onto the datum face; push in 0.37–12.08 mm" in mount
    faces = [s for s in steps if isinstance(s, FaceSet)]
    assert joint_instruction(faces[2], jp, ["B"]) == (
        "joint x, target 3 of 7: lift the plunger, set a stack of gauge blocks of 77.157 mm "
        "on the stop, lower the plunger onto it (ρ_x = 277.457 mm now)")
    assert "the datum again, read for the drift" in joint_instruction(faces[-1], jp, ["B"])
    assert "no stack: the plunger on the stop" in joint_instruction(faces[-1], jp, ["B"])
    assert joint_instruction(steps[-1], jp, ["B"]) == (
        "joint x's own test is done: take gauge A off carriage x and the gauge blocks off the "
        "base")
    bar = JointTestPlan(**{**jp.__dict__, "reference": "length bar", "faces": (0.0, 175.0),
                           "targets": (202.75, 377.75), "sides": ((True, True),) * 2})
    assert "the length bar (175.000 mm) on the stop" in joint_instruction(
        FaceSet("x", 1, 175.0), bar, [])


def test_the_picture_draws_the_rail_the_gauge_and_every_face() -> None:
    jp = planned(config(joints=("x",))).of("x")
    svg = draw(jp, 12.5, 6.25)
    root = ElementTree.fromstring(svg)
    assert root.get("data-joint") == "x"
    parts = [e.get("data-part") for e in root.iter() if e.get("data-part")]
    for part in ("rail", "carriage", "plunger", "body", "datum face", "window"):
        assert part in parts, part
    targets = [e for e in root.iter() if e.get("data-part") == "target"]
    assert [float(e.get("data-face")) for e in targets] == pytest.approx(jp.faces, abs=5e-4)
    window = next(e for e in root.iter() if e.get("data-part") == "window")
    assert window.get("data-window") == "0.37-12.08"
    # the plunger runs from the gauge toward lower ρ, to the datum face (left of the body)
    plunger = next(e for e in root.iter() if e.get("data-part") == "plunger")
    assert float(plunger.get("x2")) < float(plunger.get("x1"))
