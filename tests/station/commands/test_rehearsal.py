"""Rehearsal works as docs/drive.md says: ``orthocal sim --profile MAP
--config-out FILE`` hands out a config that ``orthocal run --config FILE --plan``
accepts for every shipped and every example map (a map whose axes are separate
drives gets no ``motion = "coordinated"``); ``orthocal init`` writes the documented
defaults; ``orthocal init --config FILE`` probes what ``probe --config`` probes and
writes a starter config around it; a bad ``--config`` is one line, exit 2."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

from drivers.map_files import builtin_maps, read_map, resolve_map
from drivers.sim.specs import DriveSpec, GaugeSpec
from station.commands.cli import main
from station.commands.simulate.station_setups import SimulatedStation
from station.config import (
    ControllerConfig,
    MachineConfig,
    ProcedureConfig,
    WritebackConfig,
    load_config,
)
from station.config.toml import toml_text

ROOT = Path(__file__).resolve().parents[3]
EXAMPLES = sorted((ROOT / "examples" / "maps").glob("*.toml"))
GATEWAY = ROOT / "examples" / "maps" / "gateway-3x1.toml"
HELD = ROOT / "examples" / "maps" / "gateway-3x1-no-offsets.toml"  # no OFFSET registers
# Every map a user may rehearse: the built-in ones (orthocal-generic and the files of
# drivers/maps/) by name, docs/drive.md's examples by path.
MAPS = [*sorted(builtin_maps()), *(str(p) for p in EXAMPLES)]


def separate_drives(profile: str) -> bool:
    """The map's three targets are on different unit ids (docs/drive.md, "A map of your own")."""
    return len({r.device_id for r in resolve_map(profile).axis_registers("TARGET")}) > 1


def test_the_maps_cover_every_shipped_and_example_file() -> None:
    shipped = {read_map(p).name for p in (ROOT / "drivers" / "maps").glob("*.toml")}
    assert shipped and shipped < set(builtin_maps())
    assert len(EXAMPLES) >= 2 and str(GATEWAY) in MAPS


@pytest.fixture
def no_design(monkeypatch: pytest.MonkeyPatch) -> None:
    """``run --plan`` without the design summary it prints last (orthocal design's
    search for better strokes: 15-45 s per map here, and nothing ``run`` refuses a
    config for): the plan is still built from the config and checked against the live
    controller's limits and positions, as ``run`` does before anything moves."""
    from station.commands import design_command as design

    monkeypatch.setattr(design, "design_summary", lambda *args, **kwargs: {})


@pytest.fixture
def sim_config(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Path]:
    """``orthocal sim --profile MAP --config-out FILE`` as docs/drive.md runs it, in its own
    process: FILE once written; stopped with Ctrl-C (SIGINT) afterwards, exit 0."""
    config_path = tmp_path / "sim.toml"
    proc = subprocess.Popen(
        [sys.executable, "-m", "station", "sim", "--config-out", str(config_path),
         "--seed", "2", "--profile", request.param],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 30
        while not config_path.exists() or "[writeback]" not in config_path.read_text():
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "orthocal sim wrote no config in 30 s"
            time.sleep(0.05)
        yield config_path
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
        proc.stdout.close()
        proc.stderr.close()


@pytest.mark.parametrize("sim_config", MAPS, indirect=True, ids=lambda m: Path(m).stem)
def test_sim_config_out_is_a_config_run_accepts(sim_config: Path, capsys,
                                                no_design: None) -> None:
    config = load_config(sim_config)
    profile = config.controller.profile
    if separate_drives(profile):
        # one request per drive: nothing moves the axes on one line, and the config
        # does not say otherwise
        assert config.controller.motion in (None, "independent")
        assert 'motion = "coordinated"' not in sim_config.read_text()
        assert "drive independent" in sim_config.read_text().splitlines()[0]
    else:
        # one drive for all axes: the virtual one interpolates, and the config says so
        assert config.controller.motion == "coordinated"
    capsys.readouterr()
    assert main(["run", "--config", str(sim_config), "--plan", "--json"]) == 0, \
        capsys.readouterr().err
    plan = json.loads(capsys.readouterr().out)
    assert plan["motion"] == (config.controller.motion or resolve_map(profile).motion)


def test_sim_refuses_coordinated_for_separate_drives(tmp_path: Path, capsys) -> None:
    out = tmp_path / "sim.toml"
    argv = ["sim", "--config-out", str(out), "--profile", str(GATEWAY),
            "--motion", "coordinated"]
    assert main(argv) == 2  # refused before anything is served
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--motion coordinated" in err and "separate drives" in err
    assert not out.exists()


# --- orthocal init ------------------------------------------------------------------


def test_init_writes_the_documented_defaults(tmp_path: Path) -> None:
    out = tmp_path / "station.toml"
    # one port that is not there: nothing to wait for, the placeholders written
    assert main(["init", "--out", str(out), str(tmp_path / "no-such-port"),
                 "--timeout", "0.1"]) == 0
    data = tomllib.loads(out.read_text())
    assert data["procedure"]["model"] == "auto"
    for table, defaults in (("machine", MachineConfig()), ("procedure", ProcedureConfig()),
                            ("writeback", WritebackConfig())):
        for key, value in data[table].items():
            assert value == getattr(defaults, key), f"[{table}] {key}"
    controller = ControllerConfig()
    for key, value in data["controller"].items():
        if key not in ("host", "port"):  # the placeholder of a controller not probed
            assert value == getattr(controller, key), f"[controller] {key}"
    assert {i["stroke_mm"] for i in data["indicators"]} == {12.5}


def test_init_config_probes_its_devices_and_writes_a_config_run_accepts(
        tmp_path: Path, capsys, no_design: None) -> None:
    # A drive without soft-limit registers or writable offsets (docs/drive.md's gateway,
    # the station holding the offsets), its map beside the config, the starter config
    # written into another folder.
    (tmp_path / "a" / "maps").mkdir(parents=True)
    shutil.copy(HELD, tmp_path / "a" / "maps" / "gateway.toml")
    (tmp_path / "b").mkdir()
    source, out = tmp_path / "a" / "station.toml", tmp_path / "b" / "station.toml"
    drive = DriveSpec(motion="independent", register_map=read_map(HELD),
                      profile="maps/gateway.toml")
    with SimulatedStation(drive=drive, gauges=GaugeSpec(line_time=False), seed=1) as vs:
        given = vs.config()
        given["controller"]["offsets"] = [0.01, -0.02, 0.03]
        source.write_text(toml_text(given))
        assert main(["init", "--config", str(source), "--out", str(out),
                     "--timeout", "0.3"]) == 0
        text = out.read_text()
        assert f"`orthocal probe --config {source}`" in text
        data = tomllib.loads(text)
        c = data["controller"]
        assert (c["host"], c["port"]) == ("127.0.0.1", vs.controller.port)
        assert (out.parent / c["profile"]).resolve() == \
            (tmp_path / "a" / "maps" / "gateway.toml").resolve()
        # what only the operator knows, as that config says it
        for key in ("soft_min", "soft_max", "offsets"):
            assert c[key] == pytest.approx(given["controller"][key]), key
        assert data["machine"] == {k: given["machine"][k]
                                   for k in ("leg_length", "rho_min", "rho_max")}
        # the gauges of that config's ports, each found at its protocol
        assert [i["port"] for i in data["indicators"]] == \
            [i["port"] for i in given["indicators"]]
        assert data["procedure"]["model"] == "auto"
        capsys.readouterr()
        assert main(["run", "--config", str(out), "--plan", "--json"]) == 0, \
            capsys.readouterr().err
        assert vs.controller.stats.writes == 0  # init and --plan only read


@pytest.mark.parametrize("case", ["missing", "bad-key", "with-controller"])
def test_init_config_bad_value_is_one_line_exit_2(tmp_path: Path, capsys, case: str) -> None:
    config = tmp_path / "station.toml"
    extra: list[str] = []
    if case == "bad-key":
        config.write_text('[machine]\nleg_lenght = 300.0\n')
    elif case == "with-controller":
        config.write_text("")
        extra = ["--controller", "127.0.0.1:1"]
    out = tmp_path / "new.toml"
    assert main(["init", "--config", str(config), "--out", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("orthocal: error: ")
    assert {"missing": f"{config}: no such file",
            "bad-key": "machine.leg_lenght: unknown key",
            "with-controller": "--controller and --config"}[case] in err
    assert not out.exists()
