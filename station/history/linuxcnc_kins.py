"""The whole identified geometry into LinuxCNC (docs/design.md, "The geometry in the
controller"): ``orthocal export --to linuxcnc --kinematics`` writes the machine's
INI with the orthoglidekins component as its kinematics, a HAL file that sets the
component's geometry pins from the run, and the component's source. Pure: from the
run's record and the INI's text (and the text of the HAL files it lists) to text.

- HOME_OFFSET as the plain export writes it (station.history.controller_terms.linuxcnc);
  where the drive itself holds the offsets the run wrote, left as it was and said
  in a comment: the joints then already count as the station commanded them, and
  the ``drho`` pins carry only what those offsets did not correct.
- ``[KINS] KINEMATICS = orthoglidekins`` and ``JOINTS = 3``, the old values kept
  in comments.
- ``[HAL] HALFILE = orthoglide-geometry.hal`` after the file that loads the
  kinematics: its ``setp`` lines need the component's pins, which exist once the
  motion module has asked the kinematics for their type.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence

from station.history.controller_terms import ExportError, linuxcnc
from station.record.exportable import HEADER, header_lines
from station.record.identified import COMPONENT, IdentifiedMachine
from station.record.result import RunResult

#: The HAL file the export writes beside the INI.
GEOMETRY_HAL = "orthoglide-geometry.hal"
#: The component's source, as the export writes it beside the INI.
COMPONENT_FILE = f"{COMPONENT}.comp"
_SECTION = re.compile(r"\s*\[([^\]]+)\]")
#: Comment lines an earlier --kinematics export wrote, which this one writes afresh:
#: kept, an export onto an exported INI would name the run before beside this one.
_OWN = ("# orthocal export --kinematics:", "# orthocal: the geometry of ",
        "# orthocal: HOME_OFFSET left as it was:", HEADER)


def geometry_hal(machine: IdentifiedMachine, header: Sequence[str] = ()) -> str:
    """One ``setp orthoglidekins.<pin> <value>`` per pin, each with its meaning and
    95 % interval, and the run, the machine and the model in the header, under the
    export's ``header`` lines (station.record.exportable.header_lines)."""
    lines = [
        *header,
        f"# {GEOMETRY_HAL}: the machine's geometry for the {COMPONENT} kinematics, written",
        f"# by orthocal export --kinematics from {machine.describe()}.",
        "# Units: mm (leg lengths L + dL, gaps, drho), mrad (tilts); conventions of",
        "# orthocal's docs/model.md. drho is what the offsets written did not correct.",
        "# Intervals are 95 %. A parameter the run did not identify is at its nominal value,",
        "# and says why.",
    ]
    for v in machine.values:
        iv = "" if v.interval_95 is None else \
            f"; 95 %: [{v.interval_95[0]:.6f}, {v.interval_95[1]:.6f}] {v.unit}"
        lines.append(f"# {v.name} ({v.unit}): {v.note}{iv}")
        lines.append(f"setp {COMPONENT}.{v.pin} {v.value:.9f}")
    return "\n".join(lines) + "\n"


def _sections(ini_text: str) -> list[tuple[str, str]]:
    """(section, line) for every line of the INI ("" before the first section)."""
    section, out = "", []
    for line in ini_text.splitlines():
        if m := _SECTION.match(line):
            section = m.group(1).strip()
        out.append((section, line))
    return out


def _key(line: str) -> str | None:
    m = re.match(r"\s*([A-Za-z_][A-Za-z0-9_]*)\s*=", line)
    return m.group(1) if m else None


def _loads_kinematics(name: str, read_hal: Callable[[str], str | None]) -> bool:
    """Whether the HAL file ``name`` loads the kinematics ([KINS]KINEMATICS, or a
    kinematics module named outright)."""
    text = read_hal(name)
    return text is not None and bool(
        re.search(r"KINEMATICS|\bloadrt\s+\S*kins\b", text))


def _hal_line(lines: list[tuple[str, str]], read_hal: Callable[[str], str | None]) -> int:
    """The index after which ``HALFILE = orthoglide-geometry.hal`` goes: after the
    last HALFILE that loads the kinematics, else after the first (LinuxCNC's
    configurations load motion and kinematics in their first)."""
    # an earlier export's geometry file is no candidate: its line is dropped, and the
    # new one would go with it
    files = [(i, name) for i, name in _halfiles(lines) if GEOMETRY_HAL not in name]
    if not files:
        raise ExportError("--ini: [HAL] lists no HALFILE, so there is no file that loads the "
                          f"kinematics for {GEOMETRY_HAL} to follow")
    loading = [i for i, name in files if _loads_kinematics(name, read_hal)]
    return loading[-1] if loading else files[0][0]


def _halfiles(lines: list[tuple[str, str]]) -> list[tuple[int, str]]:
    """(index, file) of every ``[HAL] HALFILE``."""
    return [(i, line.split("=", 1)[1].split("#")[0].strip()) for i, (sec, line)
            in enumerate(lines) if sec == "HAL" and _key(line) == "HALFILE"]


def _check_kins(lines: list[tuple[str, str]], source: str) -> None:
    """A [KINS] section with a KINEMATICS line, for the component to take its place."""
    if "KINS" not in {sec for sec, _ in lines}:
        raise ExportError(f"{source}: no [KINS] section (LinuxCNC 2.9 names its kinematics "
                          "there)")
    if not any(sec == "KINS" and _key(line) == "KINEMATICS" for sec, line in lines):
        # else the INI would be written without the kinematics it is exported for
        raise ExportError(f"{source}: [KINS] has no KINEMATICS (LinuxCNC 2.9 loads the "
                          "kinematics it names)")


def kinematics_ini(result: RunResult, machine: IdentifiedMachine, ini_text: str,
                   joints: Sequence[int], source: str, backlash: bool,
                   read_hal: Callable[[str], str | None], forced: bool = False,
                   words: Sequence[str] = (), tabled: Sequence[str] = ()) -> str:
    """The INI with HOME_OFFSET (as the plain export, or kept where the drive holds
    the offsets), the component as its kinematics and the geometry's HAL file, under
    the export's header (``forced``: exported with --force, and why it needed it) and
    ``words`` (what the export takes into account); ``tabled``: the joints whose
    compensation file carries their reversal (no BACKLASH for them)."""
    held = machine.offsets_held_by == "controller"
    text = ini_text if held else linuxcnc(result, ini_text, joints, source, backlash,
                                          tabled=tabled)
    lines = _sections(text)
    _check_kins(lines, source)
    after_hal = _hal_line(lines, read_hal)
    out: list[str] = []
    for i, (sec, line) in enumerate(lines):
        key = _key(line)
        if line.startswith(_OWN):
            continue
        if sec == "KINS" and key in ("KINEMATICS", "JOINTS"):
            new = f"KINEMATICS = {COMPONENT}" if key == "KINEMATICS" else "JOINTS = 3"
            # the old line in a comment where it said something else
            out += [new] if line.strip() == new else [f"# orthocal: was {line.strip()}", new]
            continue
        if sec == "HAL" and key == "HALFILE" and GEOMETRY_HAL in line:
            continue  # an earlier export's line: written once, below
        if held and sec.startswith("JOINT_") and key == "HOME_OFFSET":
            out.append("# orthocal: HOME_OFFSET left as it was: the drive holds the offsets "
                       f"the run wrote (offsets_held_by = controller); {GEOMETRY_HAL}'s drho "
                       "pins carry only what they did not correct")
        out.append(line)
        if i == after_hal:
            out += [f"# orthocal: the geometry of {machine.describe()}, after the file that "
                    "loads the kinematics", f"HALFILE = {GEOMETRY_HAL}"]
    if not any(sec == "KINS" and _key(line) == "JOINTS" for sec, line in lines):
        at = max(i for i, line in enumerate(out) if line.startswith("KINEMATICS = "))
        out.insert(at + 1, "JOINTS = 3")
    header = [*header_lines(result, forced), *words,
              f"# orthocal export --kinematics: {machine.describe()}. Build the "
              f"kinematics once: sudo halcompile --install {COMPONENT_FILE}"]
    return "\n".join(header + out) + "\n"
