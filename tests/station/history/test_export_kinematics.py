"""``orthocal export RUN_DIR --to linuxcnc --ini MACHINE.ini --kinematics --out DIR``
(docs/design.md, "The geometry in the controller"), without LinuxCNC: the machine's
INI with the orthoglidekins component as its kinematics, the geometry's HAL file and
the component's source, from whole runs of the engine on the Protocol-level fakes
(the held-out machine and a square one, tests/helpers/heldout.py) and from synthetic run
directories (tests/helpers/compensate_runs.py) for the refusals. The example machine
(examples/linuxcnc) is the INI;
tests/station/history/test_linuxcnc.py runs the export in LinuxCNC."""

from __future__ import annotations

import json
import re
import shutil
from importlib import resources
from pathlib import Path

import heldout
import pytest
from compensate_runs import write_run
from test_export import home_offsets  # as LinuxCNC reads HOME_OFFSET

from station.commands import export as cmd_export
from station.commands.cli import main
from station.history.linuxcnc_kins import COMPONENT_FILE, GEOMETRY_HAL
from station.record.exportable import HEADER
from station.record.identified import PINS, identified_machine

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "linuxcnc"
INI = "orthoglide.ini"
L = 310.25  # the example machine's HOME_OFFSET: the joint counts L at the mechanical zero
#: The HAL file writes 9 decimals: each value is the run's to 5e-10 (mm or mrad).
TOL = 1e-9
#: The intervals in its comments have 6 decimals.
IV_TOL = 1e-6


@pytest.fixture(scope="module")
def held_out_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return Path(heldout.held_out(tmp_path_factory.mktemp("held-out"))["run_dir"])


@pytest.fixture(scope="module")
def square_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return Path(heldout.square(tmp_path_factory.mktemp("square"))["run_dir"])


def machine(folder: Path, edit: dict[str, str] | None = None) -> Path:
    """A copy of the example machine in ``folder``, each of ``edit``'s texts in its INI
    replaced; the INI's path."""
    shutil.copytree(EXAMPLE, folder)
    ini = folder / INI
    text = ini.read_text(encoding="utf-8")
    for old, new in (edit or {}).items():
        assert old in text
        text = text.replace(old, new)
    ini.write_text(text, encoding="utf-8")
    return ini


def export(run_dir: Path, ini: Path, out: Path, *extra: str) -> int:
    return main(["export", str(run_dir), "--to", "linuxcnc", "--ini", str(ini),
                 "--kinematics", "--out", str(out), *extra])


def lines_of(text: str, section: str) -> list[str]:
    """The lines of ``[section]``, comments included, as written."""
    out, current = [], ""
    for line in text.splitlines():
        if m := re.match(r"\s*\[([^\]]+)\]", line):
            current = m.group(1).strip()
            continue
        if current == section:
            out.append(line)
    return out


def values(text: str, section: str, key: str) -> list[str]:
    """Every value of ``key`` in ``[section]``, in order (LinuxCNC reads HALFILE so)."""
    return [line.split("=", 1)[1].strip() for line in lines_of(text, section)
            if re.match(rf"\s*{key}\s*=", line)]


def setps(hal: str) -> dict[str, tuple[float, str]]:
    """Per pin its value and the comment line above its ``setp``."""
    lines = hal.splitlines()
    out = {}
    for i, line in enumerate(lines):
        if line.startswith("setp "):
            _, pin, value = line.split()
            out[pin] = (float(value), lines[i - 1])
    return out


def test_the_export_writes_the_three_files(held_out_dir: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    ini, out = machine(tmp_path / "machine"), tmp_path / "out"
    assert export(held_out_dir, ini, out) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted([INI, GEOMETRY_HAL,
                                                            COMPONENT_FILE])
    shipped = (resources.files("orthocal") / COMPONENT_FILE).read_text(encoding="utf-8")
    assert (out / COMPONENT_FILE).read_text(encoding="utf-8") == shipped
    said = capsys.readouterr().out
    assert str(out / GEOMETRY_HAL) in said
    # where they go: the INI's relative HAL files are read from its own folder
    assert f"copy {INI} and {GEOMETRY_HAL} into {ini.parent}" in said
    assert ini.read_text(encoding="utf-8") == (EXAMPLE / INI).read_text(encoding="utf-8")


def test_the_ini_names_the_component_and_keeps_the_old_lines(held_out_dir: Path,
                                                             tmp_path: Path) -> None:
    ini = machine(tmp_path / "machine", {"KINEMATICS = orthoglidekins":
                                         "KINEMATICS = trivkins coordinates=XYZ",
                                         "JOINTS = 3": "JOINTS = 4"})
    assert export(held_out_dir, ini, tmp_path / "out") == 0
    text = (tmp_path / "out" / INI).read_text(encoding="utf-8")
    assert values(text, "KINS", "KINEMATICS") == ["orthoglidekins"]
    assert values(text, "KINS", "JOINTS") == ["3"]
    kins = lines_of(text, "KINS")
    assert "# orthocal: was KINEMATICS = trivkins coordinates=XYZ" in kins
    assert "# orthocal: was JOINTS = 4" in kins


def test_a_kins_section_without_joints_gets_three(held_out_dir: Path,
                                                  tmp_path: Path) -> None:
    ini = machine(tmp_path / "machine", {"JOINTS = 3\n": ""})
    assert export(held_out_dir, ini, tmp_path / "out") == 0
    text = (tmp_path / "out" / INI).read_text(encoding="utf-8")
    assert values(text, "KINS", "KINEMATICS") == ["orthoglidekins"]
    assert values(text, "KINS", "JOINTS") == ["3"]


def halfiles_after(tmp_path: Path, run_dir: Path, hal: str) -> list[str]:
    """The HALFILEs of the exported INI, the example's [HAL] replaced by ``hal``."""
    folder = tmp_path / "machine"
    ini = machine(folder, {"HALFILE = orthoglide.hal\n": hal})
    (folder / "io.hal").write_text("net estop-out iocontrol.0.user-enable-out\n")
    (folder / "spindle.hal").write_text("# the spindle: no kinematics here\n")
    assert export(run_dir, ini, tmp_path / "out") == 0
    text = (tmp_path / "out" / INI).read_text(encoding="utf-8")
    hal_lines = [ln.strip() for ln in lines_of(text, "HAL")
                 if ln.strip() and not ln.lstrip().startswith("#")]
    assert values(text, "HAL", "HALFILE") == [ln.split("=", 1)[1].strip() for ln in hal_lines]
    return values(text, "HAL", "HALFILE")


def test_the_geometry_follows_the_hal_file_that_loads_the_kinematics(
        held_out_dir: Path, tmp_path: Path) -> None:
    # [KINS]KINEMATICS in orthoglide.hal, neither first nor last
    got = halfiles_after(tmp_path, held_out_dir, "HALFILE = io.hal\nHALFILE = orthoglide.hal\n"
                         "HALFILE = spindle.hal\n")
    assert got == ["io.hal", "orthoglide.hal", GEOMETRY_HAL, "spindle.hal"]


def test_a_hal_file_in_linuxcncs_library_is_read_there(
        held_out_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    lib = tmp_path / "hallib"
    lib.mkdir()
    (lib / "core.hal").write_text("loadrt trivkins\nloadrt motmod\n")
    monkeypatch.setattr(cmd_export, "HALLIB", str(lib))
    got = halfiles_after(tmp_path, held_out_dir, "HALFILE = io.hal\nHALFILE = LIB:core.hal\n"
                         "HALFILE = spindle.hal\n")
    assert got == ["io.hal", "LIB:core.hal", GEOMETRY_HAL, "spindle.hal"]


def test_without_a_file_that_loads_the_kinematics_the_geometry_follows_the_first(
        held_out_dir: Path, tmp_path: Path) -> None:
    got = halfiles_after(tmp_path, held_out_dir, "HALFILE = io.hal\nHALFILE = spindle.hal\n")
    assert got == ["io.hal", GEOMETRY_HAL, "spindle.hal"]


def test_exporting_again_writes_each_line_once(held_out_dir: Path, square_dir: Path,
                                               tmp_path: Path) -> None:
    """The first export installed beside the machine's HAL files (its INI and HAL file
    copied over the machine's), then a later run exported onto it."""
    folder = tmp_path / "machine"
    ini = machine(folder)
    assert export(held_out_dir, ini, tmp_path / "first") == 0
    for name in (INI, GEOMETRY_HAL):
        shutil.copy(tmp_path / "first" / name, folder / name)
    assert export(square_dir, ini, tmp_path / "second") == 0
    text = (tmp_path / "second" / INI).read_text(encoding="utf-8")
    assert values(text, "HAL", "HALFILE") == ["orthoglide.hal", GEOMETRY_HAL]
    assert values(text, "KINS", "KINEMATICS") == ["orthoglidekins"]
    assert values(text, "KINS", "JOINTS") == ["3"]
    assert text.count(f"HALFILE = {GEOMETRY_HAL}") == 1
    # the INI names the run its geometry is from, not the one before
    assert str(held_out_dir) not in text and str(square_dir) in text
    assert home_offsets(text) == {f"JOINT_{j}": L for j in range(3)}
    for section in ("JOINT_0", "JOINT_1", "JOINT_2"):
        held = [ln for ln in lines_of(text, section) if "offsets_held_by" in ln]
        assert len(held) == 1


def test_the_hal_file_sets_every_pin_to_the_identified_machine(held_out_dir: Path,
                                                               tmp_path: Path) -> None:
    assert export(held_out_dir, machine(tmp_path / "machine"), tmp_path / "out") == 0
    hal = (tmp_path / "out" / GEOMETRY_HAL).read_text(encoding="utf-8")
    found = identified_machine(held_out_dir)
    assert sum(line.startswith("setp ") for line in hal.splitlines()) == 12
    pins = setps(hal)
    assert sorted(pins) == sorted(f"orthoglidekins.{p}" for p in PINS.values())
    header = hal.split("\nsetp", 1)[0]
    assert found.describe() in header.replace("\n# ", " ")
    for v in found.values:
        value, comment = pins[f"orthoglidekins.{v.pin}"]
        assert value == pytest.approx(v.value, abs=TOL), v.name
        assert comment.startswith(f"# {v.name} ({v.unit}): ")
        if v.interval_95 is not None:
            lo, hi = re.search(r"95 %: \[(\S+), (\S+)\]", comment).groups()
            assert (float(lo), float(hi)) == pytest.approx(v.interval_95, abs=IV_TOL)
    told = {v.name for v in found.values if v.identified}
    assert told == {*(f"drho_{a}" for a in "xyz"), "tilt_yx", "tilt_zx", "tilt_zy",
                    "gap_xy", "gap_xz", "gap_yz"}


def test_what_the_run_did_not_identify_stays_nominal_and_says_why(
        held_out_dir: Path, square_dir: Path, tmp_path: Path) -> None:
    ini = machine(tmp_path / "machine")
    assert export(held_out_dir, ini, tmp_path / "tilted") == 0
    assert export(square_dir, ini, tmp_path / "square") == 0
    tilted = setps((tmp_path / "tilted" / GEOMETRY_HAL).read_text(encoding="utf-8"))
    for a in "xyz":  # ΔL: two stops per leg cannot tell it from the tilts
        value, comment = tilted[f"orthoglidekins.leg-length-{a}"]
        assert value == L
        assert f"dL_{a}" in comment and "not identified" in comment
    square = setps((tmp_path / "square" / GEOMETRY_HAL).read_text(encoding="utf-8"))
    for name, pin in PINS.items():
        if name.startswith(("tilt", "gap")):
            value, comment = square[f"orthoglidekins.{pin}"]
            assert value == 0.0
            assert f"# {name} " in comment and "nominal" in comment and "'rho'" in comment


def test_where_the_drive_holds_the_offsets_home_offset_stays(held_out_dir: Path,
                                                             tmp_path: Path) -> None:
    assert json.loads((held_out_dir / "result.json").read_text())["offsets_held_by"] \
        == "controller"
    assert export(held_out_dir, machine(tmp_path / "machine"), tmp_path / "out") == 0
    text = (tmp_path / "out" / INI).read_text(encoding="utf-8")
    assert home_offsets(text) == {f"JOINT_{j}": L for j in range(3)}
    for j in range(3):
        joint = lines_of(text, f"JOINT_{j}")
        at = next(i for i, ln in enumerate(joint) if ln.startswith("HOME_OFFSET"))
        assert "offsets_held_by = controller" in joint[at - 1]


def test_where_the_station_holds_the_offsets_home_offset_is_the_plain_exports(
        held_out_dir: Path, tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(held_out_dir, run_dir)
    result = json.loads((run_dir / "result.json").read_text())
    result["offsets_held_by"] = "station"
    (run_dir / "result.json").write_text(json.dumps(result))
    ini = machine(tmp_path / "machine")
    assert export(run_dir, ini, tmp_path / "out") == 0
    assert main(["export", str(run_dir), "--to", "linuxcnc", "--ini", str(ini),
                 "--out", str(tmp_path / "plain.ini")]) == 0
    got = home_offsets((tmp_path / "out" / INI).read_text(encoding="utf-8"))
    assert got == home_offsets((tmp_path / "plain.ini").read_text(encoding="utf-8"))
    before, final = result["offsets_before"], result["offsets_final"]
    for j, a in enumerate("xyz"):  # a commanded rho puts the carriage at rho + o
        assert got[f"JOINT_{j}"] == pytest.approx(L - (final[a] - before[a]), abs=1e-6)
        assert got[f"JOINT_{j}"] != L
    assert "HOME_OFFSET was 310.250000" in (tmp_path / "out" / INI).read_text()


#: Per refusal: write_run's options (None: no run directory at all), the INI's edits,
#: the arguments changed (None: left out) and what the one line must name.
REFUSALS = {
    "failed run": ({"status": "failed"}, {}, {}, "the run failed"),
    "aborted run": ({"status": "aborted"}, {}, {}, "the run aborted"),
    "no model.json": ({"model": False}, {}, {}, "model.json"),
    "twincat": ({}, {}, {"--to": "twincat"}, "--kinematics"),
    "no --ini": ({}, {}, {"--ini": None}, "--ini"),
    "no --out": ({}, {}, {"--out": None}, "--out"),
    "--out the INI's folder": ({}, {}, {"--out": "machine"}, "--out"),
    "INI unreadable": ({}, {}, {"--ini": "nowhere.ini"}, "--ini"),
    "no [KINS]": ({}, {"[KINS]\nKINEMATICS = orthoglidekins\nJOINTS = 3\n": ""}, {},
                  "[KINS]"),
    "no KINEMATICS": ({}, {"KINEMATICS = orthoglidekins\n": ""}, {}, "KINEMATICS"),
    "no HALFILE": ({}, {"HALFILE = orthoglide.hal\n": ""}, {}, "HALFILE"),
}


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


@pytest.mark.parametrize("case", REFUSALS)
def test_a_refusal_is_one_line_and_leaves_no_file(case: str, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    run_options, edit, changed, names = REFUSALS[case]
    run_dir = write_run(tmp_path / "run", **run_options)
    ini = machine(tmp_path / "machine", edit)
    before = snapshot(tmp_path)
    args = {"--to": "linuxcnc", "--ini": str(ini), "--out": str(tmp_path / "out")}
    args.update({k: v if v is None else str(tmp_path / v) if k != "--to" else v
                 for k, v in changed.items()})
    argv = ["export", str(run_dir), "--kinematics"]
    argv += [word for k, v in args.items() if v is not None for word in (k, v)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and names in err[0], err
    assert not (tmp_path / "out").exists()
    assert snapshot(tmp_path) == before  # nothing written, the machine's INI untouched


#: Per case: what the run's record says, and what the refusal and the header name.
UNRESOLVED = {
    "ambiguous": ({"model": "rho+tilt+gap", "ambiguity": {
        "explained_by": "rho+gap+form", "apart_mm": {"drho_x": 0.015}}},
        "could not tell the axes' tilts from the legs' bows (rho+tilt+gap or rho+gap+form)"),
    "not converged": ({"verdict": "unproven", "shown_within_95_mm": {
        "drho_x": 0.0031, "drho_y": 0.0173, "drho_z": 0.0009}},
        "did not converge (not-converged): Δρ_y as left +2.1 ± 15.2 µm (95 %, not shown "
        "within)"),
}


@pytest.mark.parametrize("case", UNRESOLVED)
def test_an_unresolved_run_goes_into_the_controller_only_with_force(
        case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The plain export's one decision (station.record.exportable) holds here too: a
    geometry the run did not resolve is refused, one line and no file, and with
    --force every file's header says what it carries."""
    last_round, words = UNRESOLVED[case]
    run_dir = write_run(tmp_path / "run")
    doc = json.loads((run_dir / "result.json").read_text())
    doc["iterations"][-1].update(last_round)
    if case == "not converged":
        doc["converged"] = False
        doc["loop"]["stopped"] = "not-converged"
        # the statement's Δρ_y as left, not shown within the loop's limit
        doc["statement"] = [{**q, "value": 0.0021, "expanded": 0.0152,
                             "interval_95": [0.0021 - 0.0152, 0.0021 + 0.0152],
                             "decision": "not shown within"}
                            if q["name"] == "drho_y.as_left" else q for q in doc["statement"]]
    (run_dir / "result.json").write_text(json.dumps(doc))
    ini = machine(tmp_path / "machine")
    before = snapshot(tmp_path)
    argv = ["export", str(run_dir), "--to", "linuxcnc", "--kinematics", "--ini", str(ini),
            "--out", str(tmp_path / "out")]
    assert main(argv) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert f"{run_dir}: not exported: " in line and words in line and "--force" in line
    assert snapshot(tmp_path) == before
    assert main([*argv, "--force"]) == 0
    capsys.readouterr()
    for name in (INI, GEOMETRY_HAL):
        said = " ".join(line.removeprefix(HEADER).strip() for line in (
            tmp_path / "out" / name).read_text().splitlines() if line.startswith(HEADER))
        assert f"run {run_dir}, machine OG-tilted" in said and "verdict: " in said, name
        assert "EXPORTED WITH --force" in said and words in said, (name, said)
