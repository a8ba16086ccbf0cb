"""``orthocal export``: a run's final offsets in a controller's own terms, the new value
beside the old and the sign taken from the conventions, not left to guess."""

from __future__ import annotations

import configparser
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from station.history.export import ExportError, csv_lines, linuxcnc

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


def result(**extra: Any) -> dict[str, Any]:
    return {"run_dir": "/runs/run-1", "machine": {"id": "OG-1"}, "offsets_held_by": "station",
            "offsets_before": {"x": 0.1, "y": 0.0, "z": -0.2},
            "offsets_final": {"x": 0.6, "y": -0.3, "z": -0.2},
            "reversal": {"value_mm": {"x": 0.02, "y": 0.0003, "z": 0.0},
                         "std_errors_mm": {"x": 0.001, "y": 0.001, "z": 0.001}}, **extra}


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
    r = result()
    switch, c = {"x": 25.0, "y": 25.0, "z": 25.0}, {"x": 3.0, "y": -1.0, "z": 0.5}
    old = {a: switch[a] - r["offsets_before"][a] - c[a] for a in "xyz"}
    ini = "".join(f"[JOINT_{j}]\nHOME_OFFSET = {old[a]!r}\n" for j, a in enumerate("xyz"))
    new = home_offsets(linuxcnc(r, ini))
    for j, a in enumerate("xyz"):
        for rho in (-100.0, 0.0, 60.0):
            assert switch[a] + rho - new[f"JOINT_{j}"] == pytest.approx(
                rho + r["offsets_final"][a] + c[a], abs=1e-9)


def test_linuxcnc_keeps_the_ini_writes_old_beside_new_and_backlash_when_asked() -> None:
    text = linuxcnc(result(), INI, source="og.ini")
    assert home_offsets(text) == pytest.approx({"JOINT_0": 9.5, "JOINT_1": -2.2,
                                                "JOINT_2": 0.0})
    assert "HOME_OFFSET was 10.000000" in text and "machine OG-1" in text
    assert "MACHINE = og" in text and "TYPE = LINEAR" in text  # the rest as it was
    assert "BACKLASH" not in text  # not asked for
    asked = linuxcnc(result(), INI, source="og.ini", backlash=True)
    assert "BACKLASH = 0.020000" in asked  # 20 standard errors out
    assert asked.count("BACKLASH = ") == 1 and "BACKLASH not written" in asked
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
    (run_dir / "result.json").write_text(json.dumps(result()))
    (tmp_path / "og.ini").write_text(INI)

    def orthocal(*argv: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "station", "export", str(run_dir), *argv],
                              capture_output=True, text=True, timeout=60, cwd=tmp_path)

    ok = orthocal("--to", "linuxcnc", "--ini", str(tmp_path / "og.ini"))
    assert ok.returncode == 0 and home_offsets(ok.stdout)["JOINT_0"] == pytest.approx(9.5)
    rows = orthocal("--to", "csv").stdout.splitlines()
    assert rows[1].startswith("x,0.100000,0.600000,+0.500000,0.020000,OG-1,")
    for argv, words in ((["--to", "linuxcnc"], "--ini"),
                        (["--to", "linuxcnc", "--ini", "missing.ini"], "cannot read"),
                        (["--to", "linuxcnc", "--ini", "og.ini", "--joints", "0,1"], "--joints")):
        bad = orthocal(*argv)
        assert bad.returncode == 2 and words in bad.stderr
        assert len(bad.stderr.strip().splitlines()) == 1
