"""``orthocal export``: a run's result in a controller's terms (docs/design.md,
"Machine history", export; "The geometry in the controller"): the offsets as LinuxCNC's
HOME_OFFSET, a TwinCAT parameter list or CSV, and with ``--kinematics`` the whole
identified geometry for LinuxCNC's orthoglidekins component."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from drivers.files import write_atomic
from station.commands.history import read_result
from station.errors import BadInput, say

if TYPE_CHECKING:
    from station.record.result import RunResult

#: LinuxCNC's HAL library, where ``HALFILE = LIB:name`` finds its file (Debian's path).
HALLIB = "/usr/share/linuxcnc/hallib"


def _read_hal(ini: Path) -> Callable[[str], str | None]:
    """A HALFILE's text as LinuxCNC finds it: relative to the INI's folder, or in
    its library for ``LIB:`` (None where it cannot be read)."""
    def read(name: str) -> str | None:
        path = Path(HALLIB) / name[4:] if name.startswith("LIB:") else ini.parent / name
        try:
            return path.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return None
    return read


def _may_export(args: argparse.Namespace, result: RunResult) -> bool:
    """Whether the run goes out as it is, for every target (station.record.exportable,
    the one decision): a run that did not converge, or whose last round was
    ambiguous, only with --force (then True: its header says what it carries);
    without, one line naming the run and why (exit 2). The machine's later runs in
    the history are named before anything is written."""
    from station.history.later import later_warning
    from station.record.exportable import refusal

    why = refusal(result, args.run_dir)
    if why is not None and not args.force:
        raise BadInput(why)
    line = later_warning(Path(args.run_dir), result.machine.id, result.started,
                         "this run's offsets are older than theirs: exported, they "
                         "replace what those runs left")
    if line is not None:
        say(line)
    return why is not None


def kinematics_export(args: argparse.Namespace, result: RunResult) -> int:
    """``export --to linuxcnc --kinematics``: the INI, the geometry's HAL file and the
    component's source, into the folder --out."""
    from importlib.resources import files

    from station.history.controller_terms import ExportError
    from station.history.linuxcnc_kins import (
        COMPONENT_FILE,
        GEOMETRY_HAL,
        geometry_hal,
        kinematics_ini,
    )
    from station.record.exportable import header_lines
    from station.record.identified import NotACalibration, identified_machine

    if args.to != "linuxcnc":
        raise BadInput(f"--kinematics: only for --to linuxcnc (the orthoglidekins "
                       f"component), not {args.to}; any other controller: orthocal compensate")
    if args.ini is None or args.out is None:
        raise BadInput("--kinematics: give the machine's INI (--ini) and a folder (--out) "
                       "for the three files")
    ini, out = Path(args.ini), Path(args.out)
    target = out / ini.name
    if target.resolve() == ini.resolve():
        raise BadInput(f"--out: {out} holds the machine's own INI: the export would "
                       "overwrite it; give another folder")
    forced = _may_export(args, result)
    try:
        ini_text = ini.read_text(encoding="utf-8")
    except OSError as exc:
        raise BadInput(f"--ini: cannot read {ini} ({exc.strerror})") from None
    try:
        machine = identified_machine(args.run_dir)
        text = kinematics_ini(result, machine, ini_text, _joints(args.joints), str(ini),
                              args.backlash, _read_hal(ini), forced)
    except (NotACalibration, ExportError) as exc:
        raise BadInput(str(exc)) from None
    comp = (files("orthocal") / COMPONENT_FILE).read_text(encoding="utf-8")
    try:
        out.mkdir(parents=True, exist_ok=True)
        hal = geometry_hal(machine, header_lines(result, forced))
        for name, body in ((ini.name, text), (GEOMETRY_HAL, hal), (COMPONENT_FILE, comp)):
            write_atomic(out / name, body)
    except OSError as exc:
        raise BadInput(f"--out: cannot write into {out} ({exc.strerror})") from None
    print(f"wrote {target}, {out / GEOMETRY_HAL} and {out / COMPONENT_FILE}")
    # LinuxCNC reads the INI's relative files (HALFILEs, tool table, parameter file)
    # from the INI's own folder: started from --out it stops at the first HAL file
    print(f"to use them: copy {ini.name} and {GEOMETRY_HAL} into {ini.parent} (over the "
          f"INI there), and build the component once: sudo halcompile --install "
          f"{out / COMPONENT_FILE}")
    return 0


def _joints(text: str) -> list[int]:
    try:
        joints = [int(j) for j in text.split(",")]
    except ValueError:
        raise BadInput(f"--joints: three joint numbers for x,y,z, got {text}") from None
    if len(joints) != 3:
        raise BadInput(f"--joints: three joint numbers for x,y,z, got {text}")
    return joints


def export_main(args: argparse.Namespace) -> int:
    from station.history.controller_terms import ExportError, csv_lines, linuxcnc
    from station.history.twincat import twincat

    _, result = read_result(args.run_dir)
    if args.kinematics:
        return kinematics_export(args, result)
    forced = _may_export(args, result)
    try:
        if args.to == "csv":
            text = csv_lines(result, forced)
        elif args.to == "twincat":
            text = twincat(result, args.axes.split(","), backlash=args.backlash,
                           forced=forced)
        else:
            if args.ini is None:
                raise BadInput("--ini: LinuxCNC takes HOME_OFFSET as a value, not a "
                               "correction; give the machine's INI file")
            try:
                ini_text = Path(args.ini).read_text(encoding="utf-8")
            except OSError as exc:
                raise BadInput(f"--ini: cannot read {args.ini} ({exc.strerror})") from None
            joints = [int(j) for j in args.joints.split(",")]
            if len(joints) != 3:
                raise BadInput(f"--joints: three joint numbers for x,y,z, got {args.joints}")
            text = linuxcnc(result, ini_text, joints, source=str(args.ini),
                            backlash=args.backlash, forced=forced)
    except ExportError as exc:
        raise BadInput(str(exc)) from None
    except ValueError as exc:
        raise BadInput(f"--joints: {exc}") from None
    if args.out:
        try:
            Path(args.out).write_text(text, encoding="utf-8")
        except OSError as exc:
            raise BadInput(f"--out: cannot write {args.out} ({exc.strerror})") from None
    else:
        sys.stdout.write(text)
    return 0
