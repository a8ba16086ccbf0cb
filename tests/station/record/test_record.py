"""The run's record has a schema (station.record): the one we ship is the one the
models make, and real runs' result.json and journal lines validate against it with
an independent validator (jsonschema), as another tool reading them would."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from builders import simulated
from result_builders import golden_result
from schema_check import errors

from station.commands import run as cmd_run
from station.commands.cli import main
from station.commands.history import read_result
from station.errors import BadInput
from station.record import schema_files as schema
from station.record.migrate import migrate
from station.record.result import SCHEMA_VERSION, RunResult

DATA = Path(__file__).parents[2] / "data"
GOLDEN = DATA / "golden_run"


@pytest.mark.parametrize("kind", schema.KINDS)
def test_the_shipped_schema_is_the_models(kind: str, capsys) -> None:
    # after changing a model: python -m station schema KIND > station/record/schemas/...
    assert schema.shipped(kind) == schema.dumps(kind)
    assert main(["schema", kind]) == 0
    assert capsys.readouterr().out == schema.shipped(kind)
    assert json.loads(schema.shipped(kind))["schema_version"] == SCHEMA_VERSION == 2


def _check_run_dir(run_dir: Path) -> dict[str, Any]:
    result = json.loads((run_dir / "result.json").read_text())
    assert errors("result", result) == []
    if (run_dir / "model.json").exists():
        assert errors("model", json.loads((run_dir / "model.json").read_text())) == []
    for n, line in enumerate((run_dir / "journal.jsonl").read_text().splitlines()):
        assert errors("journal", json.loads(line)) == [], n
    return result


def test_a_run_and_a_refused_write_back_validate(tmp_path: Path, capsys) -> None:
    cmd_run.run(simulated(tmp_path / "ok", seed=3, true_drho=(0.3, -0.2, 0.1)))
    capsys.readouterr()
    (ok,) = (tmp_path / "ok").glob("run-*")
    assert _check_run_dir(ok)["schema_version"] == SCHEMA_VERSION
    machine = json.loads((ok / "model.json").read_text())
    assert machine["format"] == "orthocal machine model 1"
    # a field the record does not declare, or a unit it does not know, is caught
    assert any("unexpected" in e for e in errors("model", {**machine, "bows": {}}))
    assert errors("model", {**machine, "units": {**machine["units"], "tilt": "rad"}})
    # a correction beyond max_abs_offset_mm is refused: another status, other records
    cmd_run.run(simulated(tmp_path / "refused", seed=3, true_drho=(0.3, -0.2, 0.1),
                          writeback={"max_abs_offset_mm": 0.05}))
    capsys.readouterr()
    (refused,) = (tmp_path / "refused").glob("run-*")
    assert _check_run_dir(refused)["writeback"]["status"] == "refused"


def test_the_golden_run_validates_and_drift_does_not() -> None:
    result = json.loads((GOLDEN / "result.json").read_text())
    result.update(run_dir="RUN_DIR", started="WHEN", finished="WHEN", duration_s=1.0)
    result["timing"].update(wall_s=1.0, operator_s=0.0)
    assert errors("result", result) == []
    # a field the models do not declare, or a status they do not know, is caught
    assert any("unexpected" in e for e in errors("result", {**result, "offsets_new": 1}))
    assert errors("result", {**result, "status": "fine"})
    # a journal line of an unknown type, or a reading without values
    assert errors("journal", {"type": "mystery", "t": 0.0})
    assert errors("journal", {"type": "reading", "t": 0.0, "stop": "m:0:0:0", "indicator": "A"})


#: Results written by older versions: the golden run as version 1 wrote it (times and
#: the run directory taken out, as tests/station/engine/test_unchanged.py does), and two runs from
#: before the schema (no schema_version).
OLDER = {"result_v1.json": 1, "result_tilted_joints.json": None,
         "result_tilted_tool.json": None}


@pytest.mark.parametrize("name", sorted(OLDER))
def test_an_older_result_is_read_as_the_current_version(name: str, tmp_path: Path) -> None:
    old = json.loads((DATA / name).read_text())
    assert old.get("schema_version") == OLDER[name]
    snapshot = json.dumps(old)
    doc = migrate(old)
    assert json.dumps(old) == snapshot  # the caller's document is left as it was
    assert doc["schema_version"] == SCHEMA_VERSION and migrate(doc) == doc
    for key, value in (("run_dir", "RUN_DIR"), ("started", "WHEN"), ("finished", "WHEN"),
                       ("duration_s", 1.0)):
        doc.setdefault(key, value)
    doc["timing"].setdefault("wall_s", 1.0)
    assert errors("result", doc) == []
    expected = RunResult.model_validate_json(json.dumps(doc), strict=True)
    # every reader of a run directory reads it so (orthocal report, compare, export,
    # the history): the file as its run wrote it, what the test data leave out put back
    whole = {"run_dir": "RUN_DIR", "started": "WHEN", "finished": "WHEN", "duration_s": 1.0,
             **old, "timing": {"wall_s": 1.0, **old["timing"]}}
    (tmp_path / "result.json").write_text(json.dumps(whole))
    record = read_result(str(tmp_path))[1]
    assert record.schema_version == SCHEMA_VERSION and record == expected


def test_a_result_this_version_cannot_read_is_one_line_naming_the_file(
        tmp_path: Path) -> None:
    """Torn, not a record, or of a later version: one line naming result.json (a
    command's bad input, exit 2), never a traceback or a half-read record."""
    golden = golden_result()
    path = tmp_path / "result.json"
    for text, words in (("{\"status\": \"ok\"", "not a result document"),
                        ("[1, 2]", "not a JSON object"),
                        (json.dumps({**golden, "schema_version": SCHEMA_VERSION + 1}),
                         f"schema_version {SCHEMA_VERSION + 1}, written by a later"),
                        (json.dumps({**golden, "status": "fine"}), "status")):
        path.write_text(text)
        with pytest.raises(BadInput) as got:
            read_result(str(tmp_path))
        said = str(got.value)
        assert said.startswith(f"{path}: ") and words in said and "\n" not in said, said


def test_an_old_journals_simulation_is_read_with_what_that_run_had() -> None:
    """Headers from before a simulated error existed lack it, or hold null: the run
    had none of it, said once (station.record.simulated)."""
    from station.record.simulated import SimulationParams

    old = {"seed": 4, "true_drho": [0.1, 0.2, 0.3], "true_dl": [0, 0, 0], "noise_mm": 0.002,
           "true_tilt": None, "backlash_mm": None, "indicators": 6}
    sim = SimulationParams.from_header(old)
    assert sim.true_tilt == sim.true_gap == sim.backlash_mm == sim.leg_bow_mm == (0, 0, 0)
    assert sim.mount_error_mm == 0.0 and sim.gauge_scales(6) == [0.0] * 6
    assert sim.true_drho == (0.1, 0.2, 0.3) and sim.indicators == 6
    # what a run draws now is kept as it is, one scale error per gauge included
    new = SimulationParams.from_header({**old, "gauge_scale": [0.001, -0.002],
                                        "mount_error_mm": 5.0})
    assert new.gauge_scales(2) == [0.001, -0.002] and new.mount_error_mm == 5.0
    with pytest.raises(ValueError):
        SimulationParams.from_header({**old, "true_drho": [0.1, 0.2]})


#: What makes a JSON Schema say something of a value: without any of these a value of
#: any type would pass (an open section).
_SAYS = ("type", "$ref", "anyOf", "oneOf", "allOf", "const", "enum")


def open_sections(node: object, where: str = "#") -> list[str]:
    """Where the schema ``node`` lets through what it does not declare: an object with
    properties that admits others, a map whose values are untyped, or a value of any
    type at all."""
    found: list[str] = []
    if isinstance(node, list):
        for i, item in enumerate(node):
            found += open_sections(item, f"{where}/{i}")
        return found
    if not isinstance(node, dict):
        return found
    extra = node.get("additionalProperties")
    if "properties" in node and extra is not False:
        found.append(f"{where}: properties, and others admitted ({extra!r})")
    if node.get("type") == "object" and "properties" not in node and \
            (not isinstance(extra, dict) or not any(k in extra for k in _SAYS)):
        found.append(f"{where}: an object of untyped values")
    for name, sub in node.get("properties", {}).items():
        if not any(k in sub for k in _SAYS):
            found.append(f"{where}/properties/{name}: any type")
    for key, sub in node.items():
        if key not in ("const", "enum", "default", "examples"):
            found += open_sections(sub, f"{where}/{key}")
    return found


def test_a_simulated_runs_result_fits_a_schema_with_no_open_section(tmp_path: Path,
                                                                    capsys) -> None:
    """result.json is typed through: the schema shipped for it closes every section
    and types every value, and a simulated run's file (as the engine writes it, the
    joints' lost motion measured) validates against it."""
    doc = json.loads(schema.shipped("result"))
    assert open_sections(doc) == []
    # the check sees an open section where there is one
    assert open_sections({"properties": {"a": {"type": "object"}, "b": {}}}) == [
        "#: properties, and others admitted (None)", "#/properties/b: any type",
        "#/properties/a: an object of untyped values"]
    code = cmd_run.run(simulated(tmp_path, seed=5, true_drho=(0.4, -0.3, 0.2),
                                 backlash="0.004,0.002,0.003"))
    printed = json.loads(capsys.readouterr().out)
    (run_dir,) = tmp_path.glob("run-*")
    result = json.loads((run_dir / "result.json").read_text())
    assert code in (0, 3), result["message"]
    assert errors("result", result) == []
    assert result["reversal"] is not None and result["iterations"]
    # --json prints the document the file holds
    assert printed == result


def test_a_rollback_is_appended_to_a_record_that_kept_only_the_last(tmp_path: Path) -> None:
    """A record written before rollbacks were kept has ``rolled_back`` alone: it reads
    as it is, that one is its history, and the next rollback is added after it."""
    from station.engine.rolled_back import record_rollback

    old = {"at": "2026-01-02T10:00:00+00:00", "replaced": {"x": 0.5, "y": -0.2, "z": 0.1},
           "restored": {"x": 0.0, "y": 0.0, "z": 0.0}}
    doc = {**golden_result(), "run_dir": str(tmp_path), "rolled_back": old}
    assert "rollbacks" not in doc and errors("result", doc) == []
    (tmp_path / "result.json").write_text(json.dumps(doc))
    _, record = read_result(str(tmp_path))
    assert [b.model_dump() for b in record.rollback_history()] == [old]
    replaced, restored = {"x": 0.3, "y": 0.1, "z": -0.1}, {"x": 0.0, "y": 0.0, "z": 0.0}
    after = record_rollback(tmp_path, replaced, restored, "2026-12-07T18:24:29+00:00",
                            figures=False)
    assert after is not None
    stored = json.loads((tmp_path / "result.json").read_text())
    assert stored["rollbacks"][0] == old and stored["rollbacks"][1]["replaced"] == replaced
    assert stored["rolled_back"] == stored["rollbacks"][1] and stored["rolled_back"] != old
    assert stored["offsets_final"] == restored and errors("result", stored) == []


def test_a_rolled_back_run_that_never_finished_is_not_resumed(tmp_path: Path,
                                                              capsys) -> None:
    """Its journal holds a write-back the controller no longer holds: resumed, the loop
    would measure the machine as found and write its correction again on top."""
    from builders import journal_header

    from station.record.journal_file import Journal

    run_dir = tmp_path / "run-1"
    run_dir.mkdir()
    offsets = {"x": 0.0, "y": 0.0, "z": 0.0}
    with Journal(run_dir / "journal.jsonl") as journal:
        journal.append(journal_header())
        journal.append({"type": "rollback", "stage": "intent", "restore": offsets,
                        "current": {"x": -0.4, "y": 0.3, "z": -0.2}})
        journal.append({"type": "rollback", "stage": "done", "restored": offsets})
    assert main(["resume", str(run_dir), "--yes"]) == 2
    captured = capsys.readouterr()
    (line,) = captured.err.strip().splitlines()
    assert f"{run_dir} was rolled back on " in line and "back as found" in line
    assert "orthocal run" in line and captured.out == ""
