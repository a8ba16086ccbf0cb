"""``orthocal export``: a run's final offsets in a controller's own terms, the new value
beside the old and the sign taken from the conventions, not left to guess."""

from __future__ import annotations

import configparser
import csv
import json
from pathlib import Path
from typing import Any

import pytest
from builders import FAST, Completed, cli, simulated
from result_builders import golden_result

from station.commands import run as cmd_run
from station.history.controller_terms import ExportError, csv_lines, linuxcnc
from station.history.twincat import twincat
from station.record.exportable import HEADER
from station.record.quantity_text import plus_minus
from station.record.result import RunResult
from station.record.result_statement import Quantity
from station.report import as_result

GATEWAY_NO_OFFSETS = Path(__file__).resolve().parents[3] / "examples" / "maps" / \
    "gateway-3x1-no-offsets.toml"

INI = """[EMC]
MACHINE = og
[JOINT_0]
TYPE = LINEAR
HOME_OFFSET = 10.0
[JOINT_1]
HOME_OFFSET = -2.5 ; the y joint
[JOINT_2]
HOME_OFFSET = 0
"""


#: The statement's reversal per joint in this test's record: value, U and decision.
PLAYS = {"reversal_x": {"value": 0.02, "expanded": 0.002, "decision": "compensate"},
         "reversal_y": {"value": 0.0003, "expanded": 0.002, "decision": "none"},
         "reversal_z": {"value": 0.0, "expanded": 0.002, "decision": "none"}}


def _with(q: dict[str, Any], **said: Any) -> dict[str, Any]:
    """A quantity of the statement with ``said`` (value, expanded, decision) in it, its
    interval following its value and U."""
    q = {**q, **said}
    q["interval_95"] = [q["value"] - q["expanded"], q["value"] + q["expanded"]]
    return q


def document(**extra: Any) -> dict[str, Any]:
    """A run's result.json (the golden run's) with the offsets, machine and reversal
    the export is checked against."""
    doc = golden_result()
    doc["machine"]["id"] = "OG-1"
    doc["reversal"].update(value_mm={"x": 0.02, "y": 0.0003, "z": 0.0},
                           std_errors_mm={"x": 0.001, "y": 0.001, "z": 0.001})
    # the statement's reversals, as the decision table decides them: x a play to
    # compensate, y and z within their uncertainty
    doc["statement"] = [_with(q, **PLAYS[q["name"]]) if q["name"] in PLAYS else q
                        for q in doc["statement"]]
    return {**doc, "run_dir": "/runs/run-1", "offsets_held_by": "station",
            "offsets_before": {"x": 0.1, "y": 0.0, "z": -0.2},
            "offsets_final": {"x": 0.6, "y": -0.3, "z": -0.2}, **extra}


def result(**extra: Any) -> RunResult:
    """:func:`document` as the record the export reads."""
    return as_result(document(**extra))


def home_offsets(text: str) -> dict[str, float]:
    """As LinuxCNC would read them: configparser, comments stripped."""
    ini = configparser.ConfigParser(strict=False, interpolation=None,
                                    inline_comment_prefixes=("#", ";"))
    ini.optionxform = str
    ini.read_string(text)
    return {s: float(ini.get(s, "HOME_OFFSET")) for s in ini.sections()
            if ini.has_option(s, "HOME_OFFSET")}


def test_the_carriage_stays_where_the_station_put_it() -> None:
    """Station: a commanded ρ puts the carriage at ρ + o + c. LinuxCNC: at switch + ρ −
    HOME_OFFSET. Matched before the run, the exported HOME_OFFSET must put every
    commanded ρ where the offsets the run left put it."""
    doc = document()
    r = as_result(doc)
    switch, c = {"x": 25.0, "y": 25.0, "z": 25.0}, {"x": 3.0, "y": -1.0, "z": 0.5}
    old = {a: switch[a] - doc["offsets_before"][a] - c[a] for a in "xyz"}
    ini = "".join(f"[JOINT_{j}]\nHOME_OFFSET = {old[a]!r}\n" for j, a in enumerate("xyz"))
    new = home_offsets(linuxcnc(r, ini))
    for j, a in enumerate("xyz"):
        for rho in (-100.0, 0.0, 60.0):
            assert switch[a] + rho - new[f"JOINT_{j}"] == pytest.approx(
                rho + doc["offsets_final"][a] + c[a], abs=1e-9)


def test_linuxcnc_keeps_the_ini_writes_old_beside_new_and_backlash_when_asked() -> None:
    text = linuxcnc(result(), INI, source="og.ini")
    assert home_offsets(text) == pytest.approx({"JOINT_0": 9.5, "JOINT_1": -2.2,
                                                "JOINT_2": 0.0})
    assert "HOME_OFFSET was 10.000000" in text and "machine OG-1" in text
    assert "MACHINE = og" in text and "TYPE = LINEAR" in text  # the rest as it was
    assert "BACKLASH" not in text  # not asked for
    asked = linuxcnc(result(), INI, source="og.ini", backlash=True)
    # the statement's decision (the decision table's one rule), said beside it
    assert "BACKLASH = 0.020000    # the run's statement: reversal_x +20.0 ± 2.0 µm (95 %), " \
        "the decision table: compensate" in asked
    assert asked.count("BACKLASH = ") == 1
    assert "# BACKLASH not written: the run's statement: reversal_y +0.3 ± 2.0 µm (95 %), " \
        "not beyond its uncertainty (the decision table: none)" in asked
    # a drive that holds the offsets itself: LinuxCNC must not correct them again
    with pytest.raises(ExportError, match="correct the machine twice"):
        linuxcnc(result(offsets_held_by="controller"), INI)
    # joints mapped otherwise: x drives joint 2
    swapped = home_offsets(linuxcnc(result(), INI, joints=(2, 1, 0)))
    assert swapped["JOINT_2"] == pytest.approx(-0.5)


def test_what_cannot_be_exported_is_said_naming_the_field() -> None:
    with pytest.raises(ExportError, match=r"og.ini: \[JOINT_2\] has no HOME_OFFSET"):
        linuxcnc(result(), "[JOINT_0]\nHOME_OFFSET = 1\n[JOINT_1]\nHOME_OFFSET = 1\n",
                 source="og.ini")
    with pytest.raises(ExportError, match=r"HOME_OFFSET = 'ten' is not a number"):
        linuxcnc(result(), INI.replace("10.0", "ten"))
    with pytest.raises(ExportError, match="offsets_before"):
        csv_lines(result(offsets_final=None))


def test_the_command(tmp_path: Path) -> None:
    run_dir = tmp_path / "run-1"
    run_dir.mkdir()
    (run_dir / "result.json").write_text(json.dumps(document()))
    (tmp_path / "og.ini").write_text(INI)

    def orthocal(*argv: str) -> Completed:
        return cli("export", str(run_dir), *argv, cwd=tmp_path)

    ok = orthocal("--to", "linuxcnc", "--ini", str(tmp_path / "og.ini"))
    assert ok.returncode == 0 and home_offsets(ok.stdout)["JOINT_0"] == pytest.approx(9.5)
    rows = [r for r in orthocal("--to", "csv").stdout.splitlines() if not r.startswith("#")]
    assert rows[1].startswith("x,0.100000,0.600000,+0.500000,0.020000,OG-1,")
    tc = orthocal("--to", "twincat", "--axes", "X1,Y1,Z1")
    assert tc.returncode == 0 and tc.stdout.count("\nX1,x,") == 1
    for argv, words in ((["--to", "linuxcnc"], "--ini"),
                        (["--to", "linuxcnc", "--ini", "missing.ini"], "cannot read"),
                        (["--to", "linuxcnc", "--ini", "og.ini", "--joints", "0,1"], "--joints"),
                        (["--to", "twincat", "--axes", "X1,Y1"], "--axes"),
                        (["--to", "twincat", "--out", "no/such/dir/f.csv"], "cannot write")):
        bad = orthocal(*argv)
        assert bad.returncode == 2 and words in bad.stderr
        assert len(bad.stderr.strip().splitlines()) == 1 and "Traceback" not in bad.stderr
    # offsets the drive itself holds: neither controller may be told them again
    (run_dir / "result.json").write_text(json.dumps(document(offsets_held_by="controller")))
    for target in (["--to", "twincat"], ["--to", "linuxcnc", "--ini", "og.ini"]):
        refused = orthocal(*target)
        assert refused.returncode == 2 and "correct the machine twice" in refused.stderr
        assert len(refused.stderr.strip().splitlines()) == 1
    (run_dir / "result.json").write_text(json.dumps(document(offsets_before={"x": "?"})))
    broken = orthocal("--to", "twincat")  # not a record: said before anything is exported
    assert broken.returncode == 2 and "result.json: not a result document (offsets_before.x" \
        in broken.stderr and len(broken.stderr.strip().splitlines()) == 1
    # a record whose run stopped before it read the controller: nothing to export
    (run_dir / "result.json").write_text(json.dumps(document(offsets_final=None)))
    stopped = orthocal("--to", "csv")
    assert stopped.returncode == 2 and "offsets_before/offsets_final" in stopped.stderr


def parse_quantity(doc: dict[str, Any]) -> Quantity:
    return Quantity.model_validate(doc)


def twincat_rows(text: str) -> list[dict[str, str]]:
    """The parameter rows, as a person or a PLC would read them: comments skipped."""
    lines = [line for line in text.splitlines() if line and not line.startswith("#")]
    return list(csv.DictReader(lines))


def test_twincat_reference_positions_carry_the_station_s_change() -> None:
    """TwinCAT sets the axis position at the reference cam to R: a carriage commanded
    to ρ sits at cam + ρ − R. With R matched to the offsets before the run, R + change
    must put every commanded ρ where the offsets the run left put it."""
    doc = document()
    r = as_result(doc)
    text = twincat(r)
    rows = twincat_rows(text)
    assert [row["nc_axis"] for row in rows] == ["Axis 1", "Axis 2", "Axis 3"]
    assert all("Reference position for homing" in row["parameter"] for row in rows)
    cam, c = 25.0, {"x": 3.0, "y": -1.0, "z": 0.5}
    for row in rows:
        a = row["joint"]
        change = float(row["change_mm"])
        assert change == pytest.approx(-(doc["offsets_final"][a] - doc["offsets_before"][a]))
        old = cam - doc["offsets_before"][a] - c[a]
        for rho in (-100.0, 0.0, 60.0):
            assert cam + rho - (old + change) == pytest.approx(
                rho + doc["offsets_final"][a] + c[a], abs=1e-9)
        assert row["machine_id"] == "OG-1"
    assert "machine OG-1" in text and "Position Bias" in text and "never both" in text
    assert "MC_BacklashCompensation" not in text  # not asked for
    asked = twincat(r, axes=("X1", "Y1", "Z1"), backlash=True)
    backlash = [row for row in twincat_rows(asked) if "Backlash" in row["parameter"]]
    assert [(row["nc_axis"], row["value_mm"]) for row in backlash] == [("X1", "0.020000")]
    assert asked.count("backlash not written") == 2  # y and z: within their noise
    with pytest.raises(ExportError, match="TwinCAT as well would correct the machine twice"):
        twincat(result(offsets_held_by="controller"))
    with pytest.raises(ExportError, match="--axes"):
        twincat(r, axes=("X1", "Y1"))


def test_twincat_from_a_run_whose_station_held_the_offsets(tmp_path: Path, capsys) -> None:
    true = (0.3, -0.2, 0.1)
    cmd_run.run(simulated(tmp_path / "runs", seed=3, noise=0.001, true_drho=true,
                          procedure={**FAST, "model": "rho", "approach_overrun_mm": 0.1},
                          profile=str(GATEWAY_NO_OFFSETS), backlash="0.03,0,0"))
    done = json.loads(capsys.readouterr().out)
    assert done["offsets_held_by"] == "station"
    out = tmp_path / "og.csv"
    # two cycles a setup leave z undecided: the run is no calibration without --force
    assert done["loop"]["stopped"] == "not-converged"
    refused = cli("export", done["run_dir"], "--to", "twincat", "--out", str(out),
                  cwd=tmp_path)
    assert refused.returncode == 2 and not out.exists()
    made = cli("export", done["run_dir"], "--to", "twincat", "--backlash", "--out", str(out),
               "--force", cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    text = out.read_text()
    header = [line for line in text.splitlines() if line.startswith(HEADER)]
    said = " ".join(line.removeprefix(HEADER).strip() for line in header)
    assert "EXPORTED WITH --force" in said and "the run did not converge (not-converged)" \
        in said and "(95 %, not shown within)" in said, said
    # the joints as left are the statement's, printed as every view prints them
    stated = {q["name"]: q for q in done["statement"]}
    for a in "xyz":
        q = parse_quantity(stated[f"drho_{a}.as_left"])
        assert f"{a} {plus_minus(q)}" in said, (a, said)
    rows = twincat_rows(text)
    for row in rows:
        a = row["joint"]
        if "Reference" not in row["parameter"]:
            continue
        # from zero offsets the change is −offsets_final, about +Δρ (o = −Δρ)
        assert float(row["change_mm"]) == pytest.approx(
            -(done["offsets_final"][a] - done["offsets_before"][a]), abs=1e-6)
        assert abs(float(row["change_mm"]) - true["xyz".index(a)]) < 0.005
    backlash = {row["joint"]: float(row["value_mm"]) for row in rows
                if "Backlash" in row["parameter"]}
    assert set(backlash) == {"x"} and abs(backlash["x"] - 0.03) < 0.01


#: What the record of a run that did not resolve the machine says (the engine's words,
#: station.analysis.verdict.not_converged), per case: its changes and the words the
#: refusal and the forced header must carry.
DETAIL = ("after 2 pass(es) of its last verification, Δρ_x may still be off by up to 17.3 µm "
          "at 95 %, more than converge_mm = 2 µm")


def unresolved(case: str) -> dict[str, Any]:
    doc = document()
    last = doc["iterations"][-1]
    if case in ("not converged", "both"):
        doc["converged"] = False
        doc["loop"].update(stopped="not-converged", detail=DETAIL)
        doc["message"] = f"closed loop did not converge: {DETAIL}"
        last.update(verdict="unproven", shown_within_95_mm={
            "drho_x": 0.0173, "drho_y": 0.0021, "drho_z": 0.0009})
        doc["statement"] = [_with(q, value=0.0021, expanded=0.0152,
                                  decision="not shown within")
                            if q["name"] == "drho_x.as_left" else q for q in doc["statement"]]
    if case in ("ambiguous", "both"):
        last.update(model="rho+tilt", ambiguity={"explained_by": "rho+form",
                                                 "apart_mm": {"drho_x": 0.015}})
    return doc


REASONS = {"not converged": ["the run did not converge (not-converged): Δρ_x as left "
                             "+2.1 ± 15.2 µm (95 %, not shown within)"],
           "ambiguous": ["its last round could not tell the axes' tilts from the legs' bows "
                         "(rho+tilt or rho+form)"]}
REASONS["both"] = REASONS["not converged"] + REASONS["ambiguous"]


def header_of(text: str) -> str:
    """The export's header comment, its lines joined as one text."""
    return " ".join(line.removeprefix(HEADER).strip() for line in text.splitlines()
                    if line.startswith(HEADER))


@pytest.mark.parametrize("case", REASONS)
def test_an_unresolved_run_is_exported_only_with_force(case: str, tmp_path: Path) -> None:
    run_dir = tmp_path / "run-1"
    run_dir.mkdir()
    (run_dir / "result.json").write_text(json.dumps({**unresolved(case),
                                                     "run_dir": str(run_dir)}))
    (tmp_path / "og.ini").write_text(INI)
    out = tmp_path / "exported"
    for target in (["--to", "linuxcnc", "--ini", "og.ini"], ["--to", "twincat"],
                   ["--to", "csv"]):
        refused = cli("export", str(run_dir), *target, "--out", str(out), cwd=tmp_path)
        assert refused.returncode == 2 and refused.stdout == "", (target, refused.stderr)
        (line,) = refused.stderr.strip().splitlines()
        assert line.startswith(f"orthocal: error: {run_dir}: not exported: ")
        assert all(reason in line for reason in REASONS[case]) and "--force" in line, line
        assert ("second gauge plane" in line) == (case != "not converged")
        assert not out.exists()
        forced = cli("export", str(run_dir), *target, "--out", str(out), "--force",
                     cwd=tmp_path)
        assert forced.returncode == 0, forced.stderr
        said = header_of(out.read_text())
        assert f"run {run_dir}, machine OG-1" in said
        assert "EXPORTED WITH --force, NOT A CALIBRATION TO TRUST AS IT STANDS" in said
        assert all(reason in said for reason in REASONS[case]), said
        # the verdict, and the run's own words where it has them
        assert ("verdict: NOT CONVERGED (not-converged)" in said) == (case != "ambiguous")
        assert ("AMBIGUOUS last round" in said) == (case != "not converged")
        assert (f"The run says: {DETAIL}" in said) == (case != "ambiguous")
        out.unlink()


def test_every_export_names_the_run_the_machine_and_the_verdict(tmp_path: Path) -> None:
    anonymous = result()
    anonymous.machine.id = None
    ini = linuxcnc(anonymous, INI, source="og.ini")
    for text in (ini, twincat(anonymous), csv_lines(anonymous)):
        said = header_of(text)
        writes = anonymous.loop.write_backs if anonymous.loop is not None else None
        assert said.startswith("run /runs/run-1, machine no [machine] id verdict: "
                               "converged: every joint offset shown within ±2.5 µm at "
                               f"95 %, {writes} write-back(s)"), said
        assert "--force" not in said
    # an export onto the INI an earlier one wrote writes its header afresh, once
    again = linuxcnc(result(), ini, source="og.ini")
    assert header_of(again).count("verdict:") == 1 and "machine OG-1" in header_of(again)
    assert "no [machine] id" not in header_of(again)
    # a rolled-back run says so: its offsets are no longer those the controller holds
    back = result(rolled_back={"at": "2026-12-01T10:00:00+00:00",
                               "replaced": {"x": 0.6, "y": -0.3, "z": -0.2},
                               "restored": {"x": 0.1, "y": 0.0, "z": -0.2}})
    assert "rolled back on 2026-12-01T10:00:00+00:00" in header_of(csv_lines(back))
