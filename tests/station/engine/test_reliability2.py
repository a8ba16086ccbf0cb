"""Reliability II through the real command line and the simulators: a
controller that loses power mid-run (unreachable, then back unhomed with its count
lost), a network that drops, a gauge adapter pulled and plugged back behind its
stable link, a full disk, and a second station on the same machine.

The indicator noise is 0, so the simulation is deterministic per reading: a run
that was interrupted and resumed must end with exactly the offsets that the same
run left alone wrote into the simulated controller.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import forked
import pytest
from builders import FAST, Rig, journal_header, no_figures_file, on_setup
from close import assert_same

from drivers.sim.specs import GaugeSpec, MachineTruth
from drivers.sim.station import VirtualStation
from station.commands.simulate.launch import station_config
from station.commands.simulate.station_setups import SimulatedStation
from station.config import parse_config
from station.config.toml import dump_toml
from station.record.journal_file import Journal, read_journal

ROOT = Path(__file__).resolve().parents[3]
SEED = 5
TRUE_DRHO = "0.6,-0.9,0.4"
SPEED = "20000"


def argv(out: Path, *extra: str) -> list[str]:
    return ["run", "--simulate", no_figures_file(out.parent), "--seed", str(SEED),
            "--true-drho", TRUE_DRHO, "--noise", "0",
            "--out", str(out), "--sim-speed", SPEED, "--sim-procedure", json.dumps(FAST),
            *extra]


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, Any]:
    """The same run left alone (a subprocess: the module-scoped fixture cannot use
    the per-test CLI fixture)."""
    out = tmp_path_factory.mktemp("reference")
    proc = subprocess.run([sys.executable, "-m", "station", *argv(out / "runs", "--json")],
                          capture_output=True, text=True, cwd=ROOT, timeout=300,
                          env={**os.environ, "ORTHOCAL_STATE_DIR": str(out / "state")})
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    (run_dir,) = (out / "runs").glob("run-*")
    result["nvram"] = json.loads((run_dir / "controller_nvram.json").read_text())["offsets_mm"]
    return result


def assert_uninterrupted(result: dict[str, Any], run_dir: Path, ref: dict[str, Any]) -> None:
    assert result["status"] == "ok" and result["writeback"]["status"] == "written"
    # fitted in another process than the reference: its floats as close.py compares
    # them; the offsets, counts of the drive's µm, exactly
    assert_same(result["identified"], ref["identified"], "identified")
    assert result["offsets_written"] == ref["offsets_written"]
    nvram = json.loads((run_dir / "controller_nvram.json").read_text())["offsets_mm"]
    assert nvram == ref["nvram"]  # what the simulated controller holds
    assert_same(result["verification"]["identified"], ref["verification"]["identified"],
                "verification.identified")


def events(records: list[dict[str, Any]], kind: str) -> list[dict[str, Any]]:
    return [r["event"] for r in records if r["type"] == "event" and r["event"]["event"] == kind]


def _cut_power(rig: Rig, station: VirtualStation, setup: int = 2, lose: bool = True,
               off_s: float = 1.0) -> None:
    if len(rig.stations) > 1:
        return
    f = station.controller.faults

    def arm() -> None:
        # halfway through the eleventh move after the gauges of this setup are on
        # (each stop from its approach point: two moves, four stops a cycle): the
        # long move to Π^− of its second cycle, with the first one journaled
        f.power_cut_s, f.power_cut_loses_reference = off_s, lose
        f.power_cut_after_moves = 10

    on_setup(station, setup, arm)


# --- power cut -------------------------------------------------------------------------


def test_power_cut_ends_the_run_saying_home_then_resume_homes_and_gives_the_result(
        tmp_path: Path, orthocal, reference) -> None:
    rig = Rig()
    o = orthocal(*argv(tmp_path / "runs"), rig=rig, prepare=_cut_power)
    assert o.code == 1, o.err
    assert "Traceback" not in o.err and "internal error" not in o.err
    (line,) = o.failure_lines()
    assert "must be homed" in line and f"orthocal resume {o.run_dir}" in line, line
    assert "resume homes it" in line
    assert rig.station.controller.stats.power_cuts == 1
    records = o.journal
    # The connection loss was ridden out and journaled, then the lost reference seen.
    assert events(records, "reconnect") and len(events(records, "reconnected")) == 1
    (check,) = events(records, "reference-check")
    assert check["lost"] and "HOMED clear" in check["why"]
    (fault,) = [r for r in records if r["type"] == "fault"]
    assert "ControllerNotHomed" in fault["error"]
    # No reading was taken after the jump: every journaled reading precedes the cut.
    t_cut = next(r["t"] for r in records if r["type"] == "event"
                 and r["event"]["event"] in ("retry", "reconnect"))
    assert all(r["t"] < t_cut for r in records if r["type"] == "reading")

    before = (o.run_dir / "journal.jsonl").read_bytes()
    r = orthocal("resume", str(o.run_dir), "--json", rig=rig)
    assert r.code == 0, r.err
    assert "homed in" in r.err and "same reference after homing" in r.err
    assert (o.run_dir / "journal.jsonl").read_bytes().startswith(before)
    records = r.journal
    assert [x["type"] for x in records].count("homed") == 1
    (ref_check,) = [x for x in records if x["type"] == "reference-check"]
    assert ref_check["result"] == "same" and ref_check["cycles"]
    assert not [x for x in records if x["type"] == "setup-redo"]
    assert_uninterrupted(json.loads(r.out), o.run_dir, reference)


def test_a_reference_moved_by_homing_redoes_the_interrupted_setup(
        tmp_path: Path, orthocal) -> None:
    rig = Rig()
    o = orthocal(*argv(tmp_path / "runs"), rig=rig, prepare=_cut_power)
    assert o.code == 1

    def shifted_switches(rig: Rig, station: VirtualStation) -> None:
        # The home switches of axes x and z moved by 50 µm (a loose switch, a crash):
        # the gauges of leg y (along x and z) see the platform elsewhere at Π0.
        station.machine.home_error_mm = [0.05, 0.0, 0.05]

    r = orthocal("resume", str(o.run_dir), "--json", rig=rig, prepare=shifted_switches)
    assert r.code == 0, r.err
    assert "reference moved with homing" in r.err and "is redone" in r.err
    records = r.journal
    (check,) = [x for x in records if x["type"] == "reference-check"]
    assert check["result"] == "moved"
    (redo,) = [x for x in records if x["type"] == "setup-redo"]
    assert redo["cycles_dropped"] and "gauge" in redo["reason"]
    setup = redo["setup"]
    # The redone setup's cycles were measured again after the redo record.
    i = records.index(redo)
    again = [x for x in records[i:] if x["type"] == "cycle" and x["setup"] == setup
             and x["phase"] == redo["phase"]]
    assert [x["cycle"] for x in again][:FAST["cycles"]] == [1, 2]
    assert json.loads(r.out)["status"] == "ok"


def test_a_network_drop_with_the_reference_kept_is_ridden_out(
        tmp_path: Path, orthocal, reference) -> None:
    o = orthocal(*argv(tmp_path / "runs", "--json"),
                 prepare=lambda rig, st: _cut_power(rig, st, lose=False, off_s=0.5))
    assert o.code == 0, o.err
    records = o.journal
    assert len(events(records, "reconnected")) == 1
    assert [c["lost"] for c in events(records, "reference-check")] == [False]
    assert_uninterrupted(json.loads(o.out), o.run_dir, reference)


# --- pulled gauge adapter ------------------------------------------------------------------


def test_a_gauge_pulled_and_plugged_back_is_reopened_and_the_run_goes_on(
        tmp_path: Path, orthocal, reference) -> None:
    def pull(rig: Rig, station: VirtualStation) -> None:
        if len(rig.stations) == 1:
            on_setup(station, 2, lambda: station.indicators["A"].unplug_for(0.8))

    o = orthocal(*argv(tmp_path / "runs", "--json"), prepare=pull)
    assert o.code == 0, o.err
    records = o.journal
    reopened = events(records, "reopened")
    assert len(reopened) == 1 and reopened[0]["indicator"] == "A"
    assert reopened[0]["port"].endswith("usb-orthocal-sim-gauge-A-if00")
    assert events(records, "reopen")
    assert_uninterrupted(json.loads(o.out), o.run_dir, reference)


def test_a_resume_started_while_the_port_is_gone_waits_for_it(
        tmp_path: Path, orthocal, reference) -> None:
    rig = Rig()
    o = orthocal(*argv(tmp_path / "runs"), rig=rig, prepare=_cut_power)
    assert o.code == 1

    def still_unplugged(rig: Rig, station: VirtualStation) -> None:
        station.indicators["B"].unplug_for(1.0)  # plugged back a second after the start

    r = orthocal("resume", str(o.run_dir), "--json", rig=rig, prepare=still_unplugged)
    assert r.code == 0, r.err
    assert events(r.journal, "reopened")
    assert_uninterrupted(json.loads(r.out), o.run_dir, reference)


# --- full disk -------------------------------------------------------------------------------


def _limited(limit: int):
    import resource

    def preexec() -> None:
        # SIGXFSZ keeps its default (kill): the station itself must ignore it so that
        # the write fails with EFBIG instead.
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return preexec


def test_a_full_disk_stops_the_run_and_resume_finishes_it(tmp_path: Path, reference) -> None:
    out = tmp_path / "runs"
    env = {**os.environ, "ORTHOCAL_STATE_DIR": str(tmp_path / "state")}
    full = subprocess.run([sys.executable, "-m", "station", *argv(out)], capture_output=True,
                          text=True, cwd=ROOT, timeout=300, env=env,
                          preexec_fn=_limited(20_000))  # plan.json: 13 kB
    assert full.returncode == 1, full.stderr
    assert "Traceback" not in full.stderr and "internal error" not in full.stderr
    (run_dir,) = out.glob("run-*")
    (line,) = [ln for ln in full.stderr.splitlines() if ln.startswith("orthocal: failed")]
    assert "the disk is full" in line and "was not saved" in line, line
    assert "free some disk space" in line and f"orthocal resume {run_dir}" in line
    assert "axes stopped" in line.lower()
    raw = (run_dir / "journal.jsonl").read_bytes()
    assert raw.endswith(b"\n")  # nothing half-written
    records = read_journal(run_dir / "journal.jsonl")
    assert records[-1]["type"] != "finished"
    # The reading that could not be saved was not used: no cycle uses a stop the
    # journal does not hold.
    stops = {r["stop"] for r in records if r["type"] == "reading"}
    for c in (r for r in records if r["type"] == "cycle"):
        p, s, k = c["phase"], c["setup"], c["cycle"]
        assert {f"{p}:{s}:{k}:+", f"{p}:{s}:{k}:-", f"{p}:{s}:{k}:0"} <= stops

    # the resume: a child forked from this worker (tests/helpers/forked.py)
    freed = forked.run(["resume", str(run_dir), "--json"], ROOT, env=env, timeout=300)
    assert freed.returncode == 0, freed.stderr
    assert_uninterrupted(json.loads(freed.stdout), run_dir, reference)


# --- one station per machine -------------------------------------------------------------

HOLDER = r"""
import sys
from station.record.lock import acquire

lock = acquire("tcp", "127.0.0.1", int(sys.argv[1]), 1, command="run", run_dir=sys.argv[2])
print("held", flush=True)
sys.stdin.readline()
"""


def test_a_second_station_on_the_same_machine_is_refused_at_once(
        tmp_path: Path, orthocal) -> None:
    with SimulatedStation(MachineTruth(drho=(0.3, 0.2, -0.1)),
                          gauges=GaugeSpec(noise_mm=0.0)) as station:
        config = parse_config(station_config(station, {"procedure": FAST}), "test")
        cfg = tmp_path / "station.toml"
        cfg.write_text(dump_toml(config))
        # An interrupted run of this station (its header only) to resume or roll back.
        run_dir = tmp_path / "runs" / "run-earlier"
        run_dir.mkdir(parents=True)
        (run_dir / "config.toml").write_text(dump_toml(config))
        with Journal(run_dir / "journal.jsonl") as j:
            j.append(journal_header(config=config.model_dump()))
        holder = subprocess.Popen(
            [sys.executable, "-c", HOLDER, str(station.controller.port), "/runs/other-run"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT)
        try:
            assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
            stats = station.controller.stats
            requests, connections = stats.requests, stats.connections
            for args in (["run", "--config", str(cfg), "--yes", "--out", str(tmp_path / "r2")],
                         ["resume", str(run_dir), "--yes"],
                         ["rollback", str(run_dir), "--yes"]):
                o = orthocal(*args)
                assert o.code == 1, (args, o.err)
                (line,) = o.failure_lines()
                assert f"controller 127.0.0.1:{station.controller.port} (device 1) is in use" \
                    in line and f"pid {holder.pid}" in line and "/runs/other-run" in line, line
            # refused at once: before a single request reached the controller, and before
            # a connection to it that a timeout could wait on (the server's count of them is
            # complete once it has stopped: below)
            assert stats.requests == requests
            assert not (tmp_path / "r2").exists()
        finally:
            holder.kill()
            holder.wait(timeout=30)
            for f in (holder.stdin, holder.stdout):
                if f is not None:
                    f.close()
        # The holder was killed: its lock is taken over, and the command says so.
        o = orthocal("rollback", str(run_dir), "--yes")
        assert f"took over the lock on controller 127.0.0.1:{station.controller.port}" in o.err
        assert f"pid {holder.pid}" in o.err and "that process is gone" in o.err
    # the last rollback's connection, and none of the three refused commands'
    assert stats.connections == connections + 1


def test_a_run_on_a_controller_that_lost_its_reference_homes_it_first(
        tmp_path: Path, orthocal, reference) -> None:
    def unhomed(rig: Rig, station: VirtualStation) -> None:
        # Power was lost before the run: the count restarted at 0 on every axis.
        station.machine.power_cycle([0.0, 0.0, 0.0])

    o = orthocal(*argv(tmp_path / "runs", "--json"), prepare=unhomed)
    assert o.code == 0, o.err
    assert "not homed" in o.err and "homed in" in o.err
    assert o.rig.station.controller.stats.commands.get(3) == 1  # COMMAND 3: homing
    assert_uninterrupted(json.loads(o.out), o.run_dir, reference)
