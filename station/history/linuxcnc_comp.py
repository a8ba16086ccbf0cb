"""Each joint's positioning error in LinuxCNC (docs/design.md, "Joint tables in the
controller"): one compensation file per joint that has a table, and ``[JOINT_n]
COMP_FILE`` / ``COMP_FILE_TYPE`` in the machine's INI. Pure: from the tables and the
INI's text to text.

How LinuxCNC 2.9 applies a file (src/emc/motion/usrmotintf.cc, ``usrmotLoadComp``;
src/emc/motion/command.c, ``EMCMOT_SET_JOINT_COMP``; src/emc/motion/control.c,
``compute_screw_comp`` and ``output_to_hal``): each line is ``nominal a b``; type 0
stores the trims nominal − a and nominal − b (a, b the positions the joint actually
reaches), type 1 stores a and b as they are. While the joint's commanded position
rises (``vel_cmd > 0``) the forward trim, interpolated linearly at the commanded
position, is added to it, while it falls the reverse trim, and a joint that stands
keeps the trim it had: ``motor-pos-cmd = pos_cmd + backlash_filt + motor_offset``,
backlash_filt ramping to the trim. Below the first nominal and above the last the end's
trim holds. Reading stops at the first line that is not three numbers, so the file's
comments follow its table, after a blank line. A joint with a COMP_FILE ignores
BACKLASH: the file carries the reversal.

The export writes type 1: the trims are the correction itself, t = c − q of
orthocal's (J5), −ε to first order, so a joint commanded to q stands at q. One extra
line, 1 mm below the table, has zero trims: LinuxCNC computes the trim from the
joint's count before it is homed too (from 0 at start), and keeps the one it had
when the joint is homed, which then becomes part of the joint's zero; held at zero
there, the count the joint is homed to is its own.
"""

from __future__ import annotations

import configparser
import re
from collections.abc import Sequence

from orthocal.joint_compensation import trims
from station.history.controller_terms import ExportError
from station.record.controller_tables import ControllerJoint, ControllerTables

#: LinuxCNC 2.9's table size per joint (src/emc/motion/motion.h, EMCMOT_COMP_SIZE).
MAX_ENTRIES = 256
#: The type the export writes: nominal, forward trim, reverse trim.
COMP_FILE_TYPE = 1
#: Where the zero-trim line stands below the table's first target (mm).
BELOW_MM = 1.0
_SECTION = re.compile(r"\s*\[([^\]]+)\]")
_KEY = re.compile(r"\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*([^#;]*)")
#: The comment lines this export writes into the INI: written afresh each time.
_OWN = "# orthocal: joint "


def comp_file_name(axis: str) -> str:
    """The compensation file of joint ``axis``, beside the INI."""
    return f"orthocal-joint-{axis}.comp"


def comp_file(joint: ControllerJoint, number: int, header: Sequence[str]) -> str:
    """The compensation file of ``joint`` (LinuxCNC's joint ``number``): the zero-trim
    line, then per target of its table ``nominal forward_trim reverse_trim`` (mm),
    then a blank line and the comments: ``header`` (the export's) and what the
    columns are."""
    table = joint.table
    if table is None:
        raise ValueError(f"joint {joint.axis} has no table")
    if len(table.targets_mm) + 1 > MAX_ENTRIES:
        raise ExportError(f"joint {joint.axis}: its table has {len(table.targets_mm)} "
                          f"targets; LinuxCNC 2.9 takes {MAX_ENTRIES} lines per joint, "
                          "one of them the export's zero line")
    t = trims(table)
    lo, hi = table.span
    rows = [f"{lo - BELOW_MM:.6f} 0.000000000 0.000000000"]
    rows += [f"{n:.6f} {f:.9f} {r:.9f}" for n, f, r in
             zip(t.nominal_mm, t.forward_mm + 0.0, t.reverse_mm + 0.0, strict=True)]
    notes = [
        *header,
        f"# {comp_file_name(joint.axis)}: joint {joint.axis} (JOINT_{number}), "
        f"{joint.describe()}, referred to Pi0.",
        f"# COMP_FILE_TYPE = {COMP_FILE_TYPE}: nominal (the joint commanded, mm), forward "
        "trim, reverse trim (mm):",
        "# what LinuxCNC adds to the joint it commands while the joint moves up (down), so",
        "# that the joint stands where it is commanded: -(its error) to first order.",
        f"# The table's targets moved by {joint.shift_mm:+.6f} mm: the joint commanded now "
        "stands",
        "# where the test's target stood then (the offsets the run wrote).",
        f"# Beyond {lo:.3f} .. {hi:.3f} mm LinuxCNC holds the end's trim: not compensated "
        "there.",
        f"# The first line ({lo - BELOW_MM:.3f} mm, zero trims) holds the trim at zero "
        "for the count",
        "# before homing, so that homing sets the joint's zero without a trim in it.",
        "# LinuxCNC reads the lines above until this blank line; these comments it skips.",
    ]
    return "\n".join([*rows, "", *notes]) + "\n"


def _limits(ini_text: str) -> dict[str, dict[str, float]]:
    """Each [JOINT_n]'s MIN_LIMIT and MAX_LIMIT where they are numbers."""
    ini = configparser.ConfigParser(strict=False, interpolation=None,
                                    inline_comment_prefixes=("#", ";"))
    ini.optionxform = str  # type: ignore[method-assign,assignment]
    try:
        ini.read_string(ini_text)
    except configparser.Error:
        return {}
    out: dict[str, dict[str, float]] = {}
    for section in ini.sections():
        for key in ("MIN_LIMIT", "MAX_LIMIT"):
            try:
                out.setdefault(section, {})[key] = float(ini.get(section, key))
            except (configparser.Error, ValueError):
                continue
    return out


def _lines_for(joint: ControllerJoint, section: str,
               limits: dict[str, dict[str, float]]) -> list[str]:
    """The COMP_FILE lines of a joint with a table, under their comment."""
    assert joint.table is not None
    lo, hi = joint.table.span
    lines = [f"{_OWN}{joint.axis}: its positioning error per direction, "
             f"{joint.describe()} ({comp_file_name(joint.axis)}: nominal, forward trim, "
             "reverse trim; LinuxCNC ignores BACKLASH where a joint has a COMP_FILE)"]
    lim = limits.get(section, {})
    beyond = [f"{k} {v:g}" for k, v in sorted(lim.items())
              if (k == "MIN_LIMIT" and v < lo) or (k == "MAX_LIMIT" and v > hi)]
    if beyond:
        lines.append(f"{_OWN}{joint.axis}: its table spans {lo:.3f} .. {hi:.3f} mm; "
                     f"{', '.join(beyond)} lie beyond, where it is not compensated")
    return [*lines, f"COMP_FILE = {comp_file_name(joint.axis)}",
            f"COMP_FILE_TYPE = {COMP_FILE_TYPE}"]


def with_comp_files(ini_text: str, tables: ControllerTables, joints: Sequence[int],
                    source: str = "INI") -> str:
    """The INI with ``COMP_FILE`` and ``COMP_FILE_TYPE`` in the ``[JOINT_n]`` of each
    joint that has a table (``joints``: the joint numbers of x, y, z), right under the
    section's name; a line the INI had is replaced (kept as a comment where it said
    something else), an earlier export's never doubled; an earlier export's COMP_FILE
    for a joint that now has no table removed, with why. ExportError where a joint with
    a table has no section."""
    by_section = {f"JOINT_{n}": tables.joint(axis)
                  for axis, n in zip(("x", "y", "z"), joints, strict=True)}
    present = {m.group(1).strip() for line in ini_text.splitlines()
               if (m := _SECTION.match(line))}
    for section, needed in by_section.items():
        if needed.table is not None and section not in present:
            raise ExportError(f"{source}: no [{section}] section for joint {needed.axis}'s "
                              "compensation file (--joints says which joint drives which axis)")
    limits = _limits(ini_text)
    out: list[str] = []
    section = ""
    for line in ini_text.splitlines():
        if m := _SECTION.match(line):
            section = m.group(1).strip()
            out.append(line)
            heading = by_section.get(section)
            if heading is not None and heading.table is not None:
                out += _lines_for(heading, section, limits)
            continue
        joint = by_section.get(section)
        out += [line] if joint is None else _kept(line, joint)
    return "\n".join(out) + ("\n" if ini_text.endswith("\n") or out else "")


def _kept(line: str, joint: ControllerJoint) -> list[str]:
    """What stays of a line of the joint's section."""
    if line.startswith(_OWN):
        return []  # written afresh under the section's name
    key = _KEY.match(line)
    if key is None or key.group(1) not in ("COMP_FILE", "COMP_FILE_TYPE"):
        return [line]
    value = key.group(2).strip()
    ours = key.group(1) == "COMP_FILE" and value == comp_file_name(joint.axis)
    if joint.table is not None:
        same = ours or (key.group(1) == "COMP_FILE_TYPE" and value == str(COMP_FILE_TYPE))
        return [] if same else [f"# orthocal: was {line.strip()}"]
    if ours:  # its COMP_FILE_TYPE may stay: without a COMP_FILE LinuxCNC reads none
        return [f"{_OWN}{joint.axis}: the COMP_FILE an earlier export wrote is removed: "
                "this run has no table of it"]
    return [line]  # the machine's own file for a joint the run has no table of


def comp_files(tables: ControllerTables, joints: Sequence[int],
               header: Sequence[str]) -> dict[str, str]:
    """File name → text of every joint's compensation file (joints with a table)."""
    numbers = dict(zip(("x", "y", "z"), joints, strict=True))
    return {comp_file_name(j.axis): comp_file(j, numbers[j.axis], header)
            for j in tables.tabled}

