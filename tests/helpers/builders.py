"""Builders shared by the tests: the options of a simulated run or resume, the
short procedure most simulated runs use, a small station config, and the rig and
outcome of the ``orthocal`` CLI fixture (conftest.py) with its fault trigger.

Plain functions and constants (imported as ``from builders import ...``, like
``truth``); fixtures live in conftest.py.
"""

from __future__ import annotations

import contextlib
import copy
import io
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.sim.station import VirtualStation
from station.commands.options import DriveOptions, ResumeOptions, RunOptions, SimOptions
from station.config import StationConfig, parse_config
from station.config.toml import toml_text
from station.record.journal_file import read_journal

#: A short simulated procedure: two cycles of three readings, no settling, and a
#: verification never measured again (two cycles of the tests' 2 µm gauges cannot
#: show ±converge_mm, and such a run ends "not-converged", saying so; the tests of
#: that rule, in test_closed_loop_run and test_interrupt, allow further passes).
#: docs/model.md's "paper order" of the twelve deviations, (posture, leg, direction):
#: the order of the paper's Table 1 and of the check values.
PAPER_KEYS: list[tuple[str, str, str]] = [
    (k[0], k[1], k[2]) for k in "+yx +xy -yx -xy +zx +xz -zx -xz +zy +yz -zy -yz".split()]

FAST: dict[str, Any] = {"cycles": 2, "readings": 3, "settle_s": 0.0, "max_extra_passes": 0}

#: The report of the tests' simulated runs: without its figures ([report] figures =
#: false), unless the test says ``figures=True``. Drawing them costs a second of CPU
#: per run, most of what a short run costs, and the hundreds of runs whose subject
#: is not the report would pay it for nothing; the figures have their own tests
#: (test_report, test_tool_report, test_truth_first, test_unchanged's golden run).
NO_FIGURES: dict[str, Any] = {"figures": False}


def no_figures_file(folder: Path) -> str:
    """A SIM.toml (``run --simulate FILE``) holding only :data:`NO_FIGURES` as its
    ``[report]``: what a test's command line (in a subprocess too) runs with."""
    path = Path(folder) / "no-figures.sim.toml"
    path.write_text(toml_text({"report": NO_FIGURES}), encoding="utf-8")
    return str(path)


#: A station of two gauges moved from leg to leg (config as data).
BASE: dict[str, Any] = {
    "indicators": [{"name": "A", "port": "/dev/a"}, {"name": "B", "port": "/dev/b"}],
    "setups": [
        {"leg": "x", "indicators": {"A": "y", "B": "z"}},
        {"leg": "y", "indicators": {"A": "x", "B": "-z"}},
        {"leg": "z", "indicators": {"A": "x", "B": "y"}},
    ],
}


def station_data(**sections: Any) -> dict[str, Any]:
    """A fresh copy of BASE with each given section's keys merged in
    (``controller={...}`` etc.): config as data, for a test to change further."""
    data = copy.deepcopy(BASE)
    for name, values in sections.items():
        if isinstance(values, dict) and isinstance(data.get(name), dict):
            data[name].update(copy.deepcopy(values))
        else:
            data[name] = copy.deepcopy(values)
    return data


def station_config(**sections: Any) -> StationConfig:
    """:func:`station_data`, parsed."""
    return parse_config(station_data(**sections))


def journal_header(**fields: Any) -> dict[str, Any]:
    """A journal's ``header`` record (without ``t``) for the tests' station (BASE),
    its config and plan as a run journals them, with ``fields`` put in."""
    from station.plan.steps import build_plan

    config = station_config()
    return {"type": "header", "version": "test", "config": config.model_dump(),
            "plan": build_plan(config).to_json(), "simulation": None,
            "started": "2026-01-01T00:00:00+00:00", **fields}


def simulated(out: Path, *, seed: int | None = 7, noise: float | None = 0.002,
              procedure: dict[str, Any] | None = FAST, hook: Any = None, yes: bool = False,
              json: bool = True, plan: bool = False, true_drho: Any = None,
              true_dl: Any = None, true_tilt: Any = None, true_gap: Any = None,
              mount_error: float | None = None,
              motion: str | None = None, drive_profile: str | None = None,
              drive_accel: str | None = None, drive_delays: str | None = None,
              drive_sequence: str | None = None, indicators: int = 2,
              writeback: dict[str, Any] | None = None, speed: float | None = None,
              backlash: str | None = None, profile: str | None = None,
              leg_bow: str | None = None, gauge_scale: str | None = None,
              uncertainty: dict[str, Any] | None = None, figures: bool = False
              ) -> RunOptions:
    """``orthocal run --simulate`` into ``out``, with the test knobs the command
    line does not offer: ``hook`` (given the running virtual station), ``procedure``
    and ``writeback`` overrides, ``indicators`` (2 or 6), ``speed`` (mm/s),
    ``uncertainty`` (the config's [uncertainty]), ``figures`` (the report's,
    :data:`NO_FIGURES`)."""
    if uncertainty is not None:
        # what a user writes in the config's [uncertainty] (the simulated legs and
        # gauges are as the test makes them)
        inner = hook

        def hook(station: Any) -> None:
            # the test's keys over what the simulated station states ({}: nothing)
            config = station.config
            station.config = lambda: {**config(), "uncertainty": {} if uncertainty == {} else {
                **config().get("uncertainty", {}), **uncertainty}}
            if inner is not None:
                inner(station)

    sim = SimOptions(
        seed=seed, true_drho=true_drho, true_dl=true_dl, true_tilt=true_tilt,
        true_gap=true_gap, noise=noise,
        mount_error=mount_error, backlash=backlash, leg_bow=leg_bow,
        gauge_scale=gauge_scale, profile=profile,
        drive=DriveOptions(motion=motion, profile=drive_profile, accel=drive_accel,
                           delays=drive_delays, sequence=drive_sequence),
        indicators=indicators, procedure=procedure, writeback=writeback, speed_mm_s=speed,
        report=None if figures else NO_FIGURES, station_hook=hook)
    return RunOptions(sim=sim, plan=plan, out=Path(out), yes=yes, json=json)


@dataclass
class Completed:
    """What :func:`cli` reports, as ``subprocess.run(..., capture_output=True,
    text=True)`` does."""

    returncode: int
    stdout: str
    stderr: str


def cli(*argv: str, cwd: Path) -> Completed:
    """``orthocal ARGV`` run from ``cwd`` in this process (station.commands.cli.main,
    its output captured), for tests whose subject is what a command reads, prints
    and exits with (history, compare, export). A ``python -m station`` subprocess
    pays a second and a half of imports the test worker has already paid; the tests
    whose subject is the process itself (kill -9, Ctrl-C, a second station, a pty)
    keep their subprocesses."""
    from station.commands.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.chdir(cwd), contextlib.redirect_stdout(out), \
            contextlib.redirect_stderr(err):
        try:
            code = main(list(argv))
        except SystemExit as exc:  # argparse reports usage errors by exiting 2
            code = exc.code if isinstance(exc.code, int) else 1
    return Completed(code, out.getvalue(), err.getvalue())


def parsed_simulate(*argv: str) -> Any:
    """``orthocal run --simulate --seed 5 ARGV`` as the command line parses it."""
    from station.commands import cli

    return cli.build_parser().parse_args(["run", "--simulate", "--seed", "5", *argv])


def resumed(run_dir: Path, *, yes: bool = False, json: bool = True,
            hook: Any = None) -> ResumeOptions:
    """``orthocal resume RUN_DIR`` (or rollback), ``hook`` given the restarted
    virtual station of a simulated run."""
    return ResumeOptions(run_dir=Path(run_dir), yes=yes, json=json, station_hook=hook)


# --- the rig of the ``orthocal`` CLI fixture (conftest.py) -----------------------------


@dataclass
class Rig:
    """The virtual stations the command started, and what they were asked to do."""

    stations: list[VirtualStation] = field(default_factory=list)
    writes: list[tuple[int, int]] = field(default_factory=list)  # (address, words)
    # the first station's gauges (a closed station forgets them)
    gauges: dict[str, Any] = field(default_factory=dict)

    @property
    def station(self) -> VirtualStation:
        return self.stations[0]


#: ``prepare(rig, station)``: given every virtual station the command starts.
Prepare = Callable[[Rig, VirtualStation], None]


@dataclass
class CliOutcome:
    """What one command of the ``orthocal`` fixture did."""

    code: int
    out: str
    err: str
    rig: Rig
    out_dir: Path

    @property
    def run_dir(self) -> Path:
        (run_dir,) = [p for p in self.out_dir.glob("run-*") if p.is_dir()]
        return run_dir

    @property
    def journal(self) -> list[dict[str, Any]]:
        return read_journal(self.run_dir / "journal.jsonl")

    def failure_lines(self) -> list[str]:
        return [ln for ln in self.err.splitlines() if ln.startswith("orthocal: failed")]


def on_setup(station: VirtualStation, number: int, action: Callable[[], None]) -> None:
    """Run ``action`` when the operator mounts the gauges of the ``number``-th setup
    (1-based, counted across measurement and verification): a fault mid-run."""
    mount = station.mount
    seen: dict[str, Any] = {"leg": None, "setups": 0}

    def wrapped(name: str, leg: str, direction: str, at: float = 0.5) -> None:
        if leg != seen["leg"]:
            seen["leg"] = leg
            seen["setups"] += 1
            if seen["setups"] == number:
                action()
        mount(name, leg, direction, at=at)

    station.mount = wrapped  # type: ignore[method-assign]


# --- deviations as the station forms them (the maths' tests) ------------------------


def station_deviations(truth: Any, rng: Any, *, noise: float = 0.002, cycles: int = 3,
                       readings: int = 5, stands: Any = None) -> tuple[dict, Any]:
    """Per-cycle deviations as the station forms them, on the nominal geometry: stop
    means of ``readings`` gaussian readings (σ ``noise``) per gauge, P − (Z_before +
    Z_after)/2, consecutive cycles sharing their Π0; ``stands``: each gauge's stand
    off L/2 (mm, orthocal.stands.GAUGES order), each gauge then reading in its own
    plane. Also the std of the readings at each stop (6 gauges × 3·cycles + 1)."""
    import numpy as np

    from orthocal import Geometry, deviations
    from orthocal.stands import GAUGES

    keys = [(s, i, j) for i, j in GAUGES for s in "+-"]
    planes = None if stands is None else \
        np.asarray(stands)[[GAUGES.index((k[1], k[2])) for k in keys]]
    exact = dict(zip(keys, deviations(keys, Geometry(), truth, planes), strict=True))
    raw = rng.normal(0, noise, (6, 3 * cycles + 1, readings))
    m = raw.mean(axis=2)
    data = {}
    for g, (i, j) in enumerate(GAUGES):
        for s, off in (("+", 1), ("-", 2)):
            data[(s, i, j)] = [exact[(s, i, j)] + m[g, 3 * (k - 1) + off]
                               - 0.5 * (m[g, 3 * (k - 1)] + m[g, 3 * k])
                               for k in range(1, cycles + 1)]  # fmt: skip
    return data, raw.std(axis=2, ddof=1).ravel()
