"""Each joint's table into the controller (docs/design.md, "Joint tables in the
controller"): LinuxCNC's compensation files and ``[JOINT_n] COMP_FILE`` in the INI, read
back as LinuxCNC 2.9 reads and applies them (src/emc/motion/usrmotintf.cc and
control.c, restated here), TwinCAT CNC's leadscrew error compensation lists, the CSV,
and the words every export's header says of what it takes into account.
tests/station/history/test_joints_linuxcnc.py loads the files in a real LinuxCNC."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from builders import cli
from tabled_runs import L, screw_um, table_record, with_tables
from test_export import INI, document, header_of, home_offsets

from station.history.controller_terms import ExportError
from station.history.linuxcnc_comp import comp_file, comp_file_name, with_comp_files
from station.record.controller_tables import controller_tables
from station.report import as_result

#: The run's offsets (test_export.document): o_final − o_before per joint.
MOVED = {"x": 0.5, "y": -0.3, "z": 0.0}
LEAD = {"x": 100.0, "y": -80.0}
BAND_UM = 8.0  # joint x's dead band: its table's reversal


def tabled(**extra) -> dict:
    """test_export's run with tables of x (a lead and a band) and y (a lead); z assumed."""
    return with_tables(document(**extra), {"x": table_record(LEAD["x"], BAND_UM),
                                           "y": table_record(LEAD["y"])})


def read_comp(text: str) -> np.ndarray:
    """The triplets as usrmotLoadComp reads them: lines of three numbers, up to the
    first line that is not (sscanf "%lf %lf %lf" != 3 stops it)."""
    rows = []
    for line in text.splitlines():
        try:
            row = [float(v) for v in line.split()[:3]]
        except ValueError:
            break
        if len(row) != 3:
            break
        rows.append(row)
    return np.array(rows)


def linuxcnc_trim(rows: np.ndarray, at: np.ndarray, moving_up: bool) -> np.ndarray:
    """compute_screw_comp of a type-1 table: the forward (reverse) trim at the commanded
    position, linear between nominals, the end's trim beyond."""
    return np.interp(at, rows[:, 0], rows[:, 1 if moving_up else 2])


def carriage(axis: str, count: np.ndarray, up: bool) -> np.ndarray:
    """Where the joint stands for a motor count in the controller's joints: the screw as
    the test found it, at the spot the test's target ρ + (o_final − o_before) stood."""
    forward, reverse = screw_um(LEAD[axis], count + MOVED[axis],
                                BAND_UM if axis == "x" else 0.0)
    return count + 1e-3 * (forward if up else reverse)


def test_a_compensation_file_puts_each_joint_where_it_is_commanded(tmp_path: Path) -> None:
    tables = controller_tables(as_result(tabled()))
    assert [j.axis for j in tables.tabled] == ["x", "y"]
    q = np.linspace(176.2, 370.2, 97)  # the workspace's joints
    for axis, n in (("x", 0), ("y", 1)):
        text = comp_file(tables.joint(axis), n, ["# orthocal export: run /runs/run-1"])
        rows = read_comp(text)
        assert len(rows) == 23  # the zero line and 22 targets; the comments unread
        # the first line holds zero trims 1 mm below the table: homing sets no trim
        assert rows[0, 1:] == pytest.approx([0.0, 0.0], abs=0)
        assert rows[0, 0] == pytest.approx(170.0 - MOVED[axis] - 1.0, abs=1e-6)
        assert rows[1:, 0] == pytest.approx(np.arange(170.0, 381.0, 10.0) - MOVED[axis],
                                            abs=1e-6)
        for up in (True, False):
            motor = q + linuxcnc_trim(rows, q, up)
            # the carriage stands where commanded, to a nanometre: the count for a
            # table's end target stands |ε| beyond it, where ε is the end's (ε'·|ε|:
            # 80 µm/m × 11 µm = 0.9 nm), and the file's 9 decimals
            assert carriage(axis, motor, up) == pytest.approx(q, abs=1e-6)
            assert np.abs(carriage(axis, q, up) - q).max() > 5e-3  # uncompensated
        # the sign: a joint whose screw runs long is counted short, by ~k·(ρ − L)
        far = linuxcnc_trim(rows, np.array([L + 60.0]), True)[0]
        assert 1e3 * far == pytest.approx(-1e-3 * LEAD[axis] * (60.0 + MOVED[axis])
                                          + (BAND_UM / 2 if axis == "x" else 0.0), abs=0.01)
        assert "# COMP_FILE_TYPE = 1" in text and "\n\n# orthocal export: run" in text


def test_the_ini_names_each_file_once_and_keeps_what_it_replaced(tmp_path: Path) -> None:
    tables = controller_tables(as_result(tabled()))
    own = INI.replace("[JOINT_0]\n", "[JOINT_0]\nCOMP_FILE = shop.txt\nCOMP_FILE_TYPE = 0\n") \
        .replace("HOME_OFFSET = 0\n", "HOME_OFFSET = 0\nCOMP_FILE = z-shop.txt\n")
    text = with_comp_files(own, tables, (0, 1, 2), "og.ini")
    assert re.findall(r"^COMP_FILE = (.*)$", text, re.M) == [
        comp_file_name("x"), comp_file_name("y"), "z-shop.txt"]  # z: the shop's own kept
    assert text.count("COMP_FILE_TYPE = 1") == 2
    assert "# orthocal: was COMP_FILE = shop.txt" in text
    assert "# orthocal: was COMP_FILE_TYPE = 0" in text
    # once more onto the INI it wrote: the same, never doubled
    assert with_comp_files(text, tables, (0, 1, 2), "og.ini") == text
    # a later run without tables takes the earlier export's files out, saying why
    bare = controller_tables(as_result(document()))
    cleaned = with_comp_files(text, bare, (0, 1, 2), "og.ini")
    assert re.findall(r"^COMP_FILE = (.*)$", cleaned, re.M) == ["z-shop.txt"]
    assert cleaned.count("the COMP_FILE an earlier export wrote is removed") == 2
    # joints mapped otherwise; a section missing is one line
    swapped = with_comp_files(INI, tables, (2, 1, 0), "og.ini")
    assert re.search(r"\[JOINT_2\]\n#.*\nCOMP_FILE = orthocal-joint-x.comp", swapped)
    with pytest.raises(ExportError, match=r"og.ini: no \[JOINT_1\] section for joint y"):
        with_comp_files("[JOINT_0]\nHOME_OFFSET = 1\n", tables, (0, 1, 2), "og.ini")


def test_a_table_longer_than_linuxcnc_takes_is_refused() -> None:
    long = table_record(100.0, targets=np.arange(170.0, 170.0 + 256 * 0.5, 0.5))
    tables = controller_tables(as_result(with_tables(document(), {"x": long})))
    with pytest.raises(ExportError, match=r"256 targets; LinuxCNC 2\.9 takes 256 lines"):
        comp_file(tables.joint("x"), 0, [])


def lsec(text: str) -> dict[str, str]:
    return dict(re.findall(r"^(kopf\.\S+|kw\.\S+)\s+(\S+)$", text, re.M))


def test_the_command_writes_the_files_beside_its_output(tmp_path: Path) -> None:
    run_dir = tmp_path / "run-1"
    run_dir.mkdir()
    (run_dir / "result.json").write_text(json.dumps(tabled()))
    (tmp_path / "og.ini").write_text(INI)
    out = tmp_path / "out"
    out.mkdir()

    def export(*argv: str):
        return cli("export", str(run_dir), *argv, cwd=tmp_path)

    # LinuxCNC: the INI, and a file per joint with a table beside it
    done = export("--to", "linuxcnc", "--ini", "og.ini", "--backlash", "--out",
                  str(out / "og.ini"))
    assert done.returncode == 0, done.stderr
    ini = (out / "og.ini").read_text()
    assert home_offsets(ini)["JOINT_0"] == pytest.approx(9.5)  # the offsets as before
    assert sorted(p.name for p in out.iterdir()) == [
        "og.ini", "orthocal-joint-x.comp", "orthocal-joint-y.comp"]
    assert "wrote" in done.stderr and "orthocal-joint-x.comp" in done.stderr
    said = header_of(ini)
    assert "takes into account: the offsets and the joint tables" in said
    assert "joint tables: x (test: /shop/x.csv); y (test: /shop/y.csv)" in said
    assert "no table, not compensated: z (assumed, within ±170 µm per metre" in said
    # joint x's reversal is in its file, which makes LinuxCNC ignore BACKLASH
    assert "BACKLASH = " not in ini and "COMP_FILE carries its reversal" in ini
    comp = (out / "orthocal-joint-x.comp").read_text()
    assert "takes into account: the offsets and the joint tables" in header_of(comp)
    # TwinCAT: the parameter list, and a leadscrew error compensation list per table
    assert export("--to", "twincat", "--axes", "X1,Y1,Z1", "--out",
                  str(out / "tc.csv")).returncode == 0
    listed = lsec((out / "orthocal-lsec-x.lis").read_text())
    assert listed["kopf.log_achs_name"] == "X1" and listed["kw.ssfk.bilateral"] == "1"
    assert listed["kw.ssfk.unit"] == "1" and listed["kw.ssfk.kw_nr_max"] == "22"
    # the setpoints in 0.1 µm, in the joints commanded after the run (o moved by 0.5 mm)
    setpoints = [int(listed[f"kw.ssfk.table[{i}].setpoint"]) for i in range(22)]
    assert setpoints == [round((t - 0.5) * 1e4) for t in range(170, 381, 10)]
    assert listed["kw.ssfk.kw_startpos"] == "1695000"
    forward, reverse = screw_um(LEAD["x"], np.arange(170.0, 381.0, 10.0), BAND_UM)
    # the error itself, actual − setpoint in 0.1 µm, per direction (the CNC takes it off)
    assert [int(listed[f"kw.ssfk.table[{i}].pos"]) for i in range(22)] == \
        [round(10 * v) for v in forward]
    assert [int(listed[f"kw.ssfk.table[{i}].neg"]) for i in range(22)] == \
        [round(10 * v) for v in reverse]
    assert "orthocal-lsec-z.lis" not in {p.name for p in out.iterdir()}
    tc = (out / "tc.csv").read_text()
    assert "takes into account: the offsets and the joint tables" in header_of(tc)
    # CSV: the offsets alone, and it says so
    rows = export("--to", "csv")
    assert rows.returncode == 0
    assert "takes into account: offsets only" in header_of(rows.stdout)
    assert "joint tables (x, y): not in this file" in header_of(rows.stdout)
    # files beside the output need an output: one line, nothing written
    for target in (("--to", "linuxcnc", "--ini", "og.ini"), ("--to", "twincat")):
        refused = export(*target)
        assert refused.returncode == 2 and "--out: the run has joint tables (x, y)" \
            in refused.stderr and len(refused.stderr.strip().splitlines()) == 1


def test_a_run_without_tables_exports_as_before(tmp_path: Path) -> None:
    plain = as_result(document())
    tables = controller_tables(plain)
    assert tables.tabled == [] and with_comp_files(INI, tables, (0, 1, 2)) == INI
    assert tables.words("kinematics")[0].startswith("takes into account: the kinematics: ")
