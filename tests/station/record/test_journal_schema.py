"""The journal's shipped schema (station/record/schemas/journal.schema.json) states
every line of a run's journal.jsonl: no object in it is open (each is closed, or a
map with typed values), and the lines of real runs — a simulated run, a power cut,
a pulled gauge, a resume, a rollback, and every way a write-back ends — validate
against it with an independent validator (jsonschema), as another tool reading them
would. A journal written by the first version that ran is read as it is."""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import FAST, Rig, no_figures_file, on_setup, simulated
from jsonschema import Draft202012Validator
from pydantic import BaseModel, ConfigDict, JsonValue

from drivers.sim.fake import FakeRig
from drivers.sim.station import VirtualStation
from station.commands import run as cmd_run
from station.engine.writeback import rollback, write_back
from station.errors import RunFailed
from station.record import schema_files as schema
from station.record.journal_file import Journal, read_journal, read_records
from station.record.state import RunState

DATA = Path(__file__).parents[2] / "data"
#: Where a schema holds schemas: one (items, an object's typed values), a list of them
#: (a union, a tuple), or a map of them (an object's properties, the definitions).
ONE, MANY, NAMED = ("items", "additionalProperties"), ("anyOf", "oneOf", "allOf",
                                                       "prefixItems"), ("properties", "$defs")
#: What makes a schema say what it takes (a schema with none of these takes anything).
TYPED = ("type", "$ref", "const", "enum", "anyOf", "oneOf", "allOf")


def open_parts(node: dict[str, Any], where: str = "#") -> Iterator[str]:
    """Where the schema ``node`` takes what it does not state: an object whose other
    properties are allowed (additionalProperties absent or true), or a value of any
    kind (a schema that names no type)."""
    if where != "#" and not where.endswith("/$defs") and not any(k in node for k in TYPED):
        yield f"{where}: any value"
    if node.get("type") == "object" or "properties" in node:
        extra = node.get("additionalProperties", True)
        if extra is not False and not (isinstance(extra, dict) and any(k in extra
                                                                       for k in TYPED)):
            yield f"{where}: other properties allowed"
    for key in ONE:
        if isinstance(node.get(key), dict):
            yield from open_parts(node[key], f"{where}/{key}")
    for key in MANY:
        for n, child in enumerate(node.get(key, [])):
            yield from open_parts(child, f"{where}/{key}/{n}")
    for key in NAMED:
        for name, child in node.get(key, {}).items():
            yield from open_parts(child, f"{where}/{key}/{name}")


@cache
def validator() -> Draft202012Validator:
    doc = json.loads(schema.shipped("journal"))
    Draft202012Validator.check_schema(doc)
    return Draft202012Validator(doc)


def invalid_lines(path: Path) -> list[str]:
    """Every line of the journal at ``path`` that the shipped schema refuses, and why."""
    return [f"line {n}: {'/'.join(map(str, e.absolute_path))}: {e.message[:200]}"
            for n, line in enumerate(path.read_text().splitlines(), start=1)
            for e in validator().iter_errors(json.loads(line))]


def kinds(path: Path) -> Counter[str]:
    """The journal's records by type, an event's by its kind, a stage's by its stage."""
    return Counter(r["type"] + (f":{r['event']['event']}" if r["type"] == "event" else
                                f":{r['stage']}" if "stage" in r else "")
                   for r in read_journal(path))


def test_the_shipped_journal_schema_has_no_open_object() -> None:
    doc = json.loads(schema.shipped("journal"))
    assert list(open_parts(doc)) == []
    header = doc["$defs"]["Header"]["properties"]
    assert header["config"] == {"$ref": "#/$defs/StationConfig",
                                "description": "the station config (config.toml's model)"}
    # a map keyed by data is typed: the gauges' readings at a stop after a guard stop
    recovery = doc["$defs"]["GuardRecovery"]["properties"]
    assert recovery["readings_mm"]["additionalProperties"] == {"type": "number"}


def test_an_open_object_is_found() -> None:
    class Loose(BaseModel):
        model_config = ConfigDict(extra="allow")
        anything: JsonValue
        body: dict[str, Any]
        typed: dict[str, float]

    found = list(open_parts(Loose.model_json_schema()))
    assert found == ["#: other properties allowed", "#/properties/body: other properties "
                     "allowed", "#/$defs/JsonValue: any value"]


def test_a_simulated_run_validates_line_by_line(tmp_path: Path, capsys) -> None:
    # one round: its write-back and verification (more rounds journal the same kinds)
    cmd_run.run(simulated(tmp_path, seed=4, true_drho=(0.4, -0.3, 0.2),
                          procedure={**FAST, "max_iterations": 1}))
    capsys.readouterr()
    (run_dir,) = tmp_path.glob("run-*")
    path = run_dir / "journal.jsonl"
    assert invalid_lines(path) == []
    seen = kinds(path)
    for kind in ("header", "setup", "reading", "cycle", "setup_done", "identification",
                 "event:plunger-guard-learned", "writeback:backup", "writeback:intent",
                 "writeback:done", "verification", "finished"):
        assert seen[kind] >= 1, kind


def _power_cut_and_pulled_gauge(rig: Rig, station: VirtualStation) -> None:
    """The run's station: gauge A's adapter pulled for 0.8 s as setup 1 is mounted, a
    power cut (the reference lost) in setup 2's second cycle."""
    if len(rig.stations) > 1:
        return
    f = station.controller.faults

    def cut() -> None:
        f.power_cut_s, f.power_cut_loses_reference = 1.0, True
        f.power_cut_after_moves = 10

    on_setup(station, 1, lambda: station.indicators["A"].unplug_for(0.8))
    on_setup(station, 2, cut)


def test_a_fault_a_resume_and_a_rollback_validate(tmp_path: Path, orthocal) -> None:
    rig = Rig()
    argv = ["--simulate", no_figures_file(tmp_path), "--seed", "5", "--true-drho",
            "0.3,-0.2,0.1", "--noise", "0", "--sim-speed", "500",
            "--sim-procedure", json.dumps(FAST)]
    failed = orthocal("run", *argv, "--out", str(tmp_path / "runs"), rig=rig,
                      prepare=_power_cut_and_pulled_gauge)
    assert failed.code == 1, failed.err
    path = failed.run_dir / "journal.jsonl"
    resumed = orthocal("resume", str(failed.run_dir), "--json", rig=rig)
    assert resumed.code in (0, 3), resumed.err
    back = orthocal("rollback", str(failed.run_dir), "--json", rig=rig)
    assert back.code == 0, back.err
    assert invalid_lines(path) == []
    seen = kinds(path)
    for kind in ("event:reopen", "event:reopened", "event:reconnect", "event:reconnected",
                 "event:reference-check", "fault", "resumed", "event:not-homed", "homed",
                 "reference-check", "writeback:done", "finished", "rollback:intent",
                 "rollback:done"):
        assert seen[kind] >= 1, (kind, seen)
    assert np.allclose(rig.stations[-1].offsets, [0.0, 0.0, 0.0], atol=1e-9)


class _Yes:
    def __init__(self, answer: bool = True) -> None:
        self.answer = answer

    def mount(self, *args: object) -> None:
        raise AssertionError("write-back never asks for a mounting")

    def confirm(self, question: str) -> bool:
        return self.answer


def _write_backs(run_dir: Path, journal: Journal) -> None:
    """Every way a write-back round ends, on the fake drive, each its own round."""
    axes = FakeRig().axes
    drho = {"drho_x": 0.1, "drho_y": -0.2, "drho_z": 0.05}

    def round_(n: int, **kw: Any) -> str:
        args: dict[str, Any] = {"controller": axes, "identified": drho,
                                "max_abs_offset_mm": 3.0, "run_dir": run_dir,
                                "journal": journal, "operator": _Yes(), "round": n}
        return write_back(**{**args, **kw}).status

    assert round_(1) == "written"
    assert round_(2, identified={"dL_x": 0.1}) == "skipped"
    assert round_(3, max_abs_offset_mm=0.01) == "refused"
    assert round_(4, operator=_Yes(False)) == "declined"
    axes.bad_readbacks = 1  # the write reads back off; the backup is written back
    assert round_(5) == "failed-restored"
    axes.bad_readbacks = 2  # and the backup too
    with pytest.raises(RunFailed, match="restoring the backup failed too"):
        round_(6)
    real = axes.write_offsets

    def interrupted(offsets: Any) -> Any:
        axes.write_offsets = real  # type: ignore[method-assign]
        raise KeyboardInterrupt

    axes.write_offsets = interrupted  # type: ignore[method-assign]
    with pytest.raises(KeyboardInterrupt):
        round_(7)
    rollback(axes, run_dir, journal)


def test_every_write_back_stage_and_a_rollback_validate(tmp_path: Path) -> None:
    path = tmp_path / "journal.jsonl"
    with Journal(path) as journal:
        _write_backs(tmp_path, journal)
    assert invalid_lines(path) == []
    seen = kinds(path)
    assert set(seen) == {f"writeback:{s}" for s in (
        "backup", "intent", "done", "skipped", "refused", "declined", "failed-restored",
        "failed", "interrupted-restored")} | {"rollback:intent", "rollback:done"}
    assert RunState.of(read_records(path)).writebacks[7]["interrupted-restored"].round == 7


def test_a_journal_of_the_first_version_that_ran_is_read_as_it_is() -> None:
    """journal_a003a32.jsonl: `orthocal run --simulate --seed 5 --true-drho
    0.3,-0.2,0.1 --noise 0.001 --yes` as commit a003a32 (the first end-to-end run)
    wrote it. What resume reads of it is there: the header's simulation, the steps
    done, the offsets written."""
    path = DATA / "journal_a003a32.jsonl"
    assert invalid_lines(path) == []
    state = RunState.of(read_records(path))
    assert state.header is not None and state.header.simulation is not None
    assert state.header.simulation.true_drho == (0.3, -0.2, 0.1)
    assert state.header.simulation.as_json()["seed"] == 5
    assert len(state.cycles) == 18 and len(state.setups_done) == 6
    assert state.finished is not None and state.finished.status == "ok"
    # the offsets written: -Δρ as identified, within a few µm of the truth
    assert state.offsets_held is not None
    np.testing.assert_allclose(state.offsets_held, [-0.3, 0.2, -0.1], atol=0.005)
