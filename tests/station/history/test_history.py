"""A machine's history (station.history): every finished run recorded by machine id,
listed by ``orthocal history``, rebuilt from the run directories, and two runs of one
machine compared by ``orthocal compare`` with each change's uncertainty; a store
that cannot be written never fails a run."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pg
import pytest
from builders import Completed, cli, simulated
from schema_check import errors
from system import require

from station import report
from station.commands import run as cmd_run
from station.history.store import DEFAULT_NAME, HistoryStore, default_url

TRUE = (0.4, -0.3, 0.2)


def _with(machine_id: str | None, history: dict[str, Any] | None = None) -> Any:
    def hook(station: Any) -> None:  # what a user writes in [machine] and [history]
        config = station.config

        def patched() -> dict[str, Any]:
            data = config()
            if machine_id is not None:
                data["machine"] = {**data.get("machine", {}), "id": machine_id}
            if history is not None:
                data["history"] = history
            return data
        station.config = patched
    return hook


def _run(out: Path, machine_id: str | None, true_drho=TRUE, seed: int = 4,
         history: dict[str, Any] | None = None) -> dict[str, Any]:
    """A simulated run of machine ``machine_id`` into ``out``: its JSON result, from
    the stdout captured here (a module fixture has no capsys)."""
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        code = cmd_run.run(simulated(out, seed=seed, noise=0.001, true_drho=true_drho,
                                     mount_error=0.0, hook=_with(machine_id, history)))
    result = json.loads(buffer.getvalue())
    assert code in (0, 3) and result["status"] == "ok", result.get("message")
    return result


def orthocal(*argv: str, cwd: Path) -> Completed:
    return cli(*argv, cwd=cwd)


@dataclass
class Machines:
    """Five finished runs recorded in one ``--out``: machine OG-1 three times (``a``,
    ``same``: the machine unchanged, ``moved``: its x joint drifted 20 µm), OG-2
    once, and a run that names no machine."""

    out: Path
    a: dict[str, Any]
    same: dict[str, Any]
    moved: dict[str, Any]
    other: dict[str, Any]
    anonymous: dict[str, Any]


@pytest.fixture(scope="module")
def machines(tmp_path_factory: pytest.TempPathFactory) -> Machines:
    """The runs the listing, rebuild and compare tests read (none of them writes to
    the store: a rebuild goes to a store of its own)."""
    out = tmp_path_factory.mktemp("machines") / "runs"
    return Machines(out, _run(out, "OG-1"), _run(out, "OG-1", seed=5),
                    _run(out, "OG-1", seed=6,
                         true_drho=(TRUE[0] + 0.02, TRUE[1], TRUE[2])),
                    _run(out, "OG-2", seed=5), _run(out, None, seed=6))


def test_runs_are_recorded_listed_and_rebuilt(machines: Machines, tmp_path: Path) -> None:
    m = machines
    a, same, moved = m.a, m.same, m.moved
    assert a["machine"]["id"] == "OG-1"
    everyone = [r["run_dir"] for r in (a, same, moved, m.other, m.anonymous)]
    with HistoryStore(default_url(m.out)) as store:
        mine = store.entries("OG-1")
        assert [e["run_dir"] for e in mine] == [a["run_dir"], same["run_dir"], moved["run_dir"]]
        assert [e["run_dir"] for e in store.entries()] == everyone
    listed = orthocal("history", "--out", str(m.out), "--machine", "OG-1", "--json",
                      cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    doc = json.loads(listed.stdout)
    assert [e["run_dir"] for e in doc["runs"]] == \
        [a["run_dir"], same["run_dir"], moved["run_dir"]]
    found = doc["runs"][0]["as_found"]["joint_error_mm"]
    # the machine's joint error in the controller's zero frame: Δρ − o, o = 0 here
    for axis, true in zip("xyz", TRUE, strict=True):
        assert abs(found[axis]["value_mm"] - true) < 5 * found[axis]["std_error_mm"] + 0.001
    # each row also keeps the joints' lost motion and which gauges measured it
    row = doc["runs"][0]
    assert set(row["reversal"]) == set(a["reversal"]["value_mm"]) and \
        row["reversal"]["x"]["value_mm"] == a["reversal"]["value_mm"]["x"]
    assert [i["name"] for i in row["instruments"]] == \
        [i["name"] for i in a["uncertainty_budget"]["instruments"]]
    # the run directories are the record: a store made again from them alone, in a
    # folder that must exist (said in one line naming --out, not the URL it makes)
    rebuilt_out = tmp_path / "rebuilt"
    missing = orthocal("history", "--out", str(rebuilt_out), "--rebuild", str(m.out),
                       cwd=tmp_path)
    assert missing.returncode == 2 and missing.stdout == ""
    assert missing.stderr.startswith("orthocal: error: --out: ") and \
        "not a directory" in missing.stderr and missing.stderr.count("\n") == 1
    rebuilt_out.mkdir()
    rebuilt = orthocal("history", "--out", str(rebuilt_out), "--rebuild", str(m.out),
                       "--json", cwd=tmp_path)
    assert rebuilt.returncode == 0, rebuilt.stderr
    assert [e["run_dir"] for e in json.loads(rebuilt.stdout)["runs"]] == everyone
    assert (rebuilt_out / DEFAULT_NAME).exists()
    text = orthocal("history", "--out", str(rebuilt_out), cwd=tmp_path)
    assert text.returncode == 0 and "OG-1" in text.stdout and "OG-2" in text.stdout


def test_compare_finds_drift_and_not_noise(machines: Machines, tmp_path: Path) -> None:
    a, same, moved = machines.a, machines.same, machines.moved
    unchanged = orthocal("compare", a["run_dir"], same["run_dir"], "--json", cwd=tmp_path)
    assert unchanged.returncode == 0, unchanged.stderr
    for axis, c in json.loads(unchanged.stdout)["joint_error_mm"].items():
        # the same machine: the change is noise (4 standard errors: 1 in 16 000)
        assert abs(c["change"]) < 4 * c["std_error"], (axis, c)
    drift = json.loads(orthocal("compare", a["run_dir"], moved["run_dir"], "--json",
                                cwd=tmp_path).stdout)["changes"]
    assert drift["drho_x"]["significant"] and abs(drift["drho_x"]["change_mm"] - 0.02) < 0.003
    for name in ("drho_y", "drho_z"):
        assert abs(drift[name]["change_mm"]) < 4 * drift[name]["std_error_mm"]
    assert {"tilt_yx", "tilt_zx", "tilt_zy"} <= set(drift)  # the layout too
    assert "change_mrad" in drift["tilt_yx"]
    said = orthocal("compare", a["run_dir"], moved["run_dir"], cwd=tmp_path).stdout
    # every change says whether it is significant, and by which criterion
    rows = [line for line in said.splitlines() if line.startswith("  ") and " → " in line]
    assert len(rows) == 9 and all(line.endswith("significant") for line in rows)
    assert next(r for r in rows if "joint x" in r).endswith("  significant")
    assert "lies beyond its 95 % expanded uncertainty" in said


def test_compare_refuses_a_run_compared_with_itself(machines: Machines,
                                                    tmp_path: Path) -> None:
    a = machines.a["run_dir"]
    copy = tmp_path / "copy-of-a"
    shutil.copytree(a, copy)
    for other in (a, str(copy)):  # the directory itself, or a copy of it
        refused = orthocal("compare", a, other, cwd=tmp_path)
        assert refused.returncode == 2 and refused.stdout == ""
        assert refused.stderr.count("\n") == 1 and "same run" in refused.stderr


def test_compare_refuses_other_machines_in_one_line(machines: Machines, tmp_path: Path) -> None:
    a, b, anonymous = machines.a, machines.other, machines.anonymous
    # no section without an earlier run of the same id, nor without an id
    assert "since_last" not in b and "since_last" not in anonymous
    for other, words in ((b, "different machines"), (anonymous, "names no machine")):
        refused = orthocal("compare", a["run_dir"], other["run_dir"], cwd=tmp_path)
        assert refused.returncode == 2 and words in refused.stderr
        assert len(refused.stderr.strip().splitlines()) == 1 and "Traceback" not in refused.stderr
    missing = orthocal("compare", a["run_dir"], str(tmp_path / "nowhere"), cwd=tmp_path)
    assert missing.returncode == 2 and "cannot read" in missing.stderr


def test_a_store_that_cannot_be_written_never_fails_the_run(tmp_path: Path, capsys) -> None:
    url = f"sqlite:///{tmp_path / 'no' / 'such' / 'dir' / 'h.sqlite'}"
    code = cmd_run.run(simulated(tmp_path / "runs", seed=4, noise=0.001, true_drho=TRUE,
                                 mount_error=0.0, hook=_with("OG-1", {"url": url})))
    captured = capsys.readouterr()
    assert code in (0, 3) and json.loads(captured.out)["status"] == "ok"
    assert "not recorded in the history" in captured.err and "--rebuild" in captured.err
    off = cmd_run.run(simulated(tmp_path / "off", seed=4, noise=0.001, true_drho=TRUE,
                                mount_error=0.0, hook=_with("OG-1", {"enabled": False})))
    capsys.readouterr()
    assert off in (0, 3) and not (tmp_path / "off" / DEFAULT_NAME).exists()


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def store_url(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    """The same store code on SQLite and on a real PostgreSQL server (tests/helpers/pg.py)."""
    if request.param == "sqlite":
        yield default_url(tmp_path_factory.mktemp("sqlite"))
        return
    require(pg.available(), "PostgreSQL's server (initdb, pg_ctl)")
    with pg.server() as url:
        yield url


def _entry(run_dir: str, machine: str | None, started: str, **extra: Any) -> dict[str, Any]:
    return {"run_dir": run_dir, "machine_id": machine, "started": started,
            "finished": started, "status": "ok", "stopped": "converged", "converged": True,
            "tool_after_rms_mm": 0.0012, "as_found": {"joint_error_mm": {
                "x": {"value_mm": 0.4, "std_error_mm": 0.0005}}, "dof": 30.0}, **extra}


def test_the_store_on_each_database(store_url: str, tmp_path: Path) -> None:
    with HistoryStore(store_url) as store:
        for entry in store.entries():  # the module's server is shared by its tests
            assert entry["run_dir"].startswith("/")
        prefix = f"/{tmp_path.name}"
        store.record(_entry(f"{prefix}/b", "OG-9", "2026-12-02T10:00:00+00:00"))
        store.record(_entry(f"{prefix}/a", "OG-9", "2026-11-02T10:00:00+00:00"))
        store.record(_entry(f"{prefix}/c", "OG-8", "2026-12-01T10:00:00+00:00"))
        # a resumed run's end replaces its row
        store.record(_entry(f"{prefix}/b", "OG-9", "2026-12-02T10:00:00+00:00",
                            status="ok", stopped="not-converged"))
        mine = [e for e in store.entries("OG-9") if e["run_dir"].startswith(prefix)]
        assert [e["run_dir"] for e in mine] == [f"{prefix}/a", f"{prefix}/b"]  # oldest first
        assert mine[1]["stopped"] == "not-converged"
        assert mine[0]["as_found"]["joint_error_mm"]["x"]["value_mm"] == 0.4  # JSON kept
    # a whole run recorded there through [history] url, and listed by the command
    result = _run(tmp_path / "runs", "OG-PG", history={"url": store_url})
    listed = orthocal("history", "--db", store_url, "--machine", "OG-PG", "--json",
                      cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    assert result["run_dir"] in [e["run_dir"] for e in json.loads(listed.stdout)["runs"]]


def test_a_machine_recalibrated_from_the_offsets_it_was_left_with(tmp_path: Path,
                                                                   capsys) -> None:
    """The case history is for: one machine calibrated twice into one --out, its x joint
    drifted 10 µm between the runs, the second run starting from the offsets the first
    left in the drive (the virtual drive's memory set to them)."""
    out = tmp_path / "runs"
    first = _run(out, "OG-0007")
    left = [first["offsets_final"][a] for a in "xyz"]
    drifted = (TRUE[0] + 0.010, TRUE[1], TRUE[2])

    def from_first(station: Any) -> None:
        _with("OG-0007")(station)
        station.machine.set_offsets(left)  # the drive kept what the first run wrote

    code = cmd_run.run(simulated(out, seed=5, noise=0.001, true_drho=drifted,
                                 mount_error=0.0, hook=from_first))
    second = json.loads(capsys.readouterr().out)
    assert code in (0, 3) and second["offsets_before"] == pytest.approx(
        dict(zip("xyz", left, strict=True)), abs=1e-9)
    listed = json.loads(orthocal("history", "--out", str(out), "--machine", "OG-0007",
                                 "--json", cwd=tmp_path).stdout)
    assert [e["run_dir"] for e in listed["runs"]] == [first["run_dir"], second["run_dir"]]
    compared = orthocal("compare", first["run_dir"], second["run_dir"], "--json",
                        cwd=tmp_path)
    assert compared.returncode == 0, compared.stderr
    changes = json.loads(compared.stdout)["changes"]
    assert abs(changes["drho_x"]["change_mm"] - 0.010) < 0.004
    assert changes["drho_x"]["significant"]
    for name in ("drho_y", "drho_z"):
        assert abs(changes[name]["change_mm"]) < 0.004, (name, changes[name])
    # the second run's report says what changed since the first, with compare's numbers
    assert "since_last" not in first
    since = second["since_last"]
    assert since["previous_run"] == first["run_dir"] and since["previous_state"] == "as left"
    assert since["joint_error_mm"]["x"]["change"] == pytest.approx(changes["drho_x"]["change_mm"])
    assert since["joint_error_mm"]["x"]["significant"]
    # y did not drift: whether its change is called significant is a 95 % draw (one run
    # in twenty), so what is checked is that the call is the one its numbers make
    y = since["joint_error_mm"]["y"]
    assert y["significant"] == (abs(y["change"]) > y["interval_95"]), y
    run_dir = Path(second["run_dir"])
    on_disk = json.loads((run_dir / "result.json").read_text())
    assert on_disk["since_last"] == since
    assert errors("result", on_disk) == []
    page = (run_dir / "report.html").read_text()
    assert "Since the last calibration" in page and first["run_dir"] in page
    assert "Since the last calibration" not in (Path(first["run_dir"]) / "report.html") \
        .read_text()
    summary = report.summary_text(second)
    x_line = next(line for line in summary.splitlines() if "joint x e " in line)
    assert "since last" in summary and x_line.endswith("  significant")
    # a figure of the two runs for the machine's file
    figure = tmp_path / "og7.svg"
    drawn = orthocal("history", "--out", str(out), "--machine", "OG-0007", "--plot",
                     str(figure), cwd=tmp_path)
    assert drawn.returncode == 0, drawn.stderr
    assert "OG-0007" in " ".join(ET.parse(figure).getroot().itertext())
    # the drive holds what the runs wrote: TwinCAT must not be told it again
    assert second["offsets_held_by"] == "controller"
    refused = orthocal("export", second["run_dir"], "--to", "twincat", cwd=tmp_path)
    assert refused.returncode == 2 and "correct the machine twice" in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1


def _frame_values(frame: dict[str, Any], key: str) -> list[float]:
    return [frame[key][a]["value_mm"] for a in "xyz"]


def test_the_record_keeps_its_rollbacks_and_says_so_first(tmp_path: Path) -> None:
    """A rollback is an event of the run: kept beside any other, refused where there
    is nothing to undo, said first by resume and the report, and warned of where the
    machine has later runs; the history's as left is what the run left."""
    out = tmp_path / "runs"
    done = _run(out, "OG-RB")
    run_dir = Path(done["run_dir"])
    rem = done["remaining"]["estimate"]
    # as left, the machine runs with the Δρ the last verification found left (a few µm);
    # as found, with the one it was found with (TRUE, 0.2–0.4 mm): not the same frame
    with HistoryStore(default_url(out)) as store:
        (entry,) = store.entries("OG-RB")
        store.record(_entry("/elsewhere/later", "OG-RB", "2099-01-01T00:00:00+00:00"))
        store.record(_entry("/elsewhere/of-another", "OG-2", "2099-01-02T00:00:00+00:00"))
        store.record(_entry("/elsewhere/earlier", "OG-RB", "2000-01-01T00:00:00+00:00"))
    left, found = entry["as_left"], entry["as_found"]
    assert _frame_values(left, "drho_mm") == pytest.approx(
        [rem[f"drho_{a}"] for a in "xyz"], abs=1e-9)
    assert _frame_values(found, "drho_mm") == pytest.approx(list(TRUE), abs=0.01)
    assert all(abs(v) < 0.01 for v in _frame_values(left, "drho_mm"))
    assert left["offsets_mm"] == pytest.approx(done["offsets_final"], abs=1e-12)
    # e, the machine's own, is what compare reads: the same machine at both ends
    assert _frame_values(left, "joint_error_mm") == pytest.approx(
        _frame_values(found, "joint_error_mm"), abs=1e-6)

    back = cli("rollback", str(run_dir), "--yes", cwd=tmp_path)
    assert back.returncode == 0, back.stderr
    (warning,) = [line for line in back.stderr.splitlines() if "later run" in line]
    assert "machine OG-RB has 1 later run(s)" in warning and "/elsewhere/later" in warning
    assert "of-another" not in warning and "earlier" not in warning
    record = json.loads((run_dir / "result.json").read_text())
    first = record["rolled_back"]
    assert record["rollbacks"] == [first] and errors("result", record) == []

    # nothing left to undo: refused in one line saying when, nothing journaled
    journal = (run_dir / "journal.jsonl").read_bytes()
    again = cli("rollback", str(run_dir), "--yes", cwd=tmp_path)
    assert again.returncode == 2 and again.stdout == ""
    (line,) = again.stderr.strip().splitlines()
    assert f"{run_dir} was already rolled back on {first['at']}" in line, line
    assert "nothing to undo" in line
    assert (run_dir / "journal.jsonl").read_bytes() == journal
    assert json.loads((run_dir / "result.json").read_text())["rollbacks"] == [first]

    # resume and the report say so first: the tool as found, and what to do
    resumed_run = cli("resume", str(run_dir), cwd=tmp_path)
    head = resumed_run.stdout.splitlines()[0]
    tool_before = done["accuracy"]["before"]["rms_mm"]
    assert "rolled back" in head and f"at the tool {1000 * tool_before:.1f} µm RMS" in head
    assert "back as found" in head and "calibrate it again" in head, head
    assert "nothing further" not in resumed_run.stdout
    assert "rolled back" in resumed_run.stderr.splitlines()[0]
    page = (run_dir / "report.html").read_text()
    assert '<span class="status st-refused st-rolled-back">Rolled back</span>' in page
    glance = page[page.index('id="first-screen"'):]
    verdict = glance[glance.index("<dd>") + 4:glance.index("</dd>")]
    assert "rolled back" in verdict and "back as found" in verdict, verdict
    assert "<b>Write-back: written</b>" not in page
    assert "<b>Write-back: written, then rolled back</b>" in page

    # after the rollback the run left the machine as found; e has not moved
    with HistoryStore(default_url(out)) as store:
        (entry,) = [e for e in store.entries("OG-RB") if e["run_dir"] == done["run_dir"]]
    assert _frame_values(entry["as_left"], "drho_mm") == pytest.approx(
        _frame_values(entry["as_found"], "drho_mm"), abs=1e-6)
    assert _frame_values(entry["as_left"], "joint_error_mm") == pytest.approx(
        _frame_values(left, "joint_error_mm"), abs=1e-12)
    assert entry["tool_after_rms_mm"] == pytest.approx(tool_before)

    # offsets changed since (the drive's memory edited, as a later run would): a second
    # rollback undoes something, and is kept beside the first, which stays as it was
    nvram = run_dir / "controller_nvram.json"
    memory = json.loads(nvram.read_text())
    memory["offsets_mm"] = [0.05, -0.02, 0.01]
    nvram.write_text(json.dumps(memory))
    second = cli("rollback", str(run_dir), "--yes", cwd=tmp_path)
    assert second.returncode == 0, second.stderr
    record = json.loads((run_dir / "result.json").read_text())
    assert record["rollbacks"][0] == first and len(record["rollbacks"]) == 2
    assert record["rolled_back"] == record["rollbacks"][1]
    assert record["rolled_back"]["replaced"] == pytest.approx({"x": 0.05, "y": -0.02,
                                                               "z": 0.01}, abs=1e-9)
    stages = [json.loads(x)["stage"] for x in (run_dir / "journal.jsonl").read_text()
              .splitlines() if json.loads(x)["type"] == "rollback"]
    assert stages == ["intent", "done", "intent", "done"]

    # an export of a machine with later runs names them too
    exported = cli("export", str(run_dir), "--to", "csv", "--force", cwd=tmp_path)
    assert exported.returncode == 0, exported.stderr
    assert "machine OG-RB has 1 later run(s)" in exported.stderr
    assert "/elsewhere/later" in exported.stderr
