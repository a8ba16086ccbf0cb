"""``orthocal run --simulate SIM.toml``: the virtual machine a file describes
(station.commands.simulate.rehearsal_file, its ``[simulation]`` table), with the options given on
the command line winning over it."""

from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from drivers.map_files import is_map_file
from station.commands.options import DriveOptions, RunOptions, SimOptions
from station.commands.simulate.launch import sim_params
from station.commands.simulate.rehearsal_file import as_text, read_simulation
from station.errors import BadInput


def _key_of(option: str) -> str:
    """The file's key of a long option: --true-drho → simulation.true_drho,
    --drive-profile → simulation.drive.profile, --motion → simulation.drive.motion."""
    name = option.lstrip("-").replace("-", "_")
    if name == "motion" or name.startswith("drive_"):
        return "simulation.drive." + name.removeprefix("drive_")
    return "simulation." + name


def load_simulation(path: str | Path) -> SimOptions:
    """The options the file at ``path`` gives (checked whole, with the options'
    own checks); BadInput naming the file and the key."""
    path = Path(path)
    source = str(path)
    doc = read_simulation(path)
    s, d = doc.simulation, doc.simulation.drive
    profile = s.profile
    if profile is not None and is_map_file(profile) and not Path(profile).is_absolute():
        profile = str((path.parent / profile).resolve())
    options = SimOptions(
        seed=s.seed, true_drho=s.true_drho, true_dl=s.true_dl, true_tilt=s.true_tilt,
        true_gap=s.true_gap, noise=s.noise, mount_error=s.mount_error,
        backlash=as_text(s.backlash), leg_bow=as_text(s.leg_bow),
        gauge_scale=as_text(s.gauge_scale), profile=profile, gauges=s.gauges,
        joint_lead=as_text(s.joint_lead), joint_pitch=as_text(s.joint_pitch),
        joint_test=s.joint_test,
        drive=DriveOptions(motion=d.motion, profile=as_text(d.profile), accel=as_text(d.accel),
                           delays=as_text(d.delays), sequence=d.sequence),
        procedure=_given(doc.procedure), writeback=_given(doc.writeback),
        report=_given(doc.report), uncertainty=_given(doc.uncertainty))
    try:  # the options' own checks, said in the file's words
        sim_params(options)
    except BadInput as exc:
        # the options' words made the file's: "--drive-sequence: … give --motion
        # independent" → "simulation.drive.sequence: … give simulation.drive.motion …"
        said = re.sub(r"--[a-z][\w-]*", lambda m: _key_of(m.group(0)), str(exc))
        raise BadInput(f"{source}: {said}") from None
    return options


def _given(table: BaseModel | None) -> dict[str, Any] | None:
    """A table of overrides as the keys the file gives (None: no table)."""
    return None if table is None else table.model_dump(exclude_unset=True)


def with_command_line(from_file: SimOptions, given: SimOptions) -> SimOptions:
    """``from_file``'s options with every one ``given`` on the command line instead
    (a SimOptions each; the command line's unset options are None)."""
    drive = dataclasses.replace(from_file.drive, **{
        k: v for k, v in dataclasses.asdict(given.drive).items() if v is not None})
    fields = {f.name: getattr(given, f.name) for f in dataclasses.fields(given)
              if f.name not in ("drive", "indicators") and getattr(given, f.name) is not None}
    return dataclasses.replace(from_file, **fields, drive=drive)


def run_options(args: argparse.Namespace) -> RunOptions:
    """``orthocal run``'s options; with ``--simulate SIM.toml``, the file's virtual
    station with the options given on the command line winning."""
    options = RunOptions.from_args(args)
    if not isinstance(args.simulate, str) or options.sim is None:
        return options
    return dataclasses.replace(
        options, sim=with_command_line(load_simulation(Path(args.simulate)), options.sim))
