"""Bad input through the real command line: a config, a readings file or an
argument that is wrong exits 2 with one line naming the field, the line or the
argument, creates no run directory and never shows a traceback."""

from __future__ import annotations

from pathlib import Path

import pytest

CONFIG_HEAD = ('[[indicators]]\nname = "A"\nport = "/dev/null"\n'
               '[[setups]]\nleg = "x"\nindicators = { A = "y" }\n')
BAD_CONFIGS = {
    "unknown key": (CONFIG_HEAD + "[procedure]\ncyclez = 3\n", "procedure.cyclez"),
    "wrong type": (CONFIG_HEAD + '[procedure]\nreadings = "five"\n', "procedure.readings"),
    "out of range": (CONFIG_HEAD + "[writeback]\nmax_abs_offset_mm = -1\n",
                     "writeback.max_abs_offset_mm"),
    "not TOML": ("[controller\nport = 502\n", "line 1"),
}


@pytest.mark.parametrize("name", list(BAD_CONFIGS))
def test_bad_config_exit_2_names_the_field(tmp_path: Path, orthocal, name: str) -> None:
    text, named = BAD_CONFIGS[name]
    path = tmp_path / "station.toml"
    path.write_text(text)
    o = orthocal("run", "--config", str(path), "--yes", "--out", str(tmp_path / "runs"))
    assert o.code == 2
    (line,) = [ln for ln in o.err.splitlines() if ln.startswith("orthocal:")]
    assert named in line and "Traceback" not in o.err
    assert not (tmp_path / "runs").exists()


def test_bad_csv_exit_2_names_the_line(tmp_path: Path, orthocal) -> None:
    path = tmp_path / "readings.csv"
    path.write_text("posture,leg,direction,deviation_mm\n+,x,y,0.1\n+,x,z,zero\n")
    o = orthocal("identify", str(path))
    assert o.code == 2 and "line 3" in o.err and "Traceback" not in o.err


@pytest.mark.parametrize("argv, named", [
    (["run", "--simulate", "--true-drho", "1,2"], "--true-drho"),
    (["run", "--simulate", "--seed", "seven"], "--seed"),
    (["run", "--simulate", "--config", "x.toml"], "--config"),
    (["run", "--simulate", "--sim-procedure", '{"cycles": 0}'], "procedure.cycles"),
])
def test_bad_arguments_exit_2_naming_them(tmp_path: Path, orthocal, argv: list[str],
                                          named: str) -> None:
    o = orthocal(*argv, "--out", str(tmp_path / "runs"))
    assert o.code == 2
    assert named in o.err and "Traceback" not in o.err
    assert not (tmp_path / "runs").exists()
