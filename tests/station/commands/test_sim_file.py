"""``orthocal run --simulate SIM.toml``: the virtual machine a file describes, its
keys the options without their dashes, the command line winning over it; a wrong
key or value one line naming the file and the key, exit 2, before anything starts."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator

from station.commands import cli
from station.commands.options import RunOptions
from station.commands.simulate.file_options import run_options
from station.commands.simulate.launch import sim_params
from station.record import schema_files

SIM = """
[simulation]
seed = 7
true_drho = [0.7, -1.1, 0.35]
true_tilt = [0.05, 0, -0.03]
true_gap = [0.2, -0.1, 0.15]
noise = 0.0
mount_error = 0.0
backlash = [0.004, 0, 0.002]
leg_bow = 0.003
joint_lead = [100, -80, 60]
joint_pitch = [1.0, 5.0]

[simulation.drive]
motion = "independent"
profile = ["scurve", "cosine", "trapezoid"]
accel = 12000.0
delays = [0, 0.004, 0.008]

[procedure]
cycles = 2
readings = 3
settle_s = 0.0
max_extra_passes = 0

[report]
figures = false
"""


def options(*argv: str) -> RunOptions:
    return run_options(cli.build_parser().parse_args(["run", *argv]))


def test_the_file_gives_every_option_and_the_command_line_wins(tmp_path: Path) -> None:
    path = tmp_path / "sim.toml"
    path.write_text(SIM)
    sim = options("--simulate", str(path)).sim
    assert sim is not None
    params = sim_params(sim)
    assert params["seed"] == 7 and params["true_drho"] == [0.7, -1.1, 0.35]
    assert params["true_tilt"] == [0.05, 0.0, -0.03]
    assert params["true_gap"] == pytest.approx([0.2, -0.1, 0.15])
    assert params["backlash_mm"] == [0.004, 0.0, 0.002]
    assert params["leg_bow_mm"] == [0.003] * 3 and params["mount_error_mm"] == 0.0
    assert params["joint_lead_um_per_m"] == [100.0, -80.0, 60.0]
    assert params["joint_pitch"] == [1.0, 5.0]
    assert params["drive_profile"] == ["scurve", "cosine", "trapezoid"]
    assert params["drive_delays_s"] == [0.0, 0.004, 0.008]
    assert params["procedure"]["cycles"] == 2
    # the same file, with options given on the command line: those win, the rest stays
    over = sim_params(options("--simulate", str(path), "--seed", "9", "--true-drho",
                              "0,0,1", "--drive-profile", "cosine").sim)  # type: ignore[arg-type]
    assert over["seed"] == 9 and over["true_drho"] == [0.0, 0.0, 1.0]
    assert over["drive_profile"] == ["cosine"] * 3
    assert over["true_gap"] == params["true_gap"] and over["backlash_mm"] == [0.004, 0.0, 0.002]
    lead = sim_params(options("--simulate", str(path), "--joint-lead", "5").sim)  # type: ignore[arg-type]
    assert lead["joint_lead_um_per_m"] == [5.0] * 3 and lead["joint_pitch"] == [1.0, 5.0]
    # --simulate alone is the options alone, as before
    assert options("--simulate", "--seed", "3").sim.seed == 3  # type: ignore[union-attr]


def test_a_run_from_the_file_is_the_machine_it_describes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "sim.toml"
    path.write_text(SIM)
    code = cli.main(["run", "--simulate", str(path), "--yes", "--json",
                     "--out", str(tmp_path / "runs")])
    result = json.loads(capsys.readouterr().out)
    assert code in (0, 3) and result["status"] == "ok"
    sim = result["simulation"]
    assert sim["seed"] == 7
    assert [sim["true_drho"][a] for a in "xyz"] == [0.7, -1.1, 0.35]
    assert [sim["true_gap"][k] for k in ("gap_xy", "gap_xz", "gap_yz")] == \
        pytest.approx([0.2, -0.1, 0.15])
    assert [s["cycles_used"] for s in result["setups"]] == [2, 2, 2]  # [procedure]
    assert [sim["backlash_mm"][a] for a in "xyz"] == [0.004, 0.0, 0.002]
    assert [sim["leg_bow_mm"][a] for a in "xyz"] == [0.003] * 3
    assert sim["noise_mm"] == 0.0 and sim["mount_error_mm"] == 0.0
    assert [sim["true_tilt"][k] for k in ("tilt_yx", "tilt_zx", "tilt_zy")] == \
        [0.05, 0.0, -0.03]
    # the screws, and what the station took the joints to be: no test, the bound the
    # simulated station states of its screws (the largest lead and what the periodic
    # error makes per metre from home, 2π·A/P)
    assert [sim["joint_lead_um_per_m"][a] for a in "xyz"] == [100.0, -80.0, 60.0]
    assert (sim["joint_pitch_um"], sim["joint_pitch_period_mm"]) == (1.0, 5.0)
    joints = result["joints"]
    assert [joints[a]["source"] for a in "xyz"] == ["assumed"] * 3
    assert joints["bound"]["given"] is True
    assert joints["x"]["bound_um_per_m"] == pytest.approx(100.0 + 2e3 * math.pi / 5,
                                                          abs=1e-3)
    # the record validates against the schema the package ships, as another tool reads it
    schema = json.loads(schema_files.shipped("result"))
    (run_dir,) = (tmp_path / "runs").glob("run-*")
    on_disk = json.loads((run_dir / "result.json").read_text())
    assert [e.message for e in Draft202012Validator(schema).iter_errors(on_disk)] == []


@pytest.mark.parametrize(("text", "said"), [
    ("[simulation]\nnosie = 0.001\n", "simulation.nosie: unknown key"),
    ("[simulation]\nnoise = -1\n", "simulation.noise: must be >= 0"),
    ("[simulation]\ntrue_drho = [1, 2]\n", "simulation.true_drho"),
    ("[simulation]\nleg_bow = 5\n", "simulation.leg_bow: "),
    ("[simulation.drive]\nmotion = \"coordinated\"\nsequence = \"zyx\"\n",
     "simulation.drive.sequence: "),
    ("[simulation.drive]\nprofile = \"square\"\n", "simulation.drive.profile: "),
    ("[simulation]\nprofile = \"no-such-drive\"\n", "simulation.profile: "),
    ("[controller]\nport = 502\n", "controller: unknown key"),
    ("[procedure]\ncycles = 0\n", "procedure.cycles"),
    ("x = [\n", "not valid TOML"),
])
def test_a_bad_file_is_one_line_naming_the_key_and_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, said: str) -> None:
    path = tmp_path / "sim.toml"
    path.write_text(text)
    code = cli.main(["run", "--simulate", str(path), "--yes", "--out", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert said in err and "Traceback" not in err
    assert " --" not in err  # said in the file's words, not the options'
    assert not (tmp_path / "runs").exists()


def test_a_missing_file_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nowhere.toml"
    code = cli.main(["run", "--simulate", str(missing), "--yes", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and str(missing) in err and err.count("\n") == 1


def test_the_shipped_example_loads() -> None:
    example = Path(__file__).resolve().parents[3] / "examples" / "rehearsal.toml"
    params = sim_params(options("--simulate", str(example)).sim)  # type: ignore[arg-type]
    assert params["true_gap"] == pytest.approx([0.2, -0.1, 0.15])
    assert params["backlash_mm"] == [0.004] * 3 and params["motion"] == "independent"
