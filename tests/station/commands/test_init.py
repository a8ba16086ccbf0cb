"""`orthocal init`: a commented starter config from what probe finds, accepted
by `orthocal run --plan` as written, never overwriting a file."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import pytest

from drivers.sim.specs import DriveSpec, GaugeSpec
from drivers.sim.station import VirtualStation
from station.commands.cli import main
from station.commands.init import propose_setups

ROOT = Path(__file__).resolve().parents[3]


@pytest.mark.parametrize("count", [2, 6])
def test_init_then_plan_against_the_simulator(tmp_path: Path, capsys, count: int) -> None:
    out = tmp_path / "station.toml"
    gauges = GaugeSpec(names=tuple("ABCDEF"[:count]), protocol="sylvac", line_time=False)
    with VirtualStation(gauges=gauges, seed=1) as station:
        ports = [s.port for s in station.indicators.values()]
        assert main(["init", "--out", str(out), *ports, "--timeout", "0.3",
                     "--controller", f"127.0.0.1:{station.controller.port}"]) == 0
        text = out.read_text()
        assert text.startswith("# orthocal station config") and "EDIT" in text
        data = tomllib.loads(text)
        assert [i["port"] for i in data["indicators"]] == ports
        assert {i["protocol"] for i in data["indicators"]} == {"sylvac"}
        assert data["controller"]["port"] == station.controller.port
        assert len(data["setups"]) == 3
        used = {n for s in data["setups"] for n in s["indicators"]}
        assert used == ({"A", "B"} if count == 2 else set("ABCDEF"))
        capsys.readouterr()
        assert main(["run", "--config", str(out), "--plan", "--json"]) == 0
        plan = json.loads(capsys.readouterr().out)
        assert plan["soft_limits"]["lower"] == pytest.approx([200.25] * 3)
        assert station.controller.stats.writes == 0  # init and --plan only read


def test_init_without_limit_registers_marks_them_required(tmp_path: Path, capsys) -> None:
    out = tmp_path / "station.toml"
    drive = DriveSpec(controller_options={"soft_limit_registers": False})
    with VirtualStation(drive=drive, seed=1) as station:
        ports = [s.port for s in station.indicators.values()]
        assert main(["init", "--out", str(out), *ports, "--timeout", "0.3",
                     "--controller", f"127.0.0.1:{station.controller.port}"]) == 0
        text = out.read_text()
        assert "# REQUIRED: the controller does not tell its soft limits" in text
        assert "# soft_min = " in text
        capsys.readouterr()
        # As written the plan refuses, naming what to add; uncommented, it passes.
        assert main(["run", "--config", str(out), "--plan"]) == 2
        assert "soft_min and soft_max" in capsys.readouterr().err
        out.write_text(text.replace("# soft_min = ", "soft_min = ")
                       .replace("# soft_max = ", "soft_max = "))
        assert main(["run", "--config", str(out), "--plan"]) == 0


def test_init_refuses_to_overwrite(tmp_path: Path, capsys) -> None:
    out = tmp_path / "station.toml"
    out.write_text("# mine\n")
    assert main(["init", "--out", str(out), "--controller", "127.0.0.1:1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "exists" in err and str(out) in err
    assert out.read_text() == "# mine\n"


def test_proposed_setups_cover_every_leg_and_direction_pair() -> None:
    for names in (["A"], ["A", "B"], list("ABCDEF")):
        setups = propose_setups(names)
        assert {leg for leg, _ in setups} == {"x", "y", "z"}
        for leg, inds in setups:
            assert all(d != leg for d in inds.values())
    one = propose_setups(["A"])
    assert sorted((leg, d) for leg, inds in one for d in inds.values()) == [
        ("x", "y"), ("x", "z"), ("y", "x"), ("y", "z"), ("z", "x"), ("z", "y")]


def test_init_config_keeps_reversed_mounts_motion_and_gauges(tmp_path: Path) -> None:
    # examples/station.toml as a user has it: a reversed mount (D = "-z"), the drive's
    # motion said, a gauge's own preload and a generic gauge's line settings. Its ports
    # answer nothing here (/dev/null) and its controller is not there: init still
    # writes what that config says, under the config's own names.
    text = (ROOT / "examples" / "station.toml").read_text()
    text = re.sub(r'port = "/dev/ttyUSB\d"', 'port = "/dev/null"', text)
    text = (text.replace("# motion = ", "motion = ")
            .replace('host = "192.168.0.10"', 'host = "127.0.0.1"')
            .replace("port = 502 ", "port = 1 ").replace("timeout_s = 2.0 ", "timeout_s = 0.2 "))
    source, out = tmp_path / "station.toml", tmp_path / "new.toml"
    source.write_text(text)
    given = tomllib.loads(text)
    assert {"C": "x", "D": "-z"} in [s["indicators"] for s in given["setups"]]
    assert main(["init", "--config", str(source), "--out", str(out), "--timeout", "0.1"]) == 0
    data = tomllib.loads(out.read_text())
    assert data["setups"] == given["setups"]  # every sign as given
    assert data["controller"]["motion"] == "coordinated"
    assert [i["name"] for i in data["indicators"]] == [i["name"] for i in given["indicators"]]
    assert data["indicators"][2]["preload_mm"] == 6.0
    generic = data["indicators"][5]
    assert {k: generic[k] for k in ("protocol", "baudrate", "pattern", "stroke_mm")} == \
        {k: given["indicators"][5][k] for k in ("protocol", "baudrate", "pattern", "stroke_mm")}
