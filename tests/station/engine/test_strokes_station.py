"""``[procedure] strokes``: config validation, the plan and its check, and a whole
simulated run (with a fault and a resume) through intermediate stops Π_i(s)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import forked
import numpy as np
import pytest
from builders import FAST, no_figures_file, simulated, station_data
from close import assert_same

import orthocal
from station.commands import run as cmd_run
from station.config import parse_config
from station.errors import BadInput
from station.plan.check import check_plan
from station.plan.steps import Move, Read, build_plan
from station.record.journal_file import read_journal
from station.report import not_converged

WIDE = ([0.0, 0.0, 0.0], [1000.0, 1000.0, 1000.0])
STROKES = [-50.0, 60.0, 30.0, -100.0]


def config(strokes: list[float] | None = None, **machine: float):
    data = station_data(procedure={"cycles": 2, "readings": 3})
    if strokes is not None:
        data["procedure"]["strokes"] = strokes
    if machine:
        data["machine"] = machine
    return parse_config(data, "station.toml")


@pytest.mark.parametrize(
    ("strokes", "machine", "expected"),
    [
        ([30.0, 0.0], {}, "procedure.strokes: must be finite and nonzero, got 0"),
        ([30.0, 30.0], {}, "procedure.strokes: must be unique"),
        ([30.0, 70.0], {}, "procedure.strokes: 70 is outside [rho_min, rho_max] = [-100, 60]"),
        ([-90.0], {"rho_min": -80.0}, "procedure.strokes: -90 is outside"),
        ([], {}, "procedure.strokes: "),
    ],
)
def test_bad_strokes_are_one_line_naming_the_field(strokes, machine, expected) -> None:
    with pytest.raises(BadInput) as info:
        config(strokes, **machine)
    msg = str(info.value)
    assert msg.startswith("station.toml: ") and expected in msg and "\n" not in msg


def test_default_plan_is_unchanged_by_the_feature() -> None:
    """No strokes, or the paper's two spelled out: the same plan JSON as ever."""
    default = build_plan(config())
    spelled = build_plan(config([60.0, -100.0]))
    assert default.to_json() == spelled.to_json()
    assert "test_postures" not in default.to_json()
    assert [sp.order for sp in default.setups] == [("+", "-")] * 3
    assert "(Π0 → Π+ → Π− → Π0)" in default.format()


def test_strokes_plan_sweeps_out_and_back_through_every_stop() -> None:
    cfg = config(STROKES)
    plan = check_plan(build_plan(cfg), cfg, WIDE)
    g = cfg.machine.geometry()
    assert plan.to_json()["test_postures"] == ["+30", "+", "-50", "-"]
    steps = list(plan.steps())
    labels = [m.label for m in steps if isinstance(m, Move)]
    assert labels[:8] == ["Π0", "Π_x(+30)", "Π_x^+", "Π_x(-50)", "Π_x^-", "Π0",
                          "Π0 (other side)", "Π_x(+30)"]
    moves = {m.label: m.targets for m in steps if isinstance(m, Move)}
    np.testing.assert_allclose(moves["Π_y(-50)"], orthocal.posture("-50", "y", g))
    reads = [s for s in steps if isinstance(s, Read)]
    # per setup: the opening Π0 and five stops per cycle
    # per cycle the four strokes, Π0, and Π0 from the other side (the reversal)
    assert len(reads) == 3 * (1 + 6 * 2) and len({r.stop for r in reads}) == len(reads)
    assert "m:1:2:-50" in {r.stop for r in reads}
    assert "(Π0 → Π_i(+30) → Π_i^+ → Π_i(-50) → Π_i^- → Π0)" in plan.format()


def test_plan_check_refuses_a_stroke_outside_the_soft_limits() -> None:
    cfg = config([60.0, 30.0, -50.0, -100.0])
    g = cfg.machine.geometry()
    # A lower limit on ρ_z just above Π_z(-50): the first stop it refuses is Π_z(-50).
    lo_z = orthocal.posture("-50", "z", g)[2] + 1.0
    with pytest.raises(BadInput) as info:
        check_plan(build_plan(cfg), cfg, ([0, 0, lo_z], [1000, 1000, 1000]))
    assert "Π_z(-50)" in str(info.value) and "soft limits" in str(info.value)


PROCEDURE = {**FAST, "strokes": STROKES}
TRUE_DRHO = (0.7, -1.1, 0.5)


def run_argv(out: Path) -> list[str]:
    return ["run", "--simulate", no_figures_file(out.parent), "--seed", "11",
            "--true-drho", ",".join(map(str, TRUE_DRHO)),
            "--noise", "0", "--sim-procedure", json.dumps(PROCEDURE), "--sim-speed", "20000",
            # stands exact: every phase's cycles counted below
            "--mount-error", "0", "--yes", "--json", "--out", str(out)]


def test_simulated_run_with_strokes(tmp_path: Path, capsys) -> None:
    """Every stroke in the deviations, the journal and the report; the offsets
    come back and the verification is at the noise level."""
    args = simulated(tmp_path / "runs", seed=11, true_drho=TRUE_DRHO, procedure=PROCEDURE,
                     mount_error=0.0)
    code = cmd_run.run(args)
    result = json.loads(capsys.readouterr().out)
    # completed: 0, or 3 where its closed loop did not converge (it says why)
    assert code == (3 if not_converged(result) else 0), result.get("message")
    keys = set(result["deviations"])
    assert {"+30xy", "+xy", "-50xy", "-xy", "+30zy", "-50yz"} <= keys and len(keys) == 24
    for axis, true in zip("xyz", TRUE_DRHO, strict=True):
        err = result["identified"][f"drho_{axis}"] - true
        assert abs(err) <= 3 * result["std_errors"][f"drho_{axis}"] + 1e-4
    assert result["verification"]["deviations_rms_mm"] < 0.005
    run_dir = Path(result["run_dir"])
    records = read_journal(run_dir / "journal.jsonl")
    cycles = [r for r in records if r["type"] == "cycle"]
    assert set(cycles[0]["deviations"]) == {"+30xy", "+xy", "-50xy", "-xy",
                                            "+30xz", "+xz", "-50xz", "-xz"}
    phases = len(result["iterations"])  # every phase the closed loop measured
    assert sum(1 for r in records if r["type"] == "reading") == 2 * 3 * (1 + 6 * 2) * phases
    report = (run_dir / "report.html").read_text()
    assert "Π<sub>x</sub>(+30 mm) along y" in report and "Π<sub>y</sub>(−50 mm)" in report
    assert "4 test postures Π<sub>i</sub>(s)" in report and "the 24 differences" in report


KILLER = r"""
import json, os, signal, sys
import station.record.journal_file as journal
from station.commands.cli import main

real_append = journal.Journal.append
seen = [0]

def append(self, record):
    real_append(self, record)
    if record.get("type") == "cycle" and record.get("phase") == "m":
        seen[0] += 1
        if seen[0] == 3:  # the second setup's first cycle is on disk
            os.kill(os.getpid(), signal.SIGKILL)

journal.Journal.append = append
sys.exit(main(sys.argv[1:]))
"""


def station(argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "station", *argv], cwd=cwd,
                          capture_output=True, text=True, timeout=120)


def test_killed_run_with_strokes_resumes_to_the_same_result(tmp_path: Path) -> None:
    """Noise 0 makes the virtual machine deterministic per reading, so a run killed
    by SIGKILL mid-measurement and resumed must give the uninterrupted result: the
    same offsets exactly, the fitted floats within close.py's tolerance (another
    process fits them)."""
    ref = station(run_argv(tmp_path / "ref"), tmp_path)
    assert ref.returncode in (0, 3), ref.stderr
    assert ref.returncode == (3 if not_converged(json.loads(ref.stdout)) else 0), ref.stderr
    # the killed run and its resume: children forked from this worker (tests/helpers/forked.py),
    # compared with the reference, a fresh interpreter
    killed = forked.run(run_argv(tmp_path / "killed"), tmp_path, KILLER)
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    (run_dir,) = list((tmp_path / "killed").glob("run-*"))
    before = (run_dir / "journal.jsonl").read_bytes()
    resumed = forked.run(["resume", str(run_dir), "--json"], tmp_path)
    assert resumed.returncode in (0, 3), resumed.stderr
    expected, got = json.loads(ref.stdout), json.loads(resumed.stdout)
    assert resumed.returncode == (3 if not_converged(got) else 0), resumed.stderr
    assert set(got["deviations"]) == set(expected["deviations"]) and len(got["deviations"]) == 24
    assert_same(got["identified"], expected["identified"], "identified")
    for key in ("offsets_before", "offsets_written"):
        assert got[key] == expected[key], key
    assert_same(got["verification"]["identified"], expected["verification"]["identified"],
                "verification.identified")
    assert (run_dir / "journal.jsonl").read_bytes().startswith(before)
    cycles = [(r["phase"], r["setup"], r["cycle"])
              for r in read_journal(run_dir / "journal.jsonl") if r["type"] == "cycle"]
    # 3 setups × 2 cycles per phase: measurement, then a verification per write-back
    phases = 1 + expected["loop"]["write_backs"]
    assert len(cycles) == len(set(cycles)) == 6 * phases
