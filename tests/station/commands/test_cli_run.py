"""`orthocal run|resume|rollback` through the real command line: exit codes
0 (ok), 1 (refused or failed, one line naming the device, no traceback) and
2 (bad input naming the field), --plan, --json and rollback."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import pytest
from builders import no_figures_file
from truth import assert_truth, drho

from station.commands.cli import main
from station.commands.simulate.launch import station_config
from station.commands.simulate.station_setups import SimulatedStation, gauges_for
from station.config.toml import toml_text


def test_simulated_run_then_rollback(tmp_path: Path, capsys) -> None:
    code = main(["run", "--simulate", no_figures_file(tmp_path), "--seed", "3",
                 "--true-drho", "0.4,-0.7,1.2", "--out", str(tmp_path), "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    result = json.loads(out)  # exactly one JSON document on stdout
    assert result["status"] == "ok"
    assert result["simulation"]["true_drho"] == {"x": 0.4, "y": -0.7, "z": 1.2}
    assert "Traceback" not in err
    run_dir = Path(result["run_dir"])
    nvram = json.loads((run_dir / "controller_nvram.json").read_text())["offsets_mm"]
    assert nvram == pytest.approx([result["offsets_written"][a] for a in "xyz"])

    code = main(["rollback", str(run_dir), "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    nvram = json.loads((run_dir / "controller_nvram.json").read_text())["offsets_mm"]
    assert nvram == pytest.approx([result["offsets_before"][a] for a in "xyz"])
    assert json.loads(out)["restored"] == result["offsets_before"]
    assert json.loads(out)["replaced"] == pytest.approx(result["offsets_written"], abs=1e-9)


def _values(offsets: dict) -> list[str]:
    """Each offset as the command line says it (4 decimals, signed)."""
    return [f"{offsets[a]:+.4f}" for a in "xyz"]


def _shown(offsets: dict) -> list[str]:
    """Each offset as the report and the summary show it: the typographic minus, and
    zero unsigned (station.report.format.fmt: "−0.0000" would read as negative)."""
    return ["0.0000" if round(offsets[a], 4) == 0 else
            f"{offsets[a]:+.4f}".replace("-", "−") for a in "xyz"]


def summary_lines(run_dir: Path) -> list[str]:
    """The first screen of a finished run, as ``resume`` prints it."""
    from station import report
    from station.record.io import read_result

    return report.summary_text(read_result(run_dir / "result.json"),
                               verbose=False).splitlines()


def test_a_rollback_is_a_state_of_the_run(tmp_path: Path, capsys) -> None:
    # result.json, report.html, the history and resume say "rolled back", with the
    # offsets restored; the prompt shows each joint's offset now → restored.
    code = main(["run", "--simulate", no_figures_file(tmp_path), "--seed", "5",
                 "--true-drho", "0.9,-0.6,0.3", "--out", str(tmp_path), "--json"])
    result = json.loads(capsys.readouterr().out)
    assert code == 0 and result["offsets_written"] is not None
    run_dir = Path(result["run_dir"])
    before, written = result["offsets_before"], result["offsets_written"]
    assert main(["rollback", str(run_dir), "--yes"]) == 0
    out, err = capsys.readouterr()
    for a, now, then in zip("xyz", _values(written), _values(before), strict=True):
        assert f"{a} {now} → {then}" in err  # the question, before anything is written
        assert f"{a} {now} → {then}" in out and "rolled back" in out
    stored = json.loads((run_dir / "result.json").read_text())
    assert stored["rolled_back"]["restored"] == pytest.approx(before, abs=1e-9)
    assert stored["rolled_back"]["replaced"] == pytest.approx(written, abs=1e-9)
    assert stored["offsets_final"] == pytest.approx(before, abs=1e-9)
    html = (run_dir / "report.html").read_text()
    assert "<b>Rolled back</b>" in html
    pairs = [f"{a} {now} → {then}" for a, now, then in
             zip("xyz", _shown(written), _shown(before), strict=True)]
    assert all(p in html for p in pairs)
    assert main(["history", "--out", str(tmp_path)]) == 0
    listing = capsys.readouterr().out
    assert "rolled back" in listing and all(v in listing for v in _values(before))
    assert main(["history", "--out", str(tmp_path), "--json"]) == 0
    entry = json.loads(capsys.readouterr().out)["runs"][-1]
    assert entry["rolled_back"]["restored"] == pytest.approx(before, abs=1e-9)
    assert main(["resume", str(run_dir)]) == 0
    summary = " ".join(capsys.readouterr().out.split())  # lines wrap at 160
    assert "then rolled back" in summary and "ROLLED BACK" in summary
    assert all(p in summary for p in pairs)
    # each joint is as found again: its as-left is the as-found figure, said so
    q = {x["name"]: x for x in stored["statement"]}
    for a in "xyz":
        line = next(ln for ln in summary_lines(run_dir) if ln.startswith(f"  joint {a} "))
        found = line.split("Δρ as found ")[1].split(" → ")[0]
        assert line.endswith(f"→ as left {found}, rolled back (95 %)"), line
        assert q[f"drho_{a}.as_found"]["decision"] != "within"


def test_writeback_beyond_the_limit_is_refused_exit_1(tmp_path: Path, capsys) -> None:
    code = main(["run", "--simulate", no_figures_file(tmp_path), "--seed", "4",
                 "--true-drho", "3.6,0.2,-0.3", "--out", str(tmp_path), "--json"])
    out, _err = capsys.readouterr()
    assert code == 1
    result = json.loads(out)
    assert result["status"] == "refused" and result["offsets_written"] is None
    assert result["verification"] is None
    assert abs(result["identified"]["drho_x"] - 3.6) < 0.01
    stored = json.loads((Path(result["run_dir"]) / "result.json").read_text())
    assert stored["writeback"]["status"] == "refused"


def test_bad_config_exit_2_names_the_field(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "station.toml"
    bad.write_text('[[indicators]]\nname = "A"\nport = "/dev/x"\nstroke_mm = -1\n'
                   '[[setups]]\nleg = "x"\nindicators = { A = "y" }\n')
    assert main(["run", "--config", str(bad), "--yes", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "indicators[0].stroke_mm: must be > 0" in err and "Traceback" not in err
    assert not list(tmp_path.glob("run-*"))


@pytest.fixture
def station_toml(tmp_path: Path):
    with SimulatedStation(gauges=gauges_for(6, mounted=True), seed=2) as station:
        config = station_config(station, {})
        path = tmp_path / "station.toml"

        def write(**indicator_changes) -> Path:
            for ind in config["indicators"]:
                ind.update(indicator_changes.get(ind["name"], {}))
            path.write_text(toml_text(config, "test"))
            return path

        yield write


def test_plan_lists_and_exits_0_without_moving(station_toml, tmp_path: Path, capsys) -> None:
    path = station_toml()
    assert main(["run", "--config", str(path), "--plan", "--out", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    assert "Π_x^+" in out and "plan checked" in out
    assert not list(tmp_path.glob("run-*"))
    # each setup's mounting picture, drawn under --out (docs/design.md, "Mounting pictures")
    folder = tmp_path / "mountings"
    drawn = sorted(p.name for p in folder.glob("*.svg"))
    assert drawn == ["mounting-1-leg-x.svg", "mounting-2-leg-y.svg", "mounting-3-leg-z.svg"]
    assert f"mounting pictures, one per setup, in {folder}: " + ", ".join(drawn) in err
    assert main(["run", "--config", str(path), "--plan", "--json", "--out",
                 str(tmp_path)]) == 0
    listed = json.loads(capsys.readouterr().out)["pictures"]
    assert listed == [str(folder / name) for name in drawn]
    # a folder that cannot be written: one line, exit 2, nothing moved
    assert main(["run", "--config", str(path), "--plan", "--out", "/proc/nope"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "/proc/nope/mountings" in err and "internal" not in err


def test_plan_refused_by_stroke_exit_2(station_toml, tmp_path: Path, capsys) -> None:
    # D stands on leg y, reversed: leg y's swing pushes it in, and it is at its stop
    # already (no waypoint helps)
    path = station_toml(D={"stroke_mm": 6.0, "preload_mm": 6.0})
    assert main(["run", "--config", str(path), "--yes", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "indicator D" in err and "Π_y^" in err and "nothing has moved" in err


def test_real_devices_need_a_tty_or_yes(station_toml, tmp_path: Path, capsys,
                                        monkeypatch) -> None:
    monkeypatch.setattr("sys.stdin.isatty", lambda: False, raising=False)
    path = station_toml()
    assert main(["run", "--config", str(path), "--out", str(tmp_path)]) == 2
    assert "--yes" in capsys.readouterr().err


def test_unreachable_controller_exit_1_names_it(tmp_path: Path, capsys) -> None:
    with socket.socket() as s:  # a port that was free a moment ago: nothing listens
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    path = tmp_path / "station.toml"
    path.write_text(f'[controller]\nport = {port}\ntimeout_s = 0.2\n'
                    '[[indicators]]\nname = "A"\nport = "/dev/null"\n'
                    '[[setups]]\nleg = "x"\nindicators = { A = "y" }\n')
    assert main(["run", "--config", str(path), "--yes", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert f"127.0.0.1:{port}" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_resume_of_a_missing_run_dir_exit_2(tmp_path: Path, capsys) -> None:
    assert main(["resume", str(tmp_path / "nope")]) == 2
    assert "no such run directory" in capsys.readouterr().err


def test_kill_9_mid_run_then_resume_finishes(tmp_path: Path, capsys) -> None:
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "runs"
    proc = subprocess.Popen(
        [sys.executable, "-m", "station", "run", "--simulate", no_figures_file(tmp_path),
         "--seed", "11",
         "--true-drho", "1.1,-0.4,0.6", "--out", str(out), "--json"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        journal = None
        while time.monotonic() < deadline:  # kill once the second setup is under way
            found = list(out.glob("run-*/journal.jsonl"))
            if found and found[0].read_text().count('"type":"setup"') >= 2:
                journal = found[0]
                break
            time.sleep(0.05)
        assert journal is not None, "the run did not get to its second setup"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(10)
    before = journal.read_bytes()
    run_dir = journal.parent
    assert main(["resume", str(run_dir), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["status"] == "ok"
    assert journal.read_bytes().startswith(before)
    assert_truth(result, drho((1.1, -0.4, 0.6)))
    assert result["verification"]["deviations_rms_mm"] < 0.005
