"""A second gauge plane per leg in a whole run (``[[setups]] at``), over the
simulators: on a tilted machine whose legs are bowed 8 µm, where the middles alone
cannot tell the bow from the tilts, the run fits each gauge plane's bow beside the
geometry and states the tilts and the bows; and a plane the leg leaves at a test
posture is refused before anything moves."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import FAST, simulated, station_data

from orthocal import BOW_NAMES, TILT_NAMES
from station.commands import run as cmd_run
from station.errors import BadInput
from station.report import as_result
from station.report import leg_form as form

TILT = (0.2, 0.1, -0.15)
GAP = (0.15, -0.10, 0.12)  # mm
BOW = 0.008
# One round, no verification: what the identification states is under test here.
# Six cycles of five readings: a bow's standard error is then about 0.7 µm, so asking
# each bow within 3 µm is a test that fails for a wrong bow, not for an unlucky draw
# (at the default three cycles it is ~1 µm; bench/second_plane.py runs the default).
PROCEDURE = {**FAST, "cycles": 6, "readings": 5, "model": "auto", "max_iterations": 1,
             "verify": False}


def second_plane(at: float) -> Any:
    """Every setup of the virtual station, then each again at ``at`` of its leg."""
    def hook(station: Any) -> None:
        config = station.config
        station.config = lambda: {**config(), "setups": [
            *config()["setups"], *({**s, "at": at} for s in config()["setups"])]}
    return hook


def test_a_second_plane_tells_the_bow_from_the_tilts(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    # Offsets already near right, as in the closed loop's later rounds: with Δρ of
    # tenths of a mm the stands by eye (a column of stand error × the legs' slope
    # each) and the bows share each gauge's four rows, and the first round is the
    # stands' (bench/second_plane.py runs the whole loop).
    code = cmd_run.run(simulated(tmp_path / "runs", seed=3, noise=0.001,
                                 true_drho=(0.02, -0.03, 0.01),
                                 true_tilt=TILT, leg_bow=f"{BOW}", procedure=PROCEDURE,
                                 hook=second_plane(0.75)))
    result = json.loads(capsys.readouterr().out)
    assert code == 0, result.get("message")
    assert result["model"].endswith("+form") and "tilt" in result["model"]
    identified = result["identified"]
    for name, true in zip(TILT_NAMES, TILT, strict=True):
        assert abs(identified[name] - true) <= 0.05, (name, identified[name])
    for name in BOW_NAMES:  # the simulator bows every leg alike, along +j in both planes
        assert abs(identified[name] - BOW) <= 0.003, (name, identified[name])
        # and each is stated with a standard error that covers its error
        assert abs(identified[name] - BOW) <= 4 * result["std_errors"][name], name
    # six mountings: each leg at three quarters, then in its middle (whose gauges a
    # verification would keep on)
    setups = [r for r in _journal(result) if r["type"] == "setup"]
    assert [r.get("at", 0.5) for r in setups] == [0.75] * 3 + [0.5] * 3
    assert any(k.startswith("+@0.75") for k in result["deviations"])
    # the summary and the report state the bows, and name the plane of each deviation
    (line,) = form.summary_lines(as_result(result))
    assert line.startswith("  legs' bows    XY +") and "nothing to write" in line
    page = (Path(result["run_dir"]) / "report.html").read_text()
    assert "The legs' form" in page and "at 0.75 of the leg" in page


def test_a_plane_the_leg_leaves_is_refused_before_anything_moves(tmp_path: Path) -> None:
    # at 0.25 of the paper's legs the carriage passes the gauges' plane at Π_i^−
    with pytest.raises(BadInput, match=r"leg x could leave the plane.*nothing has moved"):
        cmd_run.run(simulated(tmp_path / "runs", seed=3, procedure=PROCEDURE,
                              hook=second_plane(0.25)))


def _journal(result: dict[str, Any]) -> list[dict[str, Any]]:
    path = Path(result["run_dir"]) / "journal.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()]


def test_a_bowed_tilted_gapped_machine_reads_the_second_plane_once_and_names_its_limit(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # The whole loop, default procedure (3 cycles of 5, stands by eye): the first pass
    # at the legs' middles while the offsets are large, the second (the first
    # verification) in both planes, every later one at the middles again, joined with
    # the second's tilts, gaps and bows (orthocal.carry.joined_fit): 3 + 5 + 2 × (write-
    # backs − 1) mountings. With 1 µm gauges the bows are known to about 1 µm after one
    # pass, and at the middles a uniform bow moves Δρ (docs/model.md, "Tilts or bows"):
    # about 1.2 µm of Δρ's standard error is the carried bows', which no pass at the
    # middles shrinks (orthocal.carry.prior_floor). The loop sees that after the second
    # write-back's first pass and stops there, naming it, instead of reading the
    # middles twice more for nothing; the offsets it wrote are within 2.5 µm anyway.
    code = cmd_run.run(simulated(tmp_path / "runs", seed=1, noise=0.001, true_tilt=TILT,
                                 true_gap=GAP, leg_bow=f"{BOW}",
                                 procedure={"settle_s": 0.0}, writeback={"objective": "joints"},
                                 hook=second_plane(0.75)))
    result = json.loads(capsys.readouterr().out)
    assert code == 3, result.get("message")
    assert result["loop"]["stopped"] == "not-converged"
    last = result["iterations"][-1]
    assert last["verdict"] == "form-limited" and last.get("passes") is None
    # each axis's floor is a part of its standard error, and a large one
    floor = last["form_floor_mm"]
    for name, part in floor.items():
        assert 0.5 * last["std_errors"][name] <= part <= last["std_errors"][name], name
    assert "may still be off by up to" in result["loop"]["detail"]  # how far: the headline
    (remedy,) = [a["text"] for a in result["advice"] if a["id"] == "converge"]
    # the stands set by eye made most of the bows' error in the pass that measured them
    assert "legs' bows" in remedy and "stand_tolerance_mm" in remedy
    assert "larger converge_mm" not in remedy  # advice that would only hide it
    writes = result["loop"]["write_backs"]
    assert writes == 2
    records = _journal(result)
    setups = [r for r in records if r["type"] == "setup"]
    assert len(setups) == result["timing"]["mountings"] == 3 + 5 + 2 * (writes - 1) <= 12
    # the second plane in the second pass alone ("v": the first write-back's
    # verification), which ends at a leg's middle
    assert [r["phase"] for r in setups if r.get("at", 0.5) != 0.5] == ["v"] * 3
    assert all(r.get("at", 0.5) == 0.5 for r in setups if r["phase"] != "v")
    assert [r for r in setups if r["phase"] == "v"][-1].get("at", 0.5) == 0.5
    # the first round claims no bows (a uniform bow is a tilt at the middles); every
    # verification fits them: the first measures them, the later ones carry them
    (first,) = [r for r in records if r["type"] == "identification"]
    assert not first["model"].endswith("+form")
    verifications = [r for r in records if r["type"] == "verification"]
    assert verifications and all(r["model"].endswith("+form") for r in verifications)
    truth = np.array([result["simulation"]["true_drho"][a] for a in "xyz"])
    offsets = np.array([result["offsets_final"][a] - result["offsets_before"][a]
                        for a in "xyz"])
    assert np.all(np.abs(truth + offsets) <= 0.0025), 1000 * (truth + offsets)


def test_the_plan_reads_the_second_plane_in_one_pass_and_says_so(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from station.config import parse_config
    from station.plan.steps import build_plan

    assert cmd_run.run(simulated(tmp_path / "runs", plan=True, json=False,
                                 procedure={"settle_s": 0.0}, hook=second_plane(0.75))) == 0
    text = capsys.readouterr().out
    assert "passes: the first measures setups 1, 2, 3 (the legs' middles); the second" in text
    assert "setups 4, 5, 6, 1, 2, 3 (the second gauge plane first" in text
    assert "mountings: expect 8 (one write-back, verified at once)" in text
    assert cmd_run.run(simulated(tmp_path / "runs", plan=True, json=True,
                                 procedure={"settle_s": 0.0}, hook=second_plane(0.75))) == 0
    planned = json.loads(capsys.readouterr().out)
    assert planned["mountings"]["usual"] == 8 and planned["mountings"]["per_write_back"] == 2
    # the passes as a function of their index alone (a resumed run measures each as it
    # was): middles, both planes ending at a middle, middles; with nothing verified the
    # first pass is the one that reads both
    for verify, two in ((True, 1), (False, 0)):
        config = parse_config(_config_with_planes(verify), "station.toml")
        plan = build_plan(config)
        ats = [[sp.at for sp in plan.setups_of(i)] for i in range(4)]
        assert ats[two] == [0.75] * 3 + [0.5] * 3
        assert all(a == [0.5] * 3 for i, a in enumerate(ats) if i != two)


def _config_with_planes(verify: bool) -> dict[str, Any]:
    """The tests' base config with each setup again at 0.75 of its leg."""
    data = station_data(procedure={"verify": verify})
    data["setups"] = [*data["setups"], *({**sp, "at": 0.75} for sp in data["setups"])]
    return data
