"""End to end over the simulators (real Modbus TCP server, real pty gauges,
real drivers): the hidden offsets come back, write-back corrects the machine,
both setup styles work, and an interrupted run resumes to the end."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import FAST, resumed, simulated
from truth import TRUTH_COVERAGE, assert_truth, drho

from orthocal import coverage_factor
from station import report
from station.commands import run as cmd_run
from station.errors import RunFailed
from station.record.journal_file import read_journal


def only_run_dir(tmp_path: Path) -> Path:
    (run_dir,) = list((tmp_path / "runs").glob("run-*"))
    return run_dir


def check_recovered(result: dict, true_drho: tuple[float, float, float]) -> None:
    # The truth lies within the run's own statement (identified + what the last
    # verification found left, ± k·SE with k from t on its dof: tests/helpers/truth.py).
    # Against the first identification's SE alone it does not: misplaced stands bias
    # that round beyond its noise, which the loop is there to remove.
    assert_truth(result, drho(true_drho))
    ver = result["verification"]
    # after write-back the machine is nominal: deviations at the noise level ...
    assert ver["deviations_rms_mm"] < 0.005 < result["deviations_rms_mm"]
    # ... and what is left to identify is the written correction's own error seen
    # through the verification's noise: zero within both (the closed loop's rule)
    first = result["iterations"][0]["std_errors"]
    k = coverage_factor(ver["std_errors_dof"], TRUTH_COVERAGE)
    for name, value in ver["identified"].items():
        se = math.hypot(ver["std_errors"][name], first.get(name) or 0.0)
        assert abs(value) <= max(k * se, 0.003), (name, value)


@pytest.mark.parametrize("count", [2, 6])
def test_simulated_run_recovers_hidden_offsets(tmp_path: Path, capsys, count: int) -> None:
    true_drho = (0.8, -1.3, 0.45)
    # stands exact, and the station told so (stand_tolerance_mm 0: at L/2): the 10 µm
    # below is then the gauges' noise alone, not a stand's position the prior allows
    code = cmd_run.run(simulated(tmp_path / "runs", true_drho=true_drho, indicators=count,
                                 mount_error=0.0,
                                 procedure={**FAST, "stand_tolerance_mm": 0}))
    result = json.loads(capsys.readouterr().out)
    # completed: 0, or 3 where its closed loop did not converge (it says why)
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    assert result["status"] == "ok" and result["writeback"]["status"] == "written"
    check_recovered(result, true_drho)
    for axis, true in zip("xyz", true_drho, strict=True):
        assert result["offsets_written"][axis] == pytest.approx(
            result["offsets_before"][axis] - result["identified"][f"drho_{axis}"], abs=0.0011)
        assert abs(result["offsets_written"][axis] + true) < 0.01
    run_dir = Path(result["run_dir"])
    for name in ("journal.jsonl", "config.toml", "plan.txt", "plan.json",
                 "offsets_backup.json", "result.json", "report.html"):
        assert (run_dir / name).is_file(), name
    on_disk = json.loads((run_dir / "result.json").read_text())
    assert on_disk["identified"] == result["identified"]
    setups = result["setups"]
    names = [set(s["indicators"]) for s in setups]
    if count == 2:
        assert names == [{"A", "B"}] * 3  # the same two gauges moved from leg to leg
    else:
        assert len(set().union(*names)) == 6 and "-z" in setups[1]["indicators"].values()
    kinds = [r["type"] for r in read_journal(run_dir / "journal.jsonl")]
    assert kinds[0] == "header" and kinds[-1] == "finished"
    # every phase the closed loop measured (noise can ask for a second write-back)
    phases = len(result["iterations"])
    # per setup the opening Π0, then per cycle Π+, Π−, Π0 and Π0 from the other side
    assert kinds.count("reading") == 2 * 3 * (1 + 4 * FAST["cycles"]) * phases
    stages = [r["stage"] for r in read_journal(run_dir / "journal.jsonl")
              if r["type"] == "writeback"]
    rounds = sum(1 for it in result["iterations"] if it["offsets_written"] is not None)
    assert stages == ["backup", "intent", "done"] * rounds and rounds >= 1


def test_fault_mid_run_then_resume_finishes(tmp_path: Path, capsys) -> None:
    true_drho = (-0.6, 0.9, 1.1)

    def alarm_soon(station: Any) -> None:
        # in the second setup: the first takes 18 moves (every stop from its approach
        # point, and Π0 from the other side after each cycle)
        station.controller.faults.alarm_after_moves = 22

    with pytest.raises(RunFailed) as info:
        # The plunger guard's readings during moves draw from the gauges' seeded noise
        # stream; with them this seed's verification lands at 3.5 standard errors.
        cmd_run.run(simulated(tmp_path / "runs", true_drho=true_drho, hook=alarm_soon,
                              procedure={**FAST, "plunger_guard": False}, mount_error=0.0))
    message = str(info.value)
    run_dir = only_run_dir(tmp_path)
    assert "alarm 17" in message and f"orthocal resume {run_dir}" in message
    failed = json.loads((run_dir / "result.json").read_text())
    assert failed["status"] == "failed"
    journal_before = (run_dir / "journal.jsonl").read_bytes()
    records = read_journal(run_dir / "journal.jsonl")
    assert records[-1]["type"] == "fault" and "alarm" in records[-1]["error"]
    cycles_before = sum(1 for r in records if r["type"] == "cycle")
    assert cycles_before >= 1
    capsys.readouterr()

    code = cmd_run.resume(resumed(run_dir))
    result = json.loads(capsys.readouterr().out)
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    assert result["status"] == "ok"
    check_recovered(result, true_drho)
    journal_after = (run_dir / "journal.jsonl").read_bytes()
    assert journal_after.startswith(journal_before)  # resume only appended
    records = read_journal(run_dir / "journal.jsonl")
    # completed cycles were not measured again
    keys = [(r["phase"], r["setup"], r["cycle"]) for r in records if r["type"] == "cycle"]
    assert len(keys) == len(set(keys))
    # resuming a finished run reports it and changes nothing
    again = cmd_run.resume(resumed(run_dir))
    assert again == code  # the same exit status (3 where the loop did not converge)
    assert (run_dir / "journal.jsonl").read_bytes() == journal_after


def test_adaptive_cycles_stop_early_and_retries_are_journaled(tmp_path: Path, capsys) -> None:
    def flaky(station: Any) -> None:
        station.indicators["A"].faults.drop_next = 2  # two lost replies: retried

    procedure = {**FAST, "cycles": 4, "target_std_error_mm": 0.01}
    code = cmd_run.run(simulated(tmp_path / "runs", true_drho=(0.3, 0.2, -0.4),
                                 procedure=procedure, hook=flaky, mount_error=0.0))
    result = json.loads(capsys.readouterr().out)
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    # 0.01 mm is loose against 0.002 mm noise: two cycles (the minimum) suffice
    assert [s["cycles_used"] for s in result["setups"]] == [2, 2, 2]
    assert all(s["cycles_max"] == 4 for s in result["setups"])
    records = read_journal(Path(result["run_dir"]) / "journal.jsonl")
    retries = [r for r in records if r["type"] == "event" and r["event"]["event"] == "retry"]
    assert len(retries) == 2 and all("indicator A" in r["event"]["device"] for r in retries)
    assert result["timing"]["retries"] == 2


def test_ctrl_c_stops_the_axes_and_says_how_to_resume(tmp_path: Path) -> None:
    seen: dict[str, Any] = {}

    def interrupt_second_mount(station: Any) -> None:
        seen["station"] = station
        mount = station.mount
        calls = {"n": 0}

        def operator_hits_ctrl_c(name: str, leg: str, direction: str, at: float = 0.5) -> None:
            calls["n"] += 1
            if calls["n"] > 2:  # the operator presses Ctrl-C at the second setup
                raise KeyboardInterrupt
            mount(name, leg, direction, at=at)

        station.mount = operator_hits_ctrl_c

    with pytest.raises(RunFailed) as info:
        cmd_run.run(simulated(tmp_path / "runs", hook=interrupt_second_mount,
                              mount_error=0.0))
    run_dir = only_run_dir(tmp_path)
    assert f"orthocal resume {run_dir}" in str(info.value)
    assert seen["station"].controller.stats.commands.get(2, 0) >= 1  # STOP was sent
    records = read_journal(run_dir / "journal.jsonl")
    assert records[-1]["type"] == "aborted"
    assert json.loads((run_dir / "result.json").read_text())["status"] == "aborted"


def test_outlier_rule() -> None:
    from station.analysis.statistics import reject_outliers

    assert reject_outliers([0.100, 0.101, 0.099, 0.100, 0.350], 5.0, 0.003) == \
        [True, True, True, True, False]
    # identical readings have zero MAD: the resolution floor keeps a 1-count step
    assert reject_outliers([0.100, 0.100, 0.101], 5.0, 0.003) == [True, True, True]
    assert reject_outliers([0.1, 0.5], 5.0, 0.003) == [True, True]  # too few to judge


def test_pooled_noise_scale_keeps_normal_readings_and_still_catches_knocks() -> None:
    """Five quantised readings per stop often have a MAD near zero: judged alone,
    a few percent of perfectly normal readings would be thrown away. Pooled over
    the stops, the scale is σ and nothing normal is rejected."""
    from station.analysis.statistics import NoiseScale, reject_outliers

    rng = np.random.default_rng(2)
    sigma, resolution = 0.005, 0.001
    stops = np.round(rng.normal(0.0, sigma, (400, 5)) / resolution) * resolution
    alone = pooled = 0
    scale = NoiseScale()
    for values in stops:
        scale.add(values)
        alone += 5 - sum(reject_outliers(values, 5.0, 3 * resolution))
        pooled += 5 - sum(reject_outliers(values, 5.0, 3 * resolution, scale.sigma))
    assert alone > 10  # the per-stop rule's false rejections this fix is about
    assert pooled == 0
    assert scale.sigma == pytest.approx(sigma, rel=0.1)
    knocked = [0.001, -0.004, 0.250, 0.003, 0.000]
    assert reject_outliers(knocked, 5.0, 3 * resolution, scale.sigma) == \
        [True, True, False, True, True]
