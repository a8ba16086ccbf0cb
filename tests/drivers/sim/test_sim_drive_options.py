"""The simulated drive on the command line: the drive options (profile shape, own
acceleration, start delays, axis sequence) checked before anything is served, kept
in the journal's header, and the same drive restarted when a run resumes."""

from __future__ import annotations

import argparse
import json
from typing import Any

import pytest
from builders import resumed, simulated

from drivers.sim.drive_motion import DriveMotion
from drivers.sim.station import VirtualStation
from station import report
from station.commands import cli
from station.commands.options import SimOptions
from station.commands.simulate.launch import drive_motion, sim_params, start_station
from station.errors import BadInput


def sim_args(*argv: str) -> argparse.Namespace:
    return cli.build_parser().parse_args(["run", "--simulate", "--seed", "5", *argv])


def test_drive_options_survive_the_journal_round_trip() -> None:
    args = sim_args("--drive-profile", "scurve,cosine,trapezoid", "--drive-accel", "5000",
                    "--drive-delays", "0,0.003,0.006", "--drive-sequence", "ZYX")
    params = sim_params(SimOptions.from_args(args))
    saved = json.loads(json.dumps(params))  # the journal header is JSON
    expected = DriveMotion(shape=("scurve", "cosine", "trapezoid"), accel_mm_s2=5000.0,
                           start_delay_s=(0.0, 0.003, 0.006), sequence="zyx")
    assert drive_motion(saved) == expected
    st = start_station(saved, None)
    try:
        assert st.machine.drive == expected
        assert "motion" not in st.config()["controller"]  # delays: independent
        assert st.config()["controller"]["accel_mm_s2"] != 5000.0
    finally:
        st.close()
    # without any option, and from a journal older than them: today's drives
    plain = sim_params(SimOptions.from_args(sim_args()))
    assert drive_motion(plain) == DriveMotion.named("coordinated")
    old = {k: v for k, v in params.items() if not k.startswith("drive_")}
    assert drive_motion({**old, "motion": "independent"}) == DriveMotion.named("independent")
    assert drive_motion({k: v for k, v in old.items() if k != "motion"}) \
        == DriveMotion.named("coordinated")
    # a single profile keeps the default coordinated drive, on that shape
    coord = sim_params(SimOptions.from_args(sim_args("--drive-profile", "cosine")))
    assert drive_motion(coord) == DriveMotion(coordinated=True, shape="cosine")


@pytest.mark.parametrize("argv, option", [
    (["--drive-profile", "square"], "--drive-profile"),
    (["--drive-profile", "scurve,cosine"], "--drive-profile"),
    (["--drive-accel", "0"], "--drive-accel"),
    (["--drive-accel", "fast"], "--drive-accel"),
    (["--drive-accel", "1,2"], "--drive-accel"),
    (["--drive-delays", "0,0.1"], "--drive-delays"),
    (["--drive-delays", "0,-0.1,0"], "--drive-delays"),
    (["--drive-delays", "0,nan,0"], "--drive-delays"),
    (["--drive-sequence", "xxy"], "--drive-sequence"),
    (["--motion", "coordinated", "--drive-sequence", "zyx"], "--drive-sequence"),
    (["--motion", "coordinated", "--drive-delays", "0,0,0.1"], "--drive-delays"),
    (["--drive-profile", "scurve,cosine,scurve"], "--drive-profile"),
])
def test_bad_drive_options_are_one_line_and_exit_2(
        argv: list[str], option: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(BadInput, match=f"^{option}: "):
        sim_params(SimOptions.from_args(sim_args(*argv)))
    code = cli.main(["run", "--simulate", "--seed", "5", *argv])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"orthocal: error: {option}: ") and err.count("\n") == 1, err


def test_orthocal_sim_checks_the_drive_options_before_serving(
        tmp_path: Any, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sim.toml"
    code = cli.main(["sim", "--config-out", str(out), "--drive-sequence", "xy"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("orthocal: error: --drive-sequence: ")
    assert err.count("\n") == 1 and not out.exists()


def test_a_run_against_a_sequenced_drive_resumes_with_the_same_drive(
        tmp_path: Any, capsys: pytest.CaptureFixture[str]) -> None:
    # The whole station against a drive that disagrees with every assumption it is
    # not told: S-curve, cosine and trapezoid axes, their own acceleration, start
    # delays, z then y then x. Interrupted by an alarm, resumed from the journal:
    # the restarted virtual station moves the same way, the run completes, and no
    # plunger ever left its stroke, read or not.
    from station.commands import run as cmd_run
    from station.errors import RunFailed
    from station.record.journal_file import read_journal

    expected = DriveMotion(shape=("scurve", "cosine", "trapezoid"), accel_mm_s2=12000.0,
                           start_delay_s=(0.0, 0.004, 0.008), sequence="zyx")
    stations: list[VirtualStation] = []

    def keep(st: VirtualStation) -> None:
        stations.append(st)
        if len(stations) == 1:
            st.controller.faults.alarm_after_moves = 5

    args = simulated(tmp_path / "runs", true_drho=(0.7, -1.1, 0.5),
                     drive_profile="scurve,cosine,trapezoid", drive_accel="12000",
                     drive_delays="0,0.004,0.008", drive_sequence="zyx", hook=keep)
    with pytest.raises(RunFailed, match="alarm 17"):
        cmd_run.run(args)
    (run_dir,) = list((tmp_path / "runs").glob("run-*"))
    header = read_journal(run_dir / "journal.jsonl")[0]  # the run's header
    assert drive_motion(header["simulation"]) == expected
    capsys.readouterr()
    code = cmd_run.resume(resumed(run_dir, hook=keep))
    result = json.loads(capsys.readouterr().out)
    assert result["status"] == "ok" and code == (3 if report.not_converged(result) else 0)
    assert [st.machine.drive for st in stations] == [expected, expected]
    assert [st.out_of_stroke_count for st in stations] == [0, 0]
