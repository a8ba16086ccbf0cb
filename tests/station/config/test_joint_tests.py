"""What the shop knows of its joints, in the station config (station.config.joint_tests,
station.plan.joint_travel): the ISO 230-2 test files of ``[joints] tests``, read
purely and refused in one line naming the file and the line; the travel a test must
span, checked with the plan before anything moves; ``[uncertainty]
joint_positioning_um_per_m``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from builders import station_data

import orthocal
from station.commands import cli
from station.config import load_config, parse_config
from station.config.joint_tests import parse_joint_test, read_joint_test
from station.config.toml import dump_toml, toml_text
from station.errors import BadInput
from station.plan.joint_travel import check_joint_tests, needed_travel
from station.plan.steps import build_plan

G = orthocal.Geometry()
L = G.leg_length
#: What the default workspace [−100, 60]³ needs: its far corner through the IK, and
#: Π_i^+ (the same as the box's (60, 0, 0)).
LO = -100.0 + np.sqrt(L**2 - 2 * 100.0**2)
HI = L + 60.0


def csv_text(lo: float = 170.0, hi: float = 380.0, step: float = 10.0, u: bool = True,
             k_um_per_m: float = 100.0) -> str:
    rows = ["target_mm,forward_um,reverse_um" + (",u_um" if u else "")]
    for t in np.arange(lo, hi + step / 2, step):
        e = k_um_per_m * 1e-3 * (t - L)
        rows.append(f"{t:g},{e - 2:.3f},{e + 2:.3f}" + (",0.5" if u else ""))
    return "\n".join(rows) + "\n"


# --- the file --------------------------------------------------------------------------


def test_a_test_file_reads_whatever_the_order_of_its_columns() -> None:
    text = ("\ufeff# a laser test, 2026-01-12\n"
            "reverse_um, target_mm ,u_um,forward_um\n"
            "\n"
            "3.0,200,0.5,1.0\n"
            "# the middle\n"
            "4.5,300.5,0.6,2.5\n"
            "6,400,0.7,4\n")
    test = parse_joint_test(text, "x.csv")
    assert test.targets_mm == (200.0, 300.5, 400.0)
    assert test.forward_um == (1.0, 2.5, 4.0) and test.reverse_um == (3.0, 4.5, 6.0)
    assert test.u_um == (0.5, 0.6, 0.7)
    assert test.lines == (4, 6, 7)
    plain = parse_joint_test("target_mm,forward_um,reverse_um\n1,0,0\n2,0,0\n", "y.csv")
    assert plain.u_um is None and plain.lines == (2, 3)


@pytest.mark.parametrize("text, said", [
    ("target_mm,forward_um\n1,2\n", "x.csv: line 1: the header lacks reverse_um"),
    ("target_mm,forward_um,reverse_um,temp_c\n1,2,3,20\n",
     "x.csv: line 1: unknown column 'temp_c'"),
    ("target_mm,forward_um,reverse_um,forward_um\n", "x.csv: line 1: a column is named twice"),
    ("target_mm,forward_um,reverse_um\n200,1,2\n210,1\n",
     "x.csv: line 3: 2 values where the header names 3"),
    ("target_mm,forward_um,reverse_um\n200,1,2\n210,1,2,3\n",
     "x.csv: line 3: 4 values where the header names 3"),
    ("target_mm,forward_um,reverse_um\n200,1,2\n210,one,2\n",
     "x.csv: line 3: forward_um is not a number: 'one'"),
    ("target_mm,forward_um,reverse_um\n200,1,2\n210,1,nan\n",
     "x.csv: line 3: reverse_um is not a finite number: 'nan'"),
    ("target_mm,forward_um,reverse_um\n200,1,2\n210,inf,2\n",
     "x.csv: line 3: forward_um is not a finite number"),
    ("target_mm,forward_um,reverse_um\n200,1,2\n,1,2\n",
     "x.csv: line 3: target_mm is not a number: ''"),
    ("target_mm,forward_um,reverse_um\n200,1,2\n200,1,2\n",
     "x.csv: line 3: target_mm 200 does not follow 200"),
    ("target_mm,forward_um,reverse_um\n200,1,2\n\n# cut\n190,1,2\n",
     "x.csv: line 5: target_mm 190 does not follow 200"),
    ("target_mm,forward_um,reverse_um,u_um\n200,1,2,0.5\n210,1,2,-0.5\n",
     "x.csv: line 3: u_um must be >= 0"),
    ("target_mm,forward_um,reverse_um\n200,1,2\n", "x.csv: 1 target(s): a test needs at least two"),
    ("# nothing\n\n", "x.csv: empty: expected the header"),
])
def test_a_bad_test_file_is_one_line_naming_the_file_and_the_line(text: str, said: str) -> None:
    with pytest.raises(BadInput) as info:
        parse_joint_test(text, "x.csv")
    message = str(info.value)
    assert message.startswith(said) and "\n" not in message, message


def test_a_file_read_again_after_it_changed_is_its_new_text(tmp_path: Path) -> None:
    path = tmp_path / "x.csv"
    path.write_text(csv_text())
    assert read_joint_test(str(path)).targets_mm[0] == 170.0
    path.write_text(csv_text(lo=160.0))
    assert read_joint_test(str(path)).targets_mm[0] == 160.0
    with pytest.raises(BadInput, match="no such file"):
        read_joint_test(str(tmp_path / "none.csv"))


# --- the config ------------------------------------------------------------------------


def write_station(folder: Path, **sections: object) -> Path:
    path = folder / "station.toml"
    path.write_text(toml_text(station_data(**sections)))
    return path


def test_the_tests_paths_are_the_configs_folders_and_survive_the_run_dirs_copy(
        tmp_path: Path) -> None:
    (tmp_path / "laser").mkdir()
    (tmp_path / "laser" / "x.csv").write_text(csv_text())
    (tmp_path / "laser" / "z.csv").write_text(csv_text(k_um_per_m=60.0))
    path = write_station(tmp_path, joints={"tests": {"x": "laser/x.csv", "z": "laser/z.csv"}},
                         uncertainty={"joint_positioning_um_per_m": 120.0})
    config = load_config(path)
    assert config.joints.tests == {"x": str(tmp_path / "laser" / "x.csv"),
                                   "z": str(tmp_path / "laser" / "z.csv")}
    assert config.uncertainty.joint_positioning_um_per_m == 120.0
    # the run directory keeps the config as TOML: it reads back equal from anywhere
    copy = tmp_path / "run" / "config.toml"
    copy.parent.mkdir()
    copy.write_text(dump_toml(config))
    assert load_config(copy) == config
    # no test given: no [joints] written, as before
    assert "[joints]" not in dump_toml(parse_config(station_data()))


@pytest.mark.parametrize("sections, said", [
    ({"joints": {"test": {"x": "x.csv"}}}, "joints.test: unknown key"),
    ({"joints": {"tests": {"w": "x.csv"}}}, "joints.tests.w"),
    ({"joints": {"tests": {"x": " "}}}, "joints.tests.x: an empty path"),
    ({"uncertainty": {"joint_positioning_um_per_m": -1}},
     "uncertainty.joint_positioning_um_per_m: must be >= 0"),
    ({"uncertainty": {"joint_positioning_um_per_m": 1e5}},
     "uncertainty.joint_positioning_um_per_m: must be <= 10000"),
])
def test_a_bad_joints_key_is_one_line_naming_the_field(
        tmp_path: Path, sections: dict, said: str) -> None:
    path = write_station(tmp_path, **sections)
    with pytest.raises(BadInput) as info:
        load_config(path)
    assert str(info.value).startswith(f"{path}: {said}"), info.value
    assert "\n" not in str(info.value)


def test_a_bad_row_stops_the_command_as_the_config_loads(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "y.csv").write_text("target_mm,forward_um,reverse_um\n200,1,2\n210,1,x\n")
    path = write_station(tmp_path, joints={"tests": {"y": "y.csv"}})
    code = cli.main(["run", "--config", str(path), "--plan"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert f"{tmp_path / 'y.csv'}: line 3: reverse_um is not a number: 'x'" in err
    (tmp_path / "y.csv").unlink()
    assert cli.main(["run", "--config", str(path), "--plan"]) == 2
    assert f"{tmp_path / 'y.csv'}: no such file" in capsys.readouterr().err


# --- the travel a test must span -------------------------------------------------------


def config_with(tmp_path: Path, text: str, axis: str = "x", **sections: object):
    (tmp_path / f"{axis}.csv").write_text(text)
    return load_config(write_station(tmp_path, joints={"tests": {axis: f"{axis}.csv"}},
                                     **sections))


def test_the_travel_needed_is_the_workspace_and_the_postures(tmp_path: Path) -> None:
    config = parse_config(station_data())
    lo, hi, why = needed_travel(config, build_plan(config))
    assert lo == pytest.approx([LO] * 3) and hi == pytest.approx([HI] * 3)
    assert why[0].startswith("the workspace box")
    assert why[3] == "the test postures"  # Π_i^+ and the box's (60, 0, 0) alike
    # the tool is stated nowhere beyond the soft limits
    lo, hi, why = needed_travel(config, build_plan(config), ([200.25] * 3, [380.25] * 3))
    assert lo == pytest.approx([200.25] * 3) and why[0].startswith("the workspace box")
    lo, hi, why = needed_travel(config, build_plan(config), ([215.0] * 3, [380.25] * 3))
    assert lo == pytest.approx([L - 100.0] * 3) and why[0] == "the test postures"
    # a smaller workspace: the postures again
    small = parse_config(station_data(machine={"workspace": [[-20, 20]] * 3}))
    lo, hi, _ = needed_travel(small, build_plan(small))
    assert lo == pytest.approx([L - 100.0] * 3) and hi == pytest.approx([L + 60.0] * 3)


def test_a_test_that_spans_the_travel_passes(tmp_path: Path) -> None:
    config = config_with(tmp_path, csv_text(lo=170.0, hi=380.0))
    check_joint_tests(config, build_plan(config))


def test_a_test_short_of_the_workspace_is_refused_naming_its_first_line(tmp_path: Path) -> None:
    config = config_with(tmp_path, "# laser\n" + csv_text(lo=200.0, hi=380.0), "y")
    with pytest.raises(BadInput) as info:
        check_joint_tests(config, build_plan(config))
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'y.csv'}: line 3: the test of joint y starts at "
                              f"200 mm; the run needs it from {LO:.3f} mm (the workspace box "
                              "through the inverse kinematics)"), message
    assert "Π0 at ρ = L = 310.25 mm" in message and "\n" not in message
    # the soft limits cut the workspace's travel to the postures', which it spans
    check_joint_tests(config, build_plan(config), ([200.0] * 3, [380.25] * 3))


def test_a_test_short_of_a_posture_is_refused_naming_its_last_line(tmp_path: Path) -> None:
    config = config_with(tmp_path, csv_text(lo=170.0, hi=360.0), "z")
    with pytest.raises(BadInput, match=r"z\.csv: line 21: the test of joint z ends at 360 mm; "
                                       r"the run needs it up to 370\.250 mm \(the test "
                                       r"postures\)"):
        check_joint_tests(config, build_plan(config))
    # targets counted from home, not from the station's ρ: the message says what ρ is
    rel = config_with(tmp_path, csv_text(lo=0.0, hi=200.0), "z")
    with pytest.raises(BadInput, match="absolute, Π0 at ρ = L"):
        check_joint_tests(rel, build_plan(rel))


def test_the_plan_check_refuses_it_before_anything_moves(tmp_path: Path) -> None:
    from fakes import FakeRig, fake_config, run_on

    (tmp_path / "x.csv").write_text(csv_text(lo=220.0))
    config = fake_config().model_copy(update={"joints": load_config(write_station(
        tmp_path, joints={"tests": {"x": "x.csv"}})).joints})
    rig = FakeRig(true_drho=(0.3, -0.2, 0.1))
    with pytest.raises(BadInput, match=r"x\.csv: line 2: the test of joint x starts at 220"):
        run_on(rig, tmp_path / "runs", config)
    assert rig.machine.moves_started == 0 and not (tmp_path / "runs").exists()
