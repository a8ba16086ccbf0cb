"""``orthocal export``: a run's result in a controller's terms (docs/design.md,
"Machine history", export; "The geometry in the controller"; "Joint tables in the
controller"): the offsets as LinuxCNC's HOME_OFFSET, a TwinCAT parameter list or CSV,
with ``--kinematics`` the whole identified geometry for LinuxCNC's orthoglidekins
component, and for LinuxCNC and TwinCAT each joint's table of its positioning error
(a compensation file, a leadscrew error compensation list) beside them."""

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
    from station.record.controller_tables import ControllerTables
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


def _tables(result: RunResult) -> ControllerTables:
    """The run's joint tables in the controller's joints (BadInput: one line)."""
    from station.record.controller_tables import NoJointFrame, controller_tables

    try:
        return controller_tables(result)
    except NoJointFrame as exc:
        raise BadInput(str(exc)) from None


def _write_files(folder: Path, files: dict[str, str]) -> list[Path]:
    """Each file into ``folder`` whole (BadInput naming --out where it cannot)."""
    written = []
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for name, body in files.items():
            write_atomic(folder / name, body)
            written.append(folder / name)
    except OSError as exc:
        raise BadInput(f"--out: cannot write into {folder} ({exc.strerror})") from None
    return written


def _needs_out(args: argparse.Namespace, tables: ControllerTables) -> None:
    """A run with joint tables writes files beside --out: it must be given."""
    if tables.tabled and not args.out:
        axes = ", ".join(j.axis for j in tables.tabled)
        raise BadInput(f"--out: the run has joint tables ({axes}): give --out FILE; their "
                       "compensation files are written beside it")


def kinematics_export(args: argparse.Namespace, result: RunResult) -> int:
    """``export --to linuxcnc --kinematics``: the INI, the geometry's HAL file and the
    component's source, into the folder --out."""
    from importlib.resources import files

    from station.history.controller_terms import ExportError
    from station.history.linuxcnc_comp import comp_files, with_comp_files
    from station.history.linuxcnc_kins import (
        COMPONENT_FILE,
        GEOMETRY_HAL,
        geometry_hal,
        kinematics_ini,
    )
    from station.record.controller_tables import header_words
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
    tables = _tables(result)
    words = header_words(tables, "kinematics")
    joints = _joints(args.joints)
    tabled = [j.axis for j in tables.tabled]
    try:
        machine = identified_machine(args.run_dir)
        text = kinematics_ini(result, machine, ini_text, joints, str(ini), args.backlash,
                              _read_hal(ini), forced, words, tabled)
        text = with_comp_files(text, tables, joints, str(ini))
        comps = comp_files(tables, joints, [*header_lines(result, forced), *words])
    except (NotACalibration, ExportError) as exc:
        raise BadInput(str(exc)) from None
    comp = (files("orthocal") / COMPONENT_FILE).read_text(encoding="utf-8")
    hal = geometry_hal(machine, [*header_lines(result, forced), *words])
    _write_files(out, {ini.name: text, GEOMETRY_HAL: hal, COMPONENT_FILE: comp, **comps})
    print(f"wrote {target}, {out / GEOMETRY_HAL} and {out / COMPONENT_FILE}"
          + "".join(f", {out / name}" for name in comps))
    # LinuxCNC reads the INI's relative files (HALFILEs, tool table, parameter file,
    # compensation files) from the INI's own folder: started from --out it stops at
    # the first HAL file
    names = [ini.name, GEOMETRY_HAL, *comps]
    moved = ", ".join(names[:-1]) + f" and {names[-1]}"
    print(f"to use them: copy {moved} into {ini.parent} (over the INI there), and build "
          f"the component once: sudo halcompile --install {out / COMPONENT_FILE}")
    return 0


def _joints(text: str) -> list[int]:
    try:
        joints = [int(j) for j in text.split(",")]
    except ValueError:
        raise BadInput(f"--joints: three joint numbers for x,y,z, got {text}") from None
    if len(joints) != 3:
        raise BadInput(f"--joints: three joint numbers for x,y,z, got {text}")
    return joints


def _plain(args: argparse.Namespace, result: RunResult, forced: bool,
           tables: ControllerTables) -> tuple[str, dict[str, str]]:
    """The export's text and the files beside it (name → text), without --kinematics."""
    from orthocal.joint_compensation import ROUTES
    from station.history.controller_terms import csv_lines, linuxcnc
    from station.history.linuxcnc_comp import comp_files, with_comp_files
    from station.history.twincat import twincat
    from station.history.twincat_lsec import lsec_lists
    from station.record.controller_tables import header_words
    from station.record.exportable import HEADER, header_lines

    tabled = [j.axis for j in tables.tabled]
    if args.to == "csv":  # the offsets alone: a table is no row of this file
        words = [f"{HEADER}takes into account: {ROUTES['offsets']}"]
        if tabled:
            words.append(f"{HEADER}joint tables ({', '.join(tabled)}): not in this file; "
                         "export --to linuxcnc or --to twincat writes them")
        return csv_lines(result, forced, words), {}
    words = header_words(tables, "offsets")
    _needs_out(args, tables)
    header = [*header_lines(result, forced), *words]
    if args.to == "twincat":
        axes = args.axes.split(",")
        text = twincat(result, axes, backlash=args.backlash, forced=forced, words=words,
                       tabled=tabled)
        return text, lsec_lists(tables.joints, axes, header)
    if args.ini is None:
        raise BadInput("--ini: LinuxCNC takes HOME_OFFSET as a value, not a "
                       "correction; give the machine's INI file")
    try:
        ini_text = Path(args.ini).read_text(encoding="utf-8")
    except OSError as exc:
        raise BadInput(f"--ini: cannot read {args.ini} ({exc.strerror})") from None
    joints = _joints(args.joints)
    text = linuxcnc(result, ini_text, joints, source=str(args.ini), backlash=args.backlash,
                    forced=forced, words=words, tabled=tabled)
    return with_comp_files(text, tables, joints, str(args.ini)), \
        comp_files(tables, joints, header)


def export_main(args: argparse.Namespace) -> int:
    from station.history.controller_terms import ExportError

    _, result = read_result(args.run_dir)
    if args.kinematics:
        return kinematics_export(args, result)
    forced = _may_export(args, result)
    tables = _tables(result)
    try:
        text, beside = _plain(args, result, forced, tables)
    except ExportError as exc:
        raise BadInput(str(exc)) from None
    except ValueError as exc:
        raise BadInput(f"--joints: {exc}") from None
    if args.out:
        try:
            Path(args.out).write_text(text, encoding="utf-8")
        except OSError as exc:
            raise BadInput(f"--out: cannot write {args.out} ({exc.strerror})") from None
        for path in _write_files(Path(args.out).parent, beside):
            say(f"wrote {path}: copy it beside the controller's configuration")
    else:
        sys.stdout.write(text)
    return 0
