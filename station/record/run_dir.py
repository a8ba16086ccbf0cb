"""The run directory: creating one, what it holds, and reopening one for resume and
rollback.

A run directory holds everything needed to understand and to continue a run:
config.toml (the config it ran with), plan.txt / plan.json, journal.jsonl,
offsets_backup.json, result.json, report.html, model.json (the identified machine),
mounting-N-leg-L.svg (each setup's mounting picture, station.report.mounting_files),
copies of the register-map and joint-test files the config names and, for a
simulated run,
simulation.json (the hidden errors, to restart the virtual station on resume) and
controller_nvram.json (the virtual controller's non-volatile offsets).
"""

from __future__ import annotations

import json
import shutil
from datetime import UTC, datetime
from pathlib import Path

from station.config import StationConfig
from station.config.toml import dump_toml
from station.errors import BadInput, RunFailed
from station.plan.steps import Plan
from station.record.journal_file import JOURNAL_NAME, read_records
from station.record.result_base import JsonObject
from station.record.state import RunState

SIM_NAME = "simulation.json"
NVRAM_NAME = "controller_nvram.json"
#: The identified machine, for a controller or a tool that compensates kinematics.
MODEL_NAME = "model.json"


def version() -> str:
    try:
        from importlib.metadata import version

        return version("orthocal")
    except Exception:
        return "unknown"


def now_iso() -> str:
    return datetime.now(UTC).astimezone().isoformat(timespec="seconds")


def new_run_dir(out: Path) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    for n in range(1000):
        path = out / (f"run-{stamp}" if n == 0 else f"run-{stamp}-{n}")
        try:
            path.mkdir()
            return path
        except FileExistsError:
            continue
    raise RunFailed(f"cannot create a run directory under {out}")


#: A run directory's copy of the register-map file its config's profile names.
MAP_NAME = "register_map.toml"
#: A run directory's copy of each joint's test file ([joints] tests), by joint.
JOINT_TEST_NAME = "joint_test_{axis}.csv"


def write_run_files(run_dir: Path, config: StationConfig, plan: Plan,
                    sim: JsonObject | None) -> None:
    """What a run directory holds before the first record of its journal: a register
    map the profile names as a file is copied in (MAP_NAME) and the run's config
    names the copy, so the run resumes and rolls back as it ran whatever becomes of
    the file; so are the joints' test files (JOINT_TEST_NAME)."""
    from drivers.map_files import is_map_file, map_to_toml, resolve_map

    if sim is not None:
        (run_dir / SIM_NAME).write_text(json.dumps(sim, indent=2) + "\n")
    profile = config.controller.profile
    if is_map_file(profile) and Path(profile).name != MAP_NAME:
        (run_dir / MAP_NAME).write_text(map_to_toml(resolve_map(profile),
                                                    f"the register map of this run, "
                                                    f"copied from {profile}"))
        config = config.model_copy(update={"controller": config.controller.model_copy(
            update={"profile": MAP_NAME})})
    tests = {axis: JOINT_TEST_NAME.format(axis=axis) for axis in config.joints.tests}
    if tests != config.joints.tests:
        for axis, path in config.joints.tests.items():
            shutil.copyfile(path, run_dir / tests[axis])
        config = config.model_copy(update={"joints": config.joints.model_copy(
            update={"tests": tests})})
    (run_dir / "config.toml").write_text(dump_toml(config))
    (run_dir / "plan.txt").write_text(plan.format() + "\n")
    (run_dir / "plan.json").write_text(json.dumps(plan.to_json(), indent=1) + "\n")


def reopen(run_dir: Path) -> tuple[Path, RunState]:
    """A run directory (named on the command line) and its journal's state, for the
    run's :class:`~station.record.journal_file.Journal` to go on from."""
    if not run_dir.is_dir():
        raise BadInput(f"{run_dir}: no such run directory")
    return run_dir, RunState.of(read_records(run_dir / JOURNAL_NAME))
