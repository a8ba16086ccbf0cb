"""A shop's acceptance limit ([acceptance] tool_rms_um / tool_max_um): judged at
95 % on the tool's error after calibration (PASS only where the whole interval lies
within the limit, FAIL where its lower end exceeds it, else not decided), recorded
in result.json as a typed section, said on the first screen and in the report, and
exit status 4 for a completed run that does not pass."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
from builders import FAST, cli, station_data
from fakes import FakeRig, fake_config, run_on
from result_builders import golden_result

from station import report
from station.analysis.acceptance import judge
from station.commands.cli import (
    EXIT_BAD_INPUT,
    EXIT_NOT_CONVERGED,
    EXIT_OK,
    EXIT_OUT_OF_TOLERANCE,
)
from station.commands.run import exit_status
from station.config import AcceptanceConfig, StationConfig
from station.config.toml import toml_text
from station.record.result import RunResult

#: the tool's error after calibration: RMS 40 µm (95 %: 30–50), max 90 µm (70–110)
AFTER = {"rms_mm": 0.040, "max_mm": 0.090, "rms_interval_95_mm": [0.030, 0.050],
         "max_interval_95_mm": [0.070, 0.110]}


def _judged(rms: float | None = None, mx: float | None = None,
            accuracy: Any = None) -> dict[str, Any] | None:
    """The judgement of the golden run's record with ``AFTER`` (or ``accuracy``) as its
    tool error, as result.json holds it."""
    doc = golden_result()
    if accuracy is None:
        doc["accuracy"]["after"].update(AFTER)
    else:
        doc["accuracy"] = accuracy
    judged = judge(AcceptanceConfig(tool_rms_um=rms, tool_max_um=mx), report.as_result(doc))
    return None if judged is None else judged.model_dump(mode="json")


@pytest.mark.parametrize(("limit", "outcome"), [
    (50.0, "pass"), (60.0, "pass"),     # the upper end within the limit
    (49.9, "undecided"), (30.0, "undecided"),  # the limit inside the interval
    (29.9, "fail"), (10.0, "fail"),     # the lower end beyond the limit
])
def test_rms_limit_against_its_interval(limit: float, outcome: str) -> None:
    judged = _judged(rms=limit)
    assert judged is not None and judged["outcome"] == outcome
    (check,) = judged["checks"]
    assert check["interval_95_um"] == pytest.approx([30.0, 50.0], abs=1e-9)
    assert check["value_um"] == pytest.approx(40.0, abs=1e-9)


def test_every_limit_must_pass_and_one_fail_decides() -> None:
    assert _judged(rms=60.0, mx=120.0)["outcome"] == "pass"
    assert _judged(rms=60.0, mx=100.0)["outcome"] == "undecided"
    assert _judged(rms=40.0, mx=60.0)["outcome"] == "fail"


def test_no_limit_no_section_and_no_figure_no_pass() -> None:
    assert _judged() is None
    judged = _judged(rms=1000.0, accuracy={"error": "not stated: singular"})
    assert judged["outcome"] == "undecided" and "singular" in judged["note"]


@pytest.mark.parametrize("value", ["-5", "0", "nan", "inf", "\"a\""])
def test_a_bad_limit_is_one_line_exit_2(tmp_path: Path, value: str) -> None:
    data = station_data()
    text = toml_text(data) + f"\n[acceptance]\ntool_rms_um = {value}\n"
    (tmp_path / "station.toml").write_text(text)
    done = cli("run", "--config", "station.toml", "--plan", cwd=tmp_path)
    assert done.returncode == EXIT_BAD_INPUT
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "acceptance.tool_rms_um" in lines[0], done.stderr
    assert "Traceback" not in done.stderr


def _run(tmp_path: Path, gap: tuple[float, float, float] = (0.0, 0.0, 0.0),
         **limits: float) -> tuple[int, dict[str, Any]]:
    config = fake_config(**{**FAST, "cycles": 3, "max_extra_passes": 1})
    config = StationConfig.model_validate(
        {**config.model_dump(), "acceptance": limits})
    rig = FakeRig(true_drho=(0.4, -0.3, 0.2), true_gap=gap, noise_mm=0.001, seed=3)
    code, result = run_on(rig, tmp_path / "runs", config)
    return exit_status(result, code), result


def test_a_run_out_of_tolerance_exits_4_and_says_fail(
        out_of_tolerance: tuple[int, dict[str, Any]]) -> None:
    code, result = out_of_tolerance
    record = RunResult.model_validate(result)
    assert record.acceptance is not None and record.acceptance.outcome == "fail"
    rms, mx = record.acceptance.checks
    assert (rms.figure, rms.outcome, mx.figure, mx.outcome) == ("rms", "fail", "max", "pass")
    assert rms.interval_95_um is not None and rms.interval_95_um[0] > 1.0
    assert code == (EXIT_NOT_CONVERGED if report.not_converged(result)
                    else EXIT_OUT_OF_TOLERANCE)
    first = report.summary_text(result, verbose=False).splitlines()
    assert first[1].startswith("  acceptance    FAIL at 95 %"), first[:3]
    page = report.render_html(result, figures=False)
    assert "FAIL at 95 %" in page.split("What was done")[0]


def test_a_square_machine_calibrated_to_a_micrometre_passes_10_um(tmp_path: Path) -> None:
    # its inputs stated (the fakes' STATED: legs, room, joints exact), 1 µm gauges
    code, result = _run(tmp_path, tool_rms_um=10.0)
    after = {q["name"]: q for q in result["statement"]}["tool.after.rms"]
    assert after["value"] < 0.002, after  # left at about a micrometre
    assert after["interval_95"][1] <= 0.010, after
    assert result["acceptance"]["outcome"] == "pass"
    assert code == (EXIT_NOT_CONVERGED if report.not_converged(result) else EXIT_OK)
    assert "PASS at 95 %" in report.summary_text(result, verbose=False)


@pytest.fixture(scope="module")
def out_of_tolerance(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, dict[str, Any]]:
    # gaps of 0.2 mm, which no offset fixes: the tool's RMS after calibration is tens
    # of µm, its whole 95 % interval far beyond 1 µm
    return _run(tmp_path_factory.mktemp("acceptance"), gap=(0.2, -0.1, 0.15),
                tool_rms_um=1.0, tool_max_um=100000.0)


@pytest.mark.parametrize(("outcome", "stopped", "code"), [
    ("pass", "converged", EXIT_OK),
    ("fail", "converged", EXIT_OUT_OF_TOLERANCE),
    ("undecided", "converged", EXIT_OUT_OF_TOLERANCE),
    ("fail", "not-converged", EXIT_NOT_CONVERGED),  # the loop's verdict comes first
])
def test_exit_status_order(out_of_tolerance: tuple[int, dict[str, Any]], outcome: str,
                           stopped: str, code: int) -> None:
    _, result = out_of_tolerance
    changed = copy.deepcopy(result)
    changed["acceptance"]["outcome"] = outcome
    changed["loop"]["stopped"] = stopped
    assert exit_status(changed) == code
    failed = {**changed, "status": "failed"}
    assert exit_status(failed) == 1
