"""A run's final offsets as TwinCAT 3 NC axis parameters (docs/design.md, "Machine
history", export). Pure: from result.json to text.

TwinCAT has no file a person imports axis parameters from: the export is a parameter
list to type into TwinCAT XAE (or to feed a PLC that sets them), one row per NC axis
and parameter, comma-separated, its header saying which parameter each value is for
and what sign it carries. Where homing sets the axis position at the reference cam
to the encoder parameter "Reference position for homing" (MC_Home with Position :=
DEFAULT_HOME_POSITION), that parameter behaves as LinuxCNC's HOME_OFFSET, and takes
the same change (station.history.controller_terms.home_changes). An axis with an absolute
encoder, which is not homed, takes it in "Position Bias" instead (the axis position
is the scaled encoder count plus the bias): one or the other, never both. The
run does not know what the NC holds now, so the rows state the change to add to it."""

from __future__ import annotations

from collections.abc import Sequence

from orthocal import AXES
from station.history.controller_terms import (
    ExportError,
    home_changes,
    offset_changes,
    plays,
)
from station.record.exportable import header_lines
from station.record.result import RunResult

#: The NC axes of the joints x, y, z unless told otherwise.
DEFAULT_AXES = ("Axis 1", "Axis 2", "Axis 3")

REFERENCE = "Reference position for homing (encoder parameter)"
BACKLASH = "MC_BacklashCompensation.Backlash (Tc2_MC2; axis parameter Position Correction on)"


def _header(result: RunResult, machine: str, backlash: bool, forced: bool,
            words: Sequence[str]) -> list[str]:
    lines = [
        *header_lines(result, forced),
        *words,
        f"# orthocal export for TwinCAT 3 NC: machine {machine}, run {result.run_dir}",
        "# Each row: the NC axis, the joint it drives, the parameter (as TwinCAT XAE names",
        "# it) and what to do with it, in mm.",
        "# change_mm: add it to the value the axis holds now (new = now + change_mm). It is",
        "#   -(offsets_final - offsets_before): the station's offset o puts a carriage",
        "#   commanded to rho at rho + o, and homing sets the axis position at the cam to",
        "#   the reference position R, so the carriage sits at cam + rho - R: raising o by",
        "#   d lowers R by d. An axis with an absolute encoder (not homed) takes the same",
        "#   change in the encoder parameter Position Bias instead (axis position =",
        "#   scaled encoder count + bias): one or the other, never both.",
    ]
    if backlash:
        lines += ["# value_mm (backlash): the joint's reversal as the run states it (ISO 230-2),",
                  "#   a value, not a change; only where the run's statement decides to",
                  "#   compensate it (reversal_*: compensate or repair, the decision table)."]
    return lines


def twincat(result: RunResult, axes: Sequence[str] = DEFAULT_AXES,
            backlash: bool = False, forced: bool = False, words: Sequence[str] = (),
            tabled: Sequence[str] = ()) -> str:
    """The parameter list of the run ``result`` for the NC ``axes`` of x, y, z;
    ``backlash``: the backlash compensation too, where the reversal stands out, except
    for the joints ``tabled`` (axes), whose bilateral leadscrew error compensation
    list carries the reversal; ``forced``: exported with --force, its header says why
    it needed it; ``words``: header lines (what the export takes into account).
    Refused where the drive holds the offsets the run wrote (home_changes)."""
    if len(axes) != len(AXES) or not all(a.strip() for a in axes):
        raise ExportError(f"--axes: three NC axis names for x,y,z, got {','.join(axes)!r}")
    change = home_changes(result, "TwinCAT")
    offsets = offset_changes(result)
    reversal = plays(result) if backlash else {}
    machine = result.machine.id or "no [machine] id"
    out = _header(result, machine, backlash, forced, words)
    out.append("nc_axis,joint,parameter,change_mm,value_mm,offset_before_mm,"
               "offset_final_mm,machine_id")
    for axis, name in zip(AXES, axes, strict=True):
        before, final = offsets[axis]
        tail = f"{before:.6f},{final:.6f},{machine}"
        out.append(f"{name.strip()},{axis},{REFERENCE},{change[axis]:+.6f},,{tail}")
        if not backlash:
            continue
        if axis in tabled:
            out.append(f"# {name.strip()} ({axis}): no backlash: its bilateral leadscrew "
                       "error compensation list carries the reversal")
        elif axis not in reversal:
            out.append(f"# {name.strip()} ({axis}): no backlash: the run measured no reversal")
        elif reversal[axis].acts:
            out.append(f"# {name.strip()} ({axis}): backlash: {reversal[axis].why}")
            out.append(f"{name.strip()},{axis},{BACKLASH},,{reversal[axis].value:.6f},{tail}")
        else:
            out.append(f"# {name.strip()} ({axis}): backlash not written: "
                       f"{reversal[axis].why}")
    return "\n".join(out) + "\n"
