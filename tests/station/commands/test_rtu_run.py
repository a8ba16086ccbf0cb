"""Modbus RTU end to end: `orthocal sim --transport rtu` serves the register map
over a pseudo-terminal pair and `orthocal run --config` calibrates through it."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

from builders import NO_FIGURES
from truth import assert_truth, drho

from station import report
from station.commands.cli import main
from station.config.toml import toml_text


def test_run_over_modbus_rtu_to_a_successful_result(tmp_path: Path, capsys) -> None:
    config_path = tmp_path / "sim.toml"
    proc = subprocess.Popen(
        [sys.executable, "-m", "station", "sim", "--transport", "rtu",
         "--config-out", str(config_path), "--seed", "6", "--true-drho", "0.4,-0.6,0.2"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while not config_path.exists() or "[procedure]" not in config_path.read_text():
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "orthocal sim wrote no config in 30 s"
            time.sleep(0.05)
        data = tomllib.loads(config_path.read_text())
        assert data["controller"]["transport"] == "rtu"
        assert data["controller"]["port"].startswith("/dev/")  # the pty's client end
        data["procedure"].update(cycles=1, readings=2)
        data["report"] = NO_FIGURES  # the subject is the wire, not the report
        short = tmp_path / "station.toml"
        short.write_text(toml_text(data, "rtu test"))
        code = main(["run", "--config", str(short), "--yes", "--json",
                     "--out", str(tmp_path / "runs")])
        out, err = capsys.readouterr()
        assert code in (0, 3), err
        result = json.loads(out)
        assert result["status"] == "ok"
        assert code == (3 if report.not_converged(result) else 0), err
        # one cycle of two readings: the standard errors are ~3 µm, and the gauges'
        # 5 mm mounting error biases the first round; the run's statement holds both
        assert_truth(result, drho((0.4, -0.6, 0.2)))
        assert result["verification"]["deviations_rms_mm"] < 0.01
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            _, sim_err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            _, sim_err = proc.communicate(timeout=10)
    assert "Modbus RTU on /dev/" in sim_err and "stopped" in sim_err
