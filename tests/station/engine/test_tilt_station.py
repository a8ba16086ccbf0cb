"""Tilted machines through the station: the virtual machine's hidden tilts, the
config's models, ``identify --model auto``, and a whole simulated run with
model auto that writes the right offsets and reports the tilts."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from builders import resumed, simulated
from fakes import FakeRig, fake_config, run_on

import orthocal
from drivers.sim.machine import VirtualOrthoglide
from station import report
from station.commands import run as cmd_run
from station.commands.cli import main
from station.config import ProcedureConfig

G = orthocal.Geometry()
TILT = (0.5, -0.5, 0.3)


def test_virtual_machine_with_tilts_shows_the_exact_models_deviations():
    drho = np.array([0.7, -1.1, 0.4])
    now = [0.0]
    m = VirtualOrthoglide(G, true_drho=drho, true_tilt=TILT, clock=lambda: now[0])

    def reading_at(rho, leg: str, d: str) -> float:
        now[0] += m.move_to(rho) + 1.0  # let the move finish on the manual clock
        return m.leg_reading(leg, d)

    truth = np.r_[drho, 0, 0, 0, TILT]
    for key in [("+", "x", "y"), ("-", "y", "z"), ("+", "z", "x"), ("-", "z", "y")]:
        sign, leg, d = key
        r0 = reading_at(orthocal.posture("0", None, G), leg, d)
        rs = reading_at(orthocal.posture(sign, leg, G), leg, d)
        assert rs - r0 == pytest.approx(orthocal.deviation(key, G, truth), abs=1e-9)
        # and the tilts matter: the untilted machine reads otherwise
        assert abs(orthocal.deviation(key, G, truth[:6]) - (rs - r0)) > 0.005
    assert VirtualOrthoglide(G, true_params=truth).true_tilt == pytest.approx(TILT)


@pytest.mark.parametrize("model", ["rho", "L", "full", "rho+tilt", "full+tilt", "auto"])
def test_config_accepts_every_model(model):
    assert ProcedureConfig(model=model).model == model


def test_auto_is_the_default_model():
    assert ProcedureConfig().model == "auto"


def _cycles_csv(tmp_path: Path, truth, noise: float, cycles: int = 3) -> Path:
    keys = [(s, i, j) for s in "+-" for i in "xyz" for j in "xyz" if i != j]
    exact = orthocal.deviations(keys, G, truth)
    rng = np.random.default_rng(8)
    rows = ["posture,leg,direction,deviation_mm,cycle"]
    for c in range(1, cycles + 1):
        for (s, i, j), v in zip(keys, exact, strict=True):
            rows.append(f"{s},{i},{j},{v + rng.normal(0, noise):.6f},{c}")
    path = tmp_path / "cycles.csv"
    path.write_text("\n".join(rows) + "\n")
    return path


def test_identify_cli_auto_uses_the_cycle_scatter(tmp_path, capsys):
    path = _cycles_csv(tmp_path, np.r_[0.4, -0.2, 0.9, 0, 0, 0, TILT], noise=0.001)
    assert main(["identify", str(path), "--model", "auto", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["model"] == "rho+tilt"
    assert doc["parameters"]["tilt_yx"] == pytest.approx(0.5, abs=0.05)
    sel = doc["model_selection"]
    assert sel["noise_source"] == "cycle-to-cycle scatter" and sel["level"] == 0.001
    # the lattice's second level: rho+gap tried beside rho+tilt, and rejected
    assert [c["model"] for c in sel["candidates"]] == ["rho", "rho+gap", "rho+tilt"]
    assert [c["passed"] for c in sel["candidates"]] == [False, False, True]
    assert main(["identify", str(path), "--model", "auto"]) == 0
    out = capsys.readouterr().out
    assert "tilt_zy" in out and "mrad" in out and "model chosen by auto" in out


def test_identify_cli_refuses_auto_without_noise_and_full_tilt_naming_why(tmp_path, capsys):
    path = tmp_path / "one.csv"
    keys = [(s, i, j) for s in "+-" for i in "xyz" for j in "xyz" if i != j]
    path.write_text("posture,leg,direction,deviation_mm\n"
                    + "".join(f"{s},{i},{j},0.01\n" for s, i, j in keys))
    assert main(["identify", str(path), "--model", "auto"]) == 2
    err = capsys.readouterr().err
    assert "auto needs the noise" in err and "cycle column" in err
    assert main(["identify", str(path), "--model", "full+tilt"]) == 2
    err = capsys.readouterr().err
    assert "ΔL cannot be separated from the tilts" in err and "Traceback" not in err


def test_simulated_tilted_run_with_auto_writes_offsets_within_4_um(tmp_path, capsys):
    # The engine's run on the Protocol-level fakes (tests/helpers/fakes.py) in front of the
    # tilted virtual machine; stands exact: their misfit would blur the tilts (and the
    # station told so: stand_tolerance_mm 0 takes them at L/2, as the paper)
    true_drho = (1.3, -0.9, 2.1)
    rig = FakeRig(seed=11, true_drho=true_drho, true_tilt=TILT, noise_mm=0.001)
    code, result = run_on(rig, tmp_path / "runs",
                          fake_config(settle_s=0.0, stand_tolerance_mm=0))
    assert result["status"] == "ok" and result["model"] == "rho+tilt"
    # completed: 0, or 3 where its closed loop did not converge (it says why)
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    assert result["simulation"]["true_tilt"] == dict(zip(orthocal.TILT_NAMES, TILT, strict=True))
    # the offsets written are the hidden truth within 4 µm
    for axis, true in zip("xyz", true_drho, strict=True):
        written = result["offsets_written"][axis] - result["offsets_before"][axis]
        assert abs(written + true) < 0.004, (axis, written, true)
    # every parameter of the model used, tilts in mrad with their uncertainty
    assert set(result["identified"]) == set(result["std_errors"]) == {
        "drho_x", "drho_y", "drho_z", "tilt_yx", "tilt_zx", "tilt_zy"}
    for name, true in zip(orthocal.TILT_NAMES, TILT, strict=True):
        se = result["std_errors"][name]
        assert 0 < se < 0.05 and abs(result["identified"][name] - true) < 5 * se
    sel = result["model_selection"]
    assert sel["model"] == "rho+tilt" and "rho leaves more than the noise" in sel["reason"]
    assert any("rotation of the whole machine" in n for n in result["not_identifiable"])
    assert any("ΔL cannot be separated from the tilts" in n for n in result["not_identifiable"])
    # only Δρ went to the controller; the verification still sees the tilts
    assert result["verification"]["identified"]["tilt_yx"] == pytest.approx(0.5, abs=0.05)
    run_dir = Path(result["run_dir"])
    page = (run_dir / "report.html").read_text(encoding="utf-8")
    assert "tilt<sub>yx</sub>" in page and "mrad" in page
    assert "rotation of the whole machine" in page and "cannot be written" in page
    assert "Lack-of-fit F test" in page
    text = report.summary_text(result)
    # one value and its 95 % uncertainty, labelled: the statement's tilt, as stated
    tilt = next(q for q in result["statement"] if q["name"] == "tilt_yx")
    line = next(ln for ln in text.splitlines() if ln.startswith("  tilts "))
    assert f"YX +{tilt['value']:.3f} ± {tilt['expanded']:.3f} mrad" in line
    assert line.endswith("(95 %)")
    assert "not identifiable  a rotation of the whole machine" in text


def test_a_tilted_simulated_run_resumes_on_the_same_tilted_machine(tmp_path, capsys):
    from station.errors import RunFailed

    def alarm_soon(station) -> None:
        station.controller.faults.alarm_after_moves = 9  # in the second setup

    true_drho = (-0.6, 0.9, 1.1)
    args = simulated(tmp_path / "runs", seed=3, true_drho=true_drho, true_tilt=TILT,
                     noise=0.001, yes=True, hook=alarm_soon)
    with pytest.raises(RunFailed):
        cmd_run.run(args)
    (run_dir,) = list((tmp_path / "runs").glob("run-*"))
    capsys.readouterr()
    code = cmd_run.resume(resumed(run_dir, yes=True))
    result = json.loads(capsys.readouterr().out)
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    # the restarted virtual machine has the journal's tilts: auto finds them again
    assert result["model"] == "rho+tilt"
    assert result["simulation"]["true_tilt"]["tilt_zx"] == -0.5
    for name, true in zip(orthocal.TILT_NAMES, TILT, strict=True):
        assert abs(result["identified"][name] - true) < 5 * result["std_errors"][name]
