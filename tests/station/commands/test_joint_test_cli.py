"""``orthocal run --simulate --joint-test`` (docs/design.md, "The station's own joint
test"): the command line's virtual station (a Modbus server, gauges on pseudo-
terminals) has gauge blocks that its gauge A, clamped to a carriage, reads through the
carriage's true position; with ``--joint-lead 100,-80,60`` the station's own test,
before the calibration, finds each lead within 10 µm/m and result.json states it.
``--plan`` lists the test and ``SIM.toml`` says ``joint_test = true`` as well. ``orthocal
sim --joint-test``, a station in another process, stands a gauge on each carriage
against a step gauge whose face is set as the station asks, and ``run --config``
against it finds the leads too. A run killed (SIGKILL) in the middle of a joint's test
resumes it from its mounting."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from builders import Rig, cli, no_figures_file
from forked import STATION, Forked

from station.record.journal_file import read_journal

SEED = "31"  # a fixed draw of the virtual gauges' 1 µm noise
SHORT = '{"cycles": 2, "readings": 5, "settle_s": 0, "verify": false, "max_iterations": 1}'


def two_repeats(rig: Rig, station: Any) -> None:
    """What a user writes in the file: two approaches of each target from each side."""
    describe = station.config
    station.config = lambda: {**describe(), "joints": {"station_repeats": 2}}


def test_run_simulate_joint_test_finds_the_leads(orthocal, tmp_path: Path) -> None:
    run = orthocal("run", "--simulate", "--seed", SEED, "--noise", "0.001", "--joint-lead",
                   "100,-80,60", "--backlash", "0.005,0,0", "--joint-test", "--yes", "--json",
                   "--sim-procedure", SHORT, "--out", str(tmp_path / "runs"),
                   prepare=two_repeats)
    assert run.code in (0, 3), run.err
    result = json.loads(run.out)
    assert result["status"] == "ok"
    for axis, k in zip("xyz", (100.0, -80.0, 60.0), strict=True):
        j = result["joints"][axis]
        assert j["source"] == "station", j
        assert k - 10.0 < j["lead_um_per_m"] < k + 10.0, (axis, j["lead_um_per_m"])
        assert j["station_test"]["repeats"] == 2
    assert result["simulation"]["joint_lead_um_per_m"] == {"x": 100.0, "y": -80.0, "z": 60.0}
    run_dir = Path(result["run_dir"])
    assert (run_dir / "joint-test-x.svg").is_file()
    # three mountings before the calibration's, said as the run starts
    assert "mountings: expect 6 (the joints' own test's 3 first)" in run.err
    # and the calibration's first mounting prompt says the same, as without the test
    assert "Mountings: expect 6 in all" in run.err
    assert result["timing"]["mountings"] == 6
    # the virtual operator was told what to do, in the prompts' words
    assert "joint x's own test: the machine is at ρ_x = 200.250 mm (its datum)" in run.err
    assert "set a stack of gauge blocks of" in run.err
    # the run directory's config keeps the test and its reference: a resume runs it so
    saved = (run_dir / "config.toml").read_text(encoding="utf-8")
    assert 'station_test = ["x", "y", "z"]' in saved and 'kind = "gauge blocks"' in saved


def test_plan_lists_the_test_and_a_sim_file_asks_for_it(orthocal, tmp_path: Path) -> None:
    sim = tmp_path / "rehearsal.toml"
    sim.write_text("[simulation]\nseed = 3\njoint_test = true\n", encoding="utf-8")
    listed = orthocal("run", "--simulate", str(sim), "--plan", "--out", str(tmp_path / "plan"))
    assert listed.code == 0, listed.err
    for axis in "xyz":
        assert f"joint {axis}'s own test: gauge A on carriage {axis}, plunger toward lower ρ, " \
               f"against the gauge blocks; ρ_{axis} from 200.250 to 370.250 mm" in listed.out
    assert "target 0: ρ = 200.250 mm, face 0.000 mm, from above only" in listed.out
    # the set-up pictures drawn before anything moves, beside the mountings'
    drawn = sorted(p.name for p in (tmp_path / "plan" / "mountings").iterdir())
    assert drawn[:3] == ["joint-test-x.svg", "joint-test-y.svg", "joint-test-z.svg"]
    assert drawn[3:] == [f"mounting-{n}-leg-{a}.svg" for n, a in ((1, "x"), (2, "y"), (3, "z"))]


def test_a_station_in_another_process_serves_the_test(tmp_path: Path) -> None:
    config = tmp_path / "sim.toml"
    proc = subprocess.Popen(
        [sys.executable, "-m", "station", "sim", "--config-out", str(config), "--seed", "4",
         "--noise", "0.001", "--joint-lead", "100,-80,60", "--joint-test"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while not config.exists() or "[joints]" not in config.read_text(encoding="utf-8"):
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "orthocal sim wrote no config in 30 s"
            time.sleep(0.05)
        text = config.read_text(encoding="utf-8")
        assert 'station_gauge = { x = "G", y = "H", z = "I" }' in text
        assert 'kind = "step gauge"' in text
        # what a user may write: a shorter test and a calibration without verification
        config.write_text(text.replace('station_test = ["x", "y", "z"]',
                                       'station_test = ["x", "y", "z"]\nstation_repeats = 2')
                          .replace("verify = true", "verify = false"), encoding="utf-8")
        run = cli("run", "--config", str(config), "--yes", "--json", "--out",
                  str(tmp_path / "runs"), cwd=tmp_path)
        assert run.returncode in (0, 3), run.stderr
        result = json.loads(run.stdout)
        for axis, k in zip("xyz", (100.0, -80.0, 60.0), strict=True):
            j = result["joints"][axis]
            assert j["source"] == "station" and j["station_test"]["reference"] == "step gauge"
            assert k - 10.0 < j["lead_um_per_m"] < k + 10.0, (axis, j["lead_um_per_m"])
            assert j["table"]["targets_mm"] == [200.25 + 20.0 * n for n in range(10)]
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
        proc.stdout.close()
        proc.stderr.close()


# The command line in a process of its own, two approaches a side, SIGKILLing itself once
# the journal holds the ``nth`` record matching ``match`` (argv[1]).
KILLER = r"""
import json, os, signal, sys
import station.commands.simulate.launch as launch
import station.record.journal_file as journal
from station.commands.cli import main

spec = json.loads(sys.argv[1])
described = launch.station_config
launch.station_config = lambda station, params: (lambda c: {
    **c, "joints": {**c["joints"], "station_repeats": 2}})(described(station, params))
real_append = journal.Journal.append
seen = [0]

def append(self, record):
    real_append(self, record)
    if all(record.get(k) == v for k, v in spec["match"].items()):
        seen[0] += 1
        if seen[0] == spec["nth"]:
            os.kill(os.getpid(), signal.SIGKILL)

journal.Journal.append = append
sys.exit(main(sys.argv[2:]))
"""


def test_a_run_killed_in_a_joints_test_resumes_it(tmp_path: Path) -> None:
    out = tmp_path / "runs"
    argv = ["run", "--simulate", no_figures_file(tmp_path), "--seed", SEED, "--noise", "0.001",
            "--joint-lead", "100,-80,60", "--joint-test", "--sim-speed", "20000",
            "--sim-procedure", SHORT, "--yes", "--json", "--out", str(out)]
    spec = {"match": {"type": "joint-face", "joint": "y"}, "nth": 3}
    env = dict(os.environ)  # the tests' clock (conftest.py) included
    killed = Forked(KILLER, [json.dumps(spec), *argv], tmp_path, env)
    killed.communicate(timeout=120)
    assert killed.returncode == -signal.SIGKILL
    (run_dir,) = list(out.glob("run-*"))
    before = (run_dir / "journal.jsonl").read_bytes()
    records = read_journal(run_dir / "journal.jsonl")
    assert [r["joint"] for r in records if r["type"] == "joint-test"] == ["x"]
    resumed = Forked(STATION, ["resume", str(run_dir), "--json"], tmp_path, env)
    stdout, stderr = resumed.communicate(timeout=120)
    assert resumed.returncode in (0, 3), stderr
    after = (run_dir / "journal.jsonl").read_bytes()
    assert after.startswith(before)  # the journal only grew
    records = read_journal(run_dir / "journal.jsonl")
    assert [r["joint"] for r in records if r["type"] == "joint-test"] == ["x", "y", "z"]
    assert [r["joint"] for r in records if r["type"] == "joint-mount"] == ["x", "y", "y", "z"]
    result = json.loads(stdout)
    for axis, k in zip("xyz", (100.0, -80.0, 60.0), strict=True):
        assert k - 10.0 < result["joints"][axis]["lead_um_per_m"] < k + 10.0
