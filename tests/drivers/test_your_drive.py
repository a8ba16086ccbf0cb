"""Drives as they come, end to end over the simulators: every built-in map
runs a whole calibration; a layout the project has never seen, described only by the
docs/drive.md's worked example (examples/maps/), calibrates within 3 µm with nothing out of
stroke, once with home-offset registers and once with the offsets held by the
station; a held run resumes, rolls back and hands its offsets to the next run; probe
reads every register of that map."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import FAST, on_setup, resumed, simulated
from truth import assert_truth, drho

from drivers.map_files import builtin_maps, read_map
from drivers.sim.specs import DriveSpec, GaugeSpec
from drivers.sim.station import VirtualStation
from station import report
from station.commands import run as cmd_run
from station.commands.cli import main
from station.commands.simulate.station_setups import SimulatedStation
from station.config.toml import toml_text
from station.errors import RunFailed
from station.record.journal_file import read_journal

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "maps"
GATEWAY = EXAMPLES / "gateway-3x1.toml"
GATEWAY_NO_OFFSETS = EXAMPLES / "gateway-3x1-no-offsets.toml"
TRUE = (0.8, -1.2, 0.5)
# The requirement on a layout the project has never seen: the offsets the run leaves
# within 3 µm of the truth (o = −Δρ from a start at zero).
WITHIN_MM = 0.003
PROCEDURE = {**FAST, "model": "rho", "max_extra_passes": 2}


def calibrate(tmp_path: Path, capsys: pytest.CaptureFixture[str], profile: str,
              hook: Any = None, **extra: Any) -> tuple[dict[str, Any], list[VirtualStation]]:
    stations: list[VirtualStation] = []

    def keep(station: VirtualStation) -> None:
        stations.append(station)
        if hook is not None:
            hook(station)

    code = cmd_run.run(simulated(tmp_path / "runs", **{
        "seed": 3, "noise": 0.001, "true_drho": TRUE, "procedure": PROCEDURE,
        "profile": profile, "hook": keep, **extra}))
    result = json.loads(capsys.readouterr().out)
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    return result, stations


def final_offsets(result: dict[str, Any], station: VirtualStation) -> np.ndarray:
    """The offsets the run leaves: in the drive, or held by the station."""
    if result["offsets_held_by"] == "station":
        return np.array([result["offsets_final"][a] for a in "xyz"])
    return np.asarray(station.machine.offsets, dtype=float)


@pytest.mark.parametrize("name", sorted(builtin_maps()))
def test_every_builtin_map_runs_a_whole_calibration(name: str, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    # Without the plunger guard, whose polls during the moves draw the gauges' noise as
    # often as the machine's load allows (test_any_timing.py and test_guard.py test it),
    # each map's run reads the same draws every time: every map converges at this seed.
    result, stations = calibrate(tmp_path, capsys, name,
                                 procedure={**PROCEDURE, "plunger_guard": False})
    (station,) = stations
    assert station.controller.map == builtin_maps()[name]  # the drive served that map
    assert result["status"] == "ok" and station.out_of_stroke_count == 0
    held = not builtin_maps()[name].has_role("OFFSET")
    assert result["offsets_held_by"] == ("station" if held else "controller")
    assert_truth(result, drho(TRUE))
    assert result["converged"] is True, result["message"]
    # a drive counting 0.01 mm (IAI) holds its targets, and so the offsets, to ±5 µm
    count = 1.0 / builtin_maps()[name]["TARGET_X"].scale
    np.testing.assert_allclose(final_offsets(result, station), -np.array(TRUE),
                               atol=WITHIN_MM + count / 2)
    # a drive holding no offsets was still moved by them: the carriages at Π0 + o
    if held:
        assert np.all(station.machine.offsets == 0)


@pytest.mark.parametrize("path", [GATEWAY, GATEWAY_NO_OFFSETS], ids=["offsets", "held"])
def test_a_layout_never_seen_calibrates_from_its_map_file(
        path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    the_map = read_map(path)
    result, stations = calibrate(tmp_path, capsys, str(path))
    (station,) = stations
    assert station.controller.map == the_map and station.controller.devices == [1, 2, 3]
    assert result["status"] == "ok" and station.out_of_stroke_count == 0, \
        station.out_of_stroke
    assert result["loop"]["write_backs"] >= 1 and len(result["iterations"]) >= 2
    error = final_offsets(result, station) + np.array(TRUE)
    assert np.all(np.abs(error) <= WITHIN_MM), error
    run_dir = Path(result["run_dir"])
    # the run directory keeps the map it ran with, loadable as it was
    assert read_map(run_dir / "register_map.toml") == the_map
    text = report.summary_text(result)
    if the_map.has_role("OFFSET"):
        assert result["offsets_held_by"] == "controller"
        assert "offsets held" not in text
    else:
        assert result["offsets_held_by"] == "station"
        assert the_map.unsupported["offsets"].rstrip(".") in result["offsets_note"]
        assert "offsets held" in text and "--offsets-from" in text
        assert "held by the station" in (run_dir / "report.html").read_text()


def test_offsets_held_by_the_station_resume_roll_back_and_carry_on(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # Cut the first verification short (an alarm on its first move, once the operator
    # has mounted its first setup): the station held the first round's offsets, and
    # the resumed run must go on from them.
    stations: list[VirtualStation] = []

    def keep(station: VirtualStation) -> None:
        stations.append(station)

        def alarm() -> None:
            station.controller.faults.alarm_after_moves = 1

        on_setup(station, 4, alarm)  # setups 1-3 measure, the 4th verifies

    with pytest.raises(RunFailed):
        cmd_run.run(simulated(tmp_path / "runs", seed=3, noise=0.001, true_drho=TRUE,
                              procedure=PROCEDURE, profile=str(GATEWAY_NO_OFFSETS),
                              hook=keep))
    (run_dir,) = list((tmp_path / "runs").glob("run-*"))
    records = read_journal(run_dir / "journal.jsonl")
    done = [r for r in records if r["type"] == "writeback" and r["stage"] == "done"]
    assert len(done) == 1  # the first round was written (held) before the alarm
    capsys.readouterr()
    code = cmd_run.resume(resumed(run_dir, hook=stations.append))
    result = json.loads(capsys.readouterr().out)
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    assert result["status"] == "ok" and result["offsets_held_by"] == "station"
    # the resumed station started from the offsets the journal held, not from zero
    assert result["offsets_before"] == pytest.approx({a: 0.0 for a in "xyz"}, abs=1e-12)
    error = np.array([result["offsets_final"][a] for a in "xyz"]) + np.array(TRUE)
    assert np.all(np.abs(error) <= WITHIN_MM), error
    assert all(st.out_of_stroke_count == 0 for st in stations)

    # The next run starts from the offsets this one left: nothing left to correct.
    capsys.readouterr()
    options = simulated(tmp_path / "next", seed=3, noise=0.001, true_drho=TRUE,
                        procedure=PROCEDURE, profile=str(GATEWAY_NO_OFFSETS))
    code = cmd_run.run(dataclasses.replace(options, offsets_from=run_dir))
    again = json.loads(capsys.readouterr().out)
    # a recheck writes only what stands out of its noise: it may end "within
    # tolerance", or undecided (exit 3, saying why) on what the last run left
    assert code == (3 if report.not_converged(again) else 0), again.get("message")
    assert again["offsets_before"] == pytest.approx(result["offsets_final"], abs=1e-12)
    assert all(abs(again["identified"][f"drho_{a}"]) <= WITHIN_MM for a in "xyz")
    assert again["loop"]["write_backs"] == 0 or all(
        abs(v) <= WITHIN_MM for v in again["remaining"]["total"].values())

    # Rollback restores what the first run began with: zero.
    code = cmd_run.rollback(resumed(run_dir, yes=True))
    restored = json.loads(capsys.readouterr().out)["restored"]
    assert code == 0 and restored == pytest.approx({a: 0.0 for a in "xyz"}, abs=1e-12)
    after = read_journal(run_dir / "journal.jsonl")
    assert after[-1]["type"] == "rollback" and after[-1]["stage"] == "done"


def test_probe_reads_every_register_of_the_unseen_layout(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    the_map = read_map(GATEWAY)
    with SimulatedStation(drive=DriveSpec(register_map=the_map, profile=str(GATEWAY)),
                          gauges=GaugeSpec(noise_mm=0.0)) as vs:
        config = tmp_path / "station.toml"
        config.write_text(toml_text(vs.config()), encoding="utf-8")
        code = main(["probe", "--config", str(config), "--json", "--timeout", "0.3"])
        found = json.loads(capsys.readouterr().out)
        assert code == 0
        regs = found["controller"]["registers"]
        assert set(regs) == {r.name for r in the_map.registers}
        assert {n for n, r in regs.items() if r["state"] != "ok"} == set()
        # every value decoded as the map says: positions in mm from low-word-first counts
        np.testing.assert_allclose([regs[f"ACTUAL_{a}"]["value"] for a in "XYZ"],
                                   np.round(vs.machine.actual() * 4000), atol=0)
        assert vs.controller.stats.writes == 0 and vs.controller.stats.commands == {}


def test_coordinated_is_refused_for_axes_on_separate_drives() -> None:
    from builders import station_config

    from station.errors import BadInput
    from station.plan.limits import motion_model

    config = station_config(controller={"profile": str(GATEWAY), "motion": "coordinated"})
    with pytest.raises(BadInput, match=r"controller.motion: .*unit ids 1, 2, 3"):
        motion_model(config)
    assert motion_model(station_config(controller={"profile": str(GATEWAY)})) == "independent"
    # one drive for all three axes may well interpolate: the config is taken at its word
    assert motion_model(station_config(controller={"motion": "coordinated"})) == "coordinated"
