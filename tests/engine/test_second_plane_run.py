"""A second gauge plane per leg in a whole run (``[[setups]] at``), over the
simulators: on a tilted machine whose legs are bowed 8 µm, where the middles alone
cannot tell the bow from the tilts, the run fits each gauge plane's bow beside the
geometry and states the tilts and the bows; and a plane the leg leaves at a test
posture is refused before anything moves."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from builders import FAST, simulated

from orthocal import BOW_NAMES, TILT_NAMES
from station.commands import run as cmd_run
from station.errors import BadInput
from station.report import as_result
from station.report import leg_form as form

TILT = (0.2, 0.1, -0.15)
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
    # six mountings: each leg in its middle and at three quarters
    setups = [r for r in _journal(result) if r["type"] == "setup"]
    assert [r.get("at", 0.5) for r in setups] == [0.5] * 3 + [0.75] * 3
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
