"""The station's own test of the joints in a run (station.engine.joint_station; docs/
design.md, "The station's own joint test"): on a machine whose screws have leads of
+100, −80, +60 µm/m and lost motion, the test before the calibration finds each lead
within 10 µm/m and the reversal the joints have; result.json states the tables as
source "station", which the exports put into the controller; a run cut off in the
middle of a joint's test resumes, replaying the joints done and taking the cut one
again from its mounting (the command line's, wire and SIGKILL included:
tests/station/commands/test_joint_test_cli.py)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import FAST
from fakes import FakeRig, fake_config, resume_on, run_on
from jsonschema import Draft202012Validator

from orthocal import lead_um_per_m
from station.config.joint_reference import ReferenceConfig
from station.config.joint_tests import JointsConfig
from station.console.operator import VirtualOperator
from station.errors import RunFailed
from station.record import schema_files
from station.record.controller_tables import controller_tables
from station.record.io import read_result
from station.record.journal_file import JOURNAL_NAME, read_journal

LEADS = (100.0, -80.0, 60.0)
BACKLASH = (0.006, 0.0, 0.004)
DRHO = (0.6, -0.4, 0.9)
WITHIN_UM_PER_M = 10.0
# The seeds of the runs below: each a fixed draw of the gauges' 1 µm noise.
SEED = 21
RESUME_SEED = 22


def config(repeats: int = 3):
    reference = ReferenceConfig(kind="gauge blocks", u_mm=0.0005, temperature_c=20.0)
    joints = JointsConfig(station_test=["x", "y", "z"], station_repeats=repeats,
                          reference=reference)
    procedure = {**FAST, "readings": 5, "max_iterations": 1, "verify": False}
    return fake_config(**procedure).model_copy(update={"joints": joints})


def rig(seed: int) -> FakeRig:
    return FakeRig(true_drho=DRHO, joint_lead=LEADS, backlash=BACKLASH, noise_mm=0.001,
                   seed=seed)


def journal_of(result: dict[str, Any]) -> list[dict[str, Any]]:
    return list(read_journal(Path(result["run_dir"]) / JOURNAL_NAME))


def assert_leads_found(joints: dict[str, Any]) -> None:
    for axis, k in zip("xyz", LEADS, strict=True):
        j = joints[axis]
        assert j["source"] == "station" and j["file"] is None
        assert k - WITHIN_UM_PER_M < j["lead_um_per_m"] < k + WITHIN_UM_PER_M, (axis, j)
        lo, hi = j["lead_interval_95_um_per_m"]
        assert lo < k < hi, (axis, lo, hi)


def test_the_run_finds_each_joints_lead_and_states_it(tmp_path: Path) -> None:
    code, result = run_on(rig(SEED), tmp_path / "runs", config())
    assert code in (0, 3) and result["status"] == "ok", result.get("message")
    on_disk = json.loads((Path(result["run_dir"]) / "result.json").read_text())
    doc = json.loads(schema_files.shipped("result"))
    assert [e.message for e in Draft202012Validator(doc).iter_errors(on_disk)] == []
    joints = on_disk["joints"]
    assert_leads_found(joints)
    assert joints["assumed"] == []
    for axis in "xyz":
        table, test = joints[axis]["table"], joints[axis]["station_test"]
        assert table["targets_mm"][0] == 200.25 and table["targets_mm"][-1] == 370.25
        # referred to Π0: its bidirectional mean at L is 0, its reversal the run's B
        mean = (np.add(table["forward_um"], table["reverse_um"]) / 2)
        assert np.interp(310.25, table["targets_mm"], mean) == pytest.approx(0.0, abs=1e-9)
        assert table["reversal_from"] == "station" and len(table["u95_um"]) == 8
        assert test["reference"] == "gauge blocks" and test["gauge"] == "A"
        assert test["repeats"] == 3 and test["noise_dof"] > 20
        assert 0.0003 < test["noise_um"] / 1e3 < 0.0008  # 1 µm gauges, 5 readings a mean
        assert abs(test["drift_um"]) < 2.0
        assert set(test["u_um"]) == {"reference", "gauge", "temperature", "noise"}
        assert test["inferred"] and test["inferred"][0].startswith("ρ = 200.250 mm from below")
    # the test's own reversal is the joints' lost motion (−B at every target)
    records = {r["joint"]: r for r in journal_of(result) if r["type"] == "joint-test"}
    assert sorted(records) == ["x", "y", "z"]
    for axis, b in zip("xyz", BACKLASH, strict=True):
        r = records[axis]
        reversal = np.subtract(r["forward_um"], r["reverse_um"])[1:]  # the datum's inferred
        assert np.mean(reversal) == pytest.approx(-1e3 * b, abs=0.6)
        assert np.all(np.abs(reversal + 1e3 * b) < 2.0)
    # what the exports and compensate put into the controller: the station's tables,
    # moved into the joints the controller commands after the run's write-back
    tables = controller_tables(read_result(Path(result["run_dir"]) / "result.json"))
    for joint, k in zip(tables.joints, LEADS, strict=True):
        assert joint.source == "station" and joint.table is not None
        assert lead_um_per_m(joint.table).value_um_per_m == pytest.approx(
            joints[joint.axis]["lead_um_per_m"], abs=1e-6)
        assert abs(lead_um_per_m(joint.table).value_um_per_m - k) < WITHIN_UM_PER_M
    # three mountings of the test, then the calibration's own; the pictures drawn
    assert result["timing"]["mountings"] >= 3 + 3
    for axis in "xyz":
        assert (Path(result["run_dir"]) / f"joint-test-{axis}.svg").is_file()


class Interrupted(FakeRig):
    """A rig whose operator is interrupted (Ctrl-C) while setting joint y's third face."""

    def operator(self) -> VirtualOperator:
        rig = self

        class Hands:
            def mount_joint_gauge(self, name: str, axis: str, plunger: int) -> None:
                rig.mount_joint_gauge(name, axis, plunger)

            def set_face(self, axis: str, face_mm: float) -> None:
                rig.faces += 1 if axis == "y" else 0
                if axis == "y" and rig.faces == 3:
                    raise KeyboardInterrupt
                rig.set_face(axis, face_mm)

            def remove_reference(self, axis: str) -> None:
                rig.remove_reference(axis)

        return VirtualOperator(self.mount, self.unmount, joint_hands=Hands())


def test_a_run_cut_off_in_a_joints_test_resumes_it_from_its_mounting(tmp_path: Path) -> None:
    cut = Interrupted(true_drho=DRHO, joint_lead=LEADS, backlash=BACKLASH, noise_mm=0.001,
                      seed=RESUME_SEED)
    cut.faces = 0
    cfg = config(repeats=2)
    with pytest.raises(RunFailed, match="aborted by the operator"):
        run_on(cut, tmp_path / "runs", cfg)
    run_dir = next((tmp_path / "runs").iterdir())
    before = list(read_journal(run_dir / JOURNAL_NAME))
    assert [r["joint"] for r in before if r["type"] == "joint-test"] == ["x"]
    assert [r["joint"] for r in before if r["type"] == "joint-mount"] == ["x", "y"]
    assert any(r["type"] == "reading" and r["stop"].startswith("j:y:") for r in before)
    # resumed on the same machine (its counts and carriages where the cut left them)
    code, result = resume_on(cut, run_dir, cfg)
    assert code in (0, 3) and result["status"] == "ok", result.get("message")
    after = journal_of(result)
    assert after[:len(before)] == before  # the journal only grew
    tested = [r["joint"] for r in after if r["type"] == "joint-test"]
    mounted = [r["joint"] for r in after if r["type"] == "joint-mount"]
    assert tested == ["x", "y", "z"]  # x replayed, not measured again
    assert mounted == ["x", "y", "y", "z"]  # y's test taken again from its mounting
    assert_leads_found(result["joints"])
