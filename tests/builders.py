"""Builders shared by the tests: the options of a simulated run or resume, the
short procedure most simulated runs use, and a small station config.

Plain functions and constants (imported as ``from builders import ...``, like
``truth``); fixtures live in conftest.py.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from station.commands.options import DriveOptions, ResumeOptions, RunOptions, SimOptions
from station.config import StationConfig, parse_config

#: A short simulated procedure: two cycles of three readings, no settling.
FAST: dict[str, Any] = {"cycles": 2, "readings": 3, "settle_s": 0.0}

#: A station of two gauges moved from leg to leg (config as data).
BASE: dict[str, Any] = {
    "indicators": [{"name": "A", "port": "/dev/a"}, {"name": "B", "port": "/dev/b"}],
    "setups": [
        {"leg": "x", "indicators": {"A": "y", "B": "z"}},
        {"leg": "y", "indicators": {"A": "x", "B": "-z"}},
        {"leg": "z", "indicators": {"A": "x", "B": "y"}},
    ],
}


def station_config(**sections: Any) -> StationConfig:
    """BASE with each given section's keys merged in (``controller={...}`` etc.)."""
    data = copy.deepcopy(BASE)
    for name, values in sections.items():
        if isinstance(values, dict) and isinstance(data.get(name), dict):
            data[name].update(values)
        else:
            data[name] = copy.deepcopy(values)
    return parse_config(data)


def simulated(out: Path, *, seed: int | None = 7, noise: float | None = 0.002,
              procedure: dict[str, Any] | None = FAST, hook: Any = None, yes: bool = False,
              json: bool = True, plan: bool = False, true_drho: Any = None,
              true_dl: Any = None, true_tilt: Any = None, mount_error: float | None = None,
              motion: str | None = None, drive_profile: str | None = None,
              drive_accel: str | None = None, drive_delays: str | None = None,
              drive_sequence: str | None = None, indicators: int = 2,
              writeback: dict[str, Any] | None = None, speed: float | None = None
              ) -> RunOptions:
    """``orthocal run --simulate`` into ``out``, with the test knobs the command
    line does not offer: ``hook`` (given the running virtual station), ``procedure``
    and ``writeback`` overrides, ``indicators`` (2 or 6), ``speed`` (mm/s)."""
    sim = SimOptions(
        seed=seed, true_drho=true_drho, true_dl=true_dl, true_tilt=true_tilt, noise=noise,
        mount_error=mount_error,
        drive=DriveOptions(motion=motion, profile=drive_profile, accel=drive_accel,
                           delays=drive_delays, sequence=drive_sequence),
        indicators=indicators, procedure=procedure, writeback=writeback, speed_mm_s=speed,
        station_hook=hook)
    return RunOptions(sim=sim, plan=plan, out=Path(out), yes=yes, json=json)


def resumed(run_dir: Path, *, yes: bool = False, json: bool = True,
            hook: Any = None) -> ResumeOptions:
    """``orthocal resume RUN_DIR`` (or rollback), ``hook`` given the restarted
    virtual station of a simulated run."""
    return ResumeOptions(run_dir=Path(run_dir), yes=yes, json=json, station_hook=hook)
