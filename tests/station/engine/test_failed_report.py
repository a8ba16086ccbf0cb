"""A run that fails after measuring part of its setups: its result.json and report
say what was measured (station.engine.procedure.measured_setups), and the page's
story names the model it set out to choose, not "the auto"."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from builders import FAST
from fakes import FakeRig, fake_config, run_on

from drivers.device_errors import DeviceError
from station.errors import RunFailed


class _LegYFails(FakeRig):
    """A gauge that does not answer once mounted on leg y (the second setup)."""

    def mount(self, name: str, leg: str, direction: str, at: float = 0.5) -> None:
        if leg == "y":
            raise DeviceError(f"indicator {name}", "no answer")
        super().mount(name, leg, direction, at)


def test_a_failed_run_shows_the_setup_it_measured(tmp_path: Path) -> None:
    rig = _LegYFails(seed=2, noise_mm=0.001, true_drho=(0.4, -0.3, 0.2))
    with pytest.raises(RunFailed):
        run_on(rig, tmp_path / "runs", fake_config(**FAST))  # model auto, 2 cycles
    (run_dir,) = (tmp_path / "runs").glob("run-*")
    result = json.loads((run_dir / "result.json").read_text())
    assert result["status"] == "failed" and result["model"] == "auto"
    (setup,) = result["setups"]
    assert setup["leg"] == "x" and setup["cycles_used"] == FAST["cycles"]
    assert setup["indicators"] == {"A": "y", "B": "z"}
    page = (run_dir / "report.html").read_text()
    assert "after measuring 1 setup (leg x, 2 cycles)" in page
    assert "No setup was measured" not in page and "0 of the 3 legs" not in page
    assert "the auto." not in page and "smallest model the data support" in page
