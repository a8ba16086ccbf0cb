"""Accuracy at the tool in a whole run of the engine (on the Protocol-level fakes,
tests/helpers/fakes.py, in front of the virtual machine): the run states where the tool
goes before and after, with intervals that hold the hidden machine's truth, for
both objectives; objective "tool" writes the offsets that leave less tool error
than the paper's Δρ; the run directory exports the identified machine; misplaced
stands are modelled, not taken for tilt."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fakes import FakeRig, fake_config, run_on

from orthocal import AXES, Geometry
from orthocal.accuracy import error_field, optimal_offsets
from station import report
from station.commands.simulate.launch import DEFAULT_MOUNT_ERROR_MM
from station.config import parse_config
from station.errors import BadInput

TILT = (0.2, 0.1, -0.15)
DRHO = (0.5, -0.3, 0.8)


def run(out: Path, *, uncertainty: dict[str, Any] | None = None,
        writeback: dict[str, Any] | None = None, **machine: Any) -> dict[str, Any]:
    # What the engine states at the tool: its run on the Protocol-level fakes
    # (tests/helpers/fakes.py), 1 µm gauges, stands placed by eye as a simulated run's.
    rig = FakeRig(**{"seed": 5, "noise_mm": 0.001,
                     "mount_error_mm": DEFAULT_MOUNT_ERROR_MM, **machine})
    config = fake_config(uncertainty=uncertainty, writeback=writeback, settle_s=0.0,
                         cycles=2)
    code, result = run_on(rig, out, config)
    # completed: 0, or 3 where its closed loop did not converge (it says why)
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    return result


def true_after(result: dict[str, Any]) -> tuple[float, float]:
    """(true after-RMS with the offsets written, the best any offsets can do), from
    the hidden machine, over the grid the run stated its figures on."""
    sim, acc = result["simulation"], result["accuracy"]
    points = np.asarray(acc["field"]["points_mm"])
    truth = np.array([*(sim["true_drho"][a] for a in AXES), 0, 0, 0,
                      *sim["true_tilt"].values()])
    o = np.array([result["offsets_written"][a] - result["offsets_before"][a] for a in AXES])
    g = Geometry()
    return (error_field(points, g, truth, o, acc["frame"]).rms_mm,
            optimal_offsets(points, g, truth, acc["frame"]).field.rms_mm)


@pytest.fixture(scope="module")
def tilted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, Any]]:
    out = tmp_path_factory.mktemp("tilted")
    # The simulated legs are straight, and the config says so: tilts of 0.1-0.2 mrad
    # on two postures per leg are told apart from legs straight to 1 µm, not from
    # the default 10 µm.
    return {objective: run(out / objective, true_drho=DRHO, true_tilt=TILT,
                           writeback={"objective": objective},
                           uncertainty={"leg_straightness_mm": 0.001})
            for objective in ("joints", "tool")}


def test_a_tilted_machine_is_stated_at_the_tool_not_by_its_legs(tilted) -> None:
    result = tilted["joints"]
    acc = result["accuracy"]
    # the verification shows the legs as the model predicts them once Δρ is
    # written (to a few µm: the tilts' own deviations stay); the tool is off by
    # docs/model.md's 14 µm
    assert result["verification"]["vs_expected_rms_mm"] < 0.003
    assert 0.010 < acc["after"]["rms_mm"] < 0.018 and acc["before"]["rms_mm"] > 0.2
    lo, hi = acc["after"]["rms_interval_95_mm"]
    truth, _ = true_after(result)
    assert lo <= truth <= hi
    assert acc["objective"] == "joints" and acc["alternative"]["objective"] == "tool"
    assert acc["objectives"]["tool"]["after"]["rms_mm"] < 0.6 * acc["after"]["rms_mm"]
    # squareness ≈ the tilts (mm/m = mrad), with what to do about each
    for name, tilt in zip(("xy", "xz", "yz"), TILT, strict=True):
        assert acc["squareness_mm_per_m"][name] == pytest.approx(tilt, abs=0.05)
    assert all("shim" in line for line in acc["squareness_advice"])
    assert any("ΔL = 0" in line for line in acc["assumes"])


def test_objective_tool_beats_the_joints_and_nears_the_best_offsets(tilted) -> None:
    joints, _ = true_after(tilted["joints"])
    tool, best = true_after(tilted["tool"])
    assert tool < 0.7 * joints
    assert tool <= 1.1 * best
    acc = tilted["tool"]["accuracy"]
    lo, hi = acc["after"]["rms_interval_95_mm"]
    assert lo <= tool <= hi
    # the verification is judged against the deviations predicted for the target,
    # not against zero: the loop does not chase the target back to Δρ = 0
    its = tilted["tool"]["iterations"]
    assert all("target_drho" in it for it in its if it["offsets_written"])
    target = [it for it in its if it["offsets_written"]][-1]["target_drho"]
    assert max(abs(v) for v in target.values()) > 0.01
    remaining = tilted["tool"]["remaining"]["estimate"]
    se = tilted["tool"]["remaining"]["std_errors"]
    for name, aim in target.items():
        # what is left from the target is no correction by the loop's own rule
        # (orthocal.loop.significant_corrections: k ≤ 4.18 over the noise of two
        # measurements), and far from what chasing Δρ = 0 would leave
        assert abs(remaining[name] - aim) < 4.18 * math.sqrt(2) * se[name]
        if abs(aim) > 0.01:
            assert abs(remaining[name] - aim) < 0.5 * abs(aim)


def test_the_tilted_axes_are_told_to_be_shimmed(tilted) -> None:
    acc = tilted["joints"]["accuracy"]
    k = acc["squareness_decision"]["k"]
    assert 3.0 < k < 6.0 and "one false alarm in a thousand" in \
        acc["squareness_decision"]["rule"]
    # 0.2, 0.1 and -0.15 mrad, each far beyond k standard errors
    assert sum("shim its rail" in a for a in acc["squareness_advice"]) == 3


def test_the_run_directory_exports_the_identified_machine(tilted) -> None:
    result = tilted["joints"]
    model = json.loads((Path(result["run_dir"]) / "model.json").read_text())
    assert model["units"] == {"drho": "mm", "dL": "mm", "tilt": "mrad", "gap": "mm"}
    # the gaps too: the run's rho+tilt+gap fits measured them (near 0 on this machine)
    assert set(model["estimated"]) == {"drho_x", "drho_y", "drho_z", "tilt_yx", "tilt_zx",
                                       "tilt_zy", "gap_xy", "gap_xz", "gap_yz"}
    assert "gap_xy" in model["conventions"]["gaps"]
    for n in ("gap_xy", "gap_xz", "gap_yz"):
        assert abs(model["parameters"][n]) < 4 * model["std_errors"][n] + 0.002
    for axis, true in zip(AXES, DRHO, strict=True):
        assert model["parameters"][f"drho_{axis}"] == pytest.approx(true, abs=0.005)
    for name, true in zip(("tilt_yx", "tilt_zx", "tilt_zy"), TILT, strict=True):
        assert model["parameters"][name] == pytest.approx(true, abs=0.04)
    cov = np.asarray(model["covariance"]["matrix"])
    assert cov.shape == (9, 9) and np.allclose(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert "dL_x" in model["not_estimated"]


def test_a_square_machine_with_its_offsets_written_leaves_nothing_at_the_tool(
        tmp_path: Path) -> None:
    # the legs' straightness stated (2 µm): what the legs' form may hide as tilts is
    # then small, and the interval a useful size
    result = run(tmp_path, true_drho=(1.2, -0.8, 0.6),
                 uncertainty={"leg_straightness_mm": 0.002})
    acc = result["accuracy"]
    truth, best = true_after(result)
    assert best < 1e-6 and truth < 0.002
    lo, hi = acc["after"]["rms_interval_95_mm"]
    assert lo <= truth <= hi and hi < 0.006
    assert any("carry the legs' form (straightness 0.002 mm, stated)" in line
               for line in acc["assumes"])
    # auto kept a model without tilt, from the first round on (the misplaced stands
    # are modelled, not taken for tilt): the tilts it could not rule out are said
    assert result["model_selection"]["model"] == "rho" and result["model"] == "rho"
    assert acc["tilt_interval_95"] is not None
    assert any("not significant" in line for line in acc["assumes"])
    # and no rail to shim: no axis leans beyond k_act combined uncertainties (the
    # decision table's one rule), and the section's advice is the statement's
    decided = {q["name"]: q["decision"] for q in result["statement"]}
    assert [decided[f"tilt_{t}"] for t in ("yx", "zx", "zy")] == ["none"] * 3
    assert acc["squareness_decision"]["k"] > 3.0
    assert acc["squareness_advice"] == [] and not any(
        a["id"].startswith("shim.") for a in result["advice"])
    # where each stand was (default: placed by eye, up to 5 mm off)
    assert result["stands"] and all("observable" in s for s in result["stands"].values())


def test_the_new_config_keys_are_checked_and_named() -> None:
    base = {"indicators": [{"name": "A", "port": "/dev/a"}],
            "setups": [{"leg": "x", "indicators": {"A": "y"}}]}
    for section, bad, field in (("writeback", {"objective": "both"}, "writeback.objective"),
                                ("writeback", {"frame": "affine"}, "writeback.frame"),
                                ("machine", {"workspace": [[0, 1], [0, 1]]}, "workspace"),
                                ("procedure", {"stand_tolerance_mm": -1}, "stand_tolerance")):
        with pytest.raises(BadInput) as info:
            parse_config({**base, section: bad})
        assert field in str(info.value) and "\n" not in str(info.value)
