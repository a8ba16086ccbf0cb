"""``orthocal compensate PROGRAM --run RUN_DIR``: a G-code program rewritten for a
controller that runs the machine's nominal kinematics (TwinCAT, Sinumerik, a
LinuxCNC without orthoglidekins) with the run's offsets in its joints, so that the
identified machine's tool follows the programmed path within ``--tolerance``
(station.gcode; docs/design.md, "Command line").

Bad input (the program, the run directory, the options) is one line naming the file,
line and word, exit 2, and no output file is left: the output is written whole, by
a temporary file renamed, once everything is checked."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from station.commands.given_paths import file_to_write
from station.errors import BadInput, read_input, storage_message

if TYPE_CHECKING:
    from station.gcode.rewrite import Job

#: --tolerance within these (mm): below, the format's rounding and the kinematics'
#: own precision are no longer far below it; above, it is no compensation.
TOLERANCE_RANGE = (1e-5, 1.0)


def main(args: argparse.Namespace) -> int:
    from drivers.files import write_atomic
    from station.gcode.rewrite import MARK, compensate
    from station.gcode.words import GcodeError

    program = Path(args.program)
    text = read_input(program)
    if MARK in text:
        raise BadInput(f"{program}: {MARK} already (its header says so): compensate the "
                       "original program, not its output")
    out = output_path(program, args.out, MARK)
    job = _job(args)
    try:
        result = compensate(text, program.name, job)
    except GcodeError as exc:
        raise BadInput(f"{program}:{exc}") from None
    try:
        write_atomic(out, result.text)
    except OSError as exc:
        raise BadInput(f"--out {storage_message(out, exc)}") from None
    print(f"orthocal: {result.motions} motions of {program} written as {result.segments} "
          f"segments within {job.tolerance:g} mm", file=sys.stderr)
    print(out)
    return 0


def output_path(program: Path, out: str | None, mark: str) -> Path:
    """``--out``, default ``<stem>.compensated<suffix>`` beside the program; never the
    program itself, nor a file compensate did not write."""
    path = Path(out) if out else program.with_name(f"{program.stem}.compensated"
                                                    f"{program.suffix}")
    if path.resolve() == program.resolve() or (
            path.exists() and os.path.samefile(path, program)):
        raise BadInput(f"--out: {path} is the program itself; give another file")
    # a folder, a device or a pipe, a folder that is not there or takes no file:
    # said before anything is read or computed
    file_to_write("--out", path, replace=True)
    if path.exists():
        try:
            with path.open(encoding="utf-8", errors="replace") as fh:
                head = fh.read(4096)
        except OSError as exc:
            raise BadInput(f"--out: {path}: cannot read ({exc.strerror})") from None
        if mark not in head:
            raise BadInput(f"--out: {path} exists and orthocal compensate did not write it: "
                           "not overwritten (remove it, or give another --out)")
    return path


def _job(args: argparse.Namespace) -> Job:
    """The run's identified machine and soft limits, the tolerance and work offset."""
    from station.commands.history import read_result
    from station.gcode.rewrite import Job
    from station.gcode.soft_bounds import LimitsError, run_limits
    from station.gcode.subdivide import CompensatedMachine
    from station.record.controller_tables import NoJointFrame, controller_tables
    from station.record.exportable import ambiguous
    from station.record.identified import NotACalibration, identified_machine

    lo, hi = TOLERANCE_RANGE
    if not lo <= args.tolerance <= hi:
        raise BadInput(f"--tolerance: {args.tolerance:g} mm is not within {lo:g} to {hi:g} mm")
    try:
        machine = identified_machine(args.run)
        limits = run_limits(Path(args.run))
    except (NotACalibration, LimitsError) as exc:
        raise BadInput(str(exc)) from None
    _, result = read_result(args.run)
    try:
        tables = controller_tables(result)
    except NoJointFrame as exc:
        raise BadInput(f"{args.run}: {exc}") from None
    if (why := ambiguous(result)) is not None:
        # a tilt there may be a bow, which the tool never sees: compensated for, it
        # would move the tool by what the bows only seemed to be (no --force here: a
        # program is run as it is written)
        raise BadInput(f"{args.run}: {why}: its geometry is no calibration to compensate "
                       "for; read a second gauge plane ([[setups]] again with at = 0.75) and "
                       "calibrate again")
    theta = machine.theta_c()
    told = ", ".join(f"{v.name} {t:+.4f} {v.unit}" for v, t in zip(machine.values, theta,
                                                                  strict=True) if t != 0.0)
    notes = [f"compensated for: {told or 'nothing, the machine is nominal'}",
             *tables.words("program")]
    if tables.tabled:
        notes.append("each joint's error is taken for the direction the program moves it; "
                     "where a joint turns back, its point is written twice: reached with "
                     "the counts of the old direction, left with those of the new, so "
                     "that the joint takes up its reversal while the tool stands")
    if machine.offsets_held_by == "station":
        notes.append("the run's offsets were held by the station: the controller must hold "
                     "them too (orthocal export) before this program runs")
    joints = tables.errors() if tables.tabled else None
    return Job(CompensatedMachine(machine.geometry, theta, joints), limits, float(args.tolerance),
               np.asarray(args.work_offset, dtype=float), machine.describe(), tuple(notes))
