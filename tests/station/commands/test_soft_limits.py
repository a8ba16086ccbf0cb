"""Soft limits as docs/design.md's "Register map" says: from the controller where it
answers, from `[controller] soft_min`/`soft_max` where it does not (exception 2,
a profile without them, a range that is none), and no motion with neither."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import NO_FIGURES

from drivers.axes import ModbusAxisController
from drivers.sim.controller import SimController
from drivers.sim.specs import DriveSpec, MachineTruth
from station.commands.cli import main
from station.commands.simulate.launch import station_config
from station.commands.simulate.station_setups import SimulatedStation, gauges_for
from station.config.toml import toml_text

SHORT = {"cycles": 1, "readings": 2, "settle_s": 0.0, "verify": False}
CONFIG_LIMITS = {"soft_min": [205.0, 205.0, 205.0], "soft_max": [375.0, 375.0, 375.0]}


def test_exception_2_reads_as_absent_not_as_a_fault() -> None:
    with SimController(soft_limit_registers=False) as sim, \
            ModbusAxisController(**sim.client_kwargs(), timeout_s=1.0) as ctl:
        limits = ctl.soft_limits()
        lo, hi = limits  # still a (lower, upper) pair to its users
        assert limits.source == "absent" and "exception 2" in limits.reason
        assert np.all(np.isnan(lo)) and np.all(np.isnan(hi))
        # The drive still enforces its own limits, which it keeps in parameters.
        assert sim.soft_min[0] == pytest.approx(200.25)


def test_all_zero_registers_read_as_nonsense() -> None:
    with SimController(soft_limit_registers=([0, 0, 0], [0, 0, 0])) as sim, \
            ModbusAxisController(**sim.client_kwargs(), timeout_s=1.0) as ctl:
        limits = ctl.soft_limits()
        assert limits.source == "nonsense" and "all zero" in limits.reason
    with SimController(soft_limit_registers=([300, 0, 0], [250, 1, 1])) as sim, \
            ModbusAxisController(**sim.client_kwargs(), timeout_s=1.0) as ctl:
        limits = ctl.soft_limits()
        assert limits.source == "nonsense" and "lower ≥ upper on axis x" in limits.reason


def _station(tmp_path: Path, soft_limit_registers: Any, controller: dict[str, Any]
             ) -> tuple[SimulatedStation, Path]:
    drive = DriveSpec(controller_options={"soft_limit_registers": soft_limit_registers})
    station = SimulatedStation(MachineTruth(drho=(0.3, -0.2, 0.1)), drive,
                               gauges_for(6, mounted=True), seed=5)
    config = station_config(station, {"procedure": SHORT, "report": NO_FIGURES})
    config["controller"].update(controller)
    path = tmp_path / "station.toml"
    path.write_text(toml_text(config, "test"))
    return station, path


def test_controller_without_limit_registers_runs_with_config_limits(tmp_path: Path,
                                                                     capsys) -> None:
    station, path = _station(tmp_path, False, CONFIG_LIMITS)
    with station:
        code = main(["run", "--config", str(path), "--yes", "--json",
                     "--out", str(tmp_path / "runs")])
        out, err = capsys.readouterr()
        assert code == 0, err
        result = json.loads(out)
        assert result["status"] == "ok"
        assert station.controller.stats.commands.get(1, 0) > 0  # it really moved
        plan = json.loads((Path(result["run_dir"]) / "plan.json").read_text())
        assert plan["soft_limits"]["lower"] == CONFIG_LIMITS["soft_min"]
        assert "config" in plan["soft_limits"]["source"]


@pytest.mark.parametrize("registers", [False, ([0, 0, 0], [0, 0, 0])],
                         ids=["exception-2", "all-zero"])
def test_no_limits_anywhere_nothing_moves(tmp_path: Path, capsys, registers: Any) -> None:
    station, path = _station(tmp_path, registers, {})
    with station:
        before = station.machine.actual().copy()
        code = main(["run", "--config", str(path), "--yes", "--out", str(tmp_path / "runs")])
        err = capsys.readouterr().err
        assert code == 2, err
        line = err.strip()
        assert "\n" not in line and "Traceback" not in line
        assert "soft_min" in line and "soft_max" in line and "[controller.registers]" in line
        if registers is False:
            assert "exception 2" in line
        else:
            assert "no range" in line and "all zero" in line
        # At the drive: no move, stop or home command ever arrived, nothing moved.
        assert station.controller.stats.commands == {}
        assert np.allclose(station.machine.actual(), before)
        assert not list((tmp_path / "runs").glob("run-*"))


def test_nonsense_registers_with_config_limits_plan_from_config(tmp_path: Path,
                                                                capsys) -> None:
    station, path = _station(tmp_path, ([0, 0, 0], [0, 0, 0]), CONFIG_LIMITS)
    with station:
        assert main(["run", "--config", str(path), "--plan"]) == 0
        out = capsys.readouterr().out
        assert "soft limits (from the config" in out
        assert "ρ_x ∈ [205.000, 375.000]" in out


def test_only_one_config_side_names_the_missing_one(tmp_path: Path, capsys) -> None:
    station, path = _station(tmp_path, False, {"soft_max": [375.0, 375.0, 375.0]})
    with station:
        assert main(["run", "--config", str(path), "--plan"]) == 2
        err = capsys.readouterr().err
        assert "[controller] soft_min (joint mm" in err and "soft_max (" not in err


def test_config_narrows_register_limits_never_widens(tmp_path: Path, capsys) -> None:
    # The drive reads [200.25, 380.25]; the config asks wider below, narrower above.
    station, path = _station(tmp_path, True, {"soft_min": [100.0, 100.0, 100.0],
                                              "soft_max": [372.0, 372.0, 372.0]})
    with station:
        assert main(["run", "--config", str(path), "--plan", "--json"]) == 0
        limits = json.loads(capsys.readouterr().out)["soft_limits"]
        assert limits["lower"] == pytest.approx([200.25] * 3)
        assert limits["upper"] == pytest.approx([372.0] * 3)
        assert "narrowed" in limits["source"]
