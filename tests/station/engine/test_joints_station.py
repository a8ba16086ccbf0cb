"""Every run's result.json states each joint's positioning error as the run took it
(``joints``, station.analysis.joints): a shop's test where the config gives one, its
reversal replaced by the lost motion the run measured, the others assumed within the
stated bound; the section validates against the shipped schema."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from builders import FAST
from fakes import FakeRig, fake_config, run_on
from jsonschema import Draft202012Validator

import orthocal
from orthocal.accuracy import error_field
from orthocal.joint_error import lead_table
from station.config import load_config
from station.config.joint_tests import JointsConfig
from station.plan.joint_travel import check_joint_tests
from station.plan.steps import build_plan
from station.record import schema_files

L = orthocal.Geometry().leg_length
LEAD = (100.0, -80.0, 60.0)
BACKLASH = (0.006, 0.0, 0.004)


def laser_test(path: Path, k_um_per_m: float) -> None:
    """The joint's test as a laser would give it: 10 mm targets over the travel, 0.5 µm,
    the screw's lead both ways and a 5 µm reversal (the test's, another day's)."""
    rows = ["target_mm,forward_um,reverse_um,u_um"]
    for t in np.arange(170.0, 381.0, 10.0):
        e = k_um_per_m * 1e-3 * (t - L)
        rows.append(f"{t:g},{e - 2.5:.4f},{e + 2.5:.4f},0.5")
    path.write_text("\n".join(rows) + "\n")


def test_a_runs_joints_are_the_shops_test_with_the_measured_reversal(tmp_path: Path) -> None:
    laser_test(tmp_path / "x.csv", LEAD[0])
    config = fake_config(uncertainty={"joint_positioning_um_per_m": 120.0}, **FAST,
                         max_iterations=2).model_copy(
        update={"joints": JointsConfig(tests={"x": str(tmp_path / "x.csv")})})
    rig = FakeRig(true_drho=(0.4, -0.3, 0.2), backlash=BACKLASH, joint_lead=LEAD)
    code, result = run_on(rig, tmp_path / "runs", config)
    assert code in (0, 3) and result["status"] == "ok", result.get("message")
    doc = json.loads(schema_files.shipped("result"))
    on_disk = json.loads((Path(result["run_dir"]) / "result.json").read_text())
    for record in (result, on_disk):
        errors = [e.message for e in Draft202012Validator(doc).iter_errors(record)]
        assert errors == []
    j = on_disk["joints"]
    assert j["x"]["source"] == "test" and j["x"]["file"] == str(tmp_path / "x.csv")
    assert j["x"]["lead_um_per_m"] == pytest.approx(100.0, abs=1e-6)
    lo, hi = j["x"]["lead_interval_95_um_per_m"]
    assert lo < 100.0 < hi and hi - lo < 20.0
    table = j["x"]["table"]
    assert table["targets_mm"][0] == 170.0 and table["u95_um"][0] == 0.5
    # the run measured joint x's lost motion: it replaces the test's 5 µm
    assert table["reversal_from"] == "station"
    measured = result["reversal"]["value_mm"]["x"]
    assert measured == pytest.approx(BACKLASH[0], abs=0.0015)
    reversal = np.subtract(table["forward_um"], table["reverse_um"])
    assert reversal == pytest.approx([-1e3 * measured] * len(reversal), abs=1e-9)
    # the table's mean is the test's, referred to Π0
    mean = np.add(table["forward_um"], table["reverse_um"]) / 2
    assert mean == pytest.approx(0.1 * (np.array(table["targets_mm"]) - L), abs=1e-9)
    for axis in "yz":
        assert j[axis]["source"] == "assumed" and j[axis]["table"] is None
        assert j[axis]["bound_um_per_m"] == 120.0
        assert j[axis]["lead_interval_95_um_per_m"] == pytest.approx([-114.0, 114.0])
    assert j["bound"]["value"] == 120.0 and j["bound"]["given"] is True
    assert j["assumed"] and j["assumed"][0].startswith("joint(s) y, z:")
    # the run directory keeps its copy of the test: it resumes whatever becomes of the file
    run_dir = Path(result["run_dir"])
    assert (run_dir / "joint_test_x.csv").read_text() == (tmp_path / "x.csv").read_text()
    (tmp_path / "x.csv").unlink()
    again = load_config(run_dir / "config.toml")
    assert again.joints.tests == {"x": str(run_dir / "joint_test_x.csv")}
    check_joint_tests(again, build_plan(again))
    # the hidden machine's screws are named beside it
    sim = on_disk["simulation"]
    assert [sim["joint_lead_um_per_m"][a] for a in "xyz"] == list(LEAD)
    assert sim["joint_pitch_um"] == 0.0
    the_statement_carries_the_joints(on_disk)


def the_statement_carries_the_joints(result: dict) -> None:
    """x's lead where its test knows it, decided; y and z within the stated bound, no
    lead; the identification says what it made of them; the tool after the offsets,
    the screws in the truth, within its 95 % intervals."""
    q = {x["name"]: x for x in result["statement"]}
    assert q["lead_x"]["unit"] == "µm/m" and q["lead_x"]["decision"] == "compensate"
    assert "lead_y" not in q and "lead_z" not in q
    said = result["joints"]["in_identification"]
    assert said.startswith("the deviations were corrected for what the tables of joint(s) x")
    assert "joint(s) y, z: a lead within ±120 µm/m" in said
    assert result["model_selection"]["allowance"]["joint_lead_um_per_m"]["y"] == 120.0
    compensated = result["accuracy"]["compensated"]
    assert compensated["route"] == "kinematics+tables"
    basis = " ".join(q["tool.after.rms"]["basis"])
    assert "joint y: not compensated, a lead within ±120 µm/m from Π0 (stated" in basis
    # the truth: the hidden machine in the joints commanded after the run, its screws
    # homed at Π0 before it (the offsets written move the carriages on them)
    acc, sim = result["accuracy"], result["simulation"]
    o = np.array([result["offsets_final"][a] - result["offsets_before"][a] for a in "xyz"])
    truth = np.zeros(12)
    truth[:3] = [sim["true_drho"][a] + o[i] for i, a in enumerate("xyz")]
    screws = orthocal.JointErrors(*(lead_table(k, (100.0, 450.0), L - o[i])
                                    for i, k in enumerate(LEAD)))
    field = error_field(np.asarray(acc["field"]["points_mm"]), orthocal.Geometry(), truth,
                        None, acc["frame"], joint_errors=screws)
    for stat, true in (("rms", field.rms_mm), ("max", field.max_mm)):
        lo, hi = q[f"tool.after.{stat}"]["interval_95"]
        assert lo <= true <= hi, (stat, lo, true, hi)
