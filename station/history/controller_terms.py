"""A run's final offsets in a controller's own terms (docs/design.md, "Machine
history", export). Pure: from result.json (its record) (and a LinuxCNC INI's text) to text.

The station's convention (the register map's ``offset_convention``): a commanded ρ_i
puts the carriage at ρ_i + o_i. LinuxCNC's ``[JOINT_n] HOME_OFFSET`` is the joint
position it assigns to the home switch, so a carriage commanded to ρ sits at
switch + ρ − HOME_OFFSET: raising o by Δo is lowering HOME_OFFSET by Δo. The export
writes the new value beside the old from the machine's own INI, never the
correction alone, which a person would add with the sign left to guess."""

from __future__ import annotations

import configparser
import re
from collections.abc import Collection, Sequence
from dataclasses import dataclass

from orthocal import AXES
from station.record.exportable import HEADER, header_lines
from station.record.quantity_text import plus_minus
from station.record.result import RunResult


class ExportError(ValueError):
    """What the export cannot do, in one line naming the field or section."""


def offset_changes(result: RunResult) -> dict[str, tuple[float, float]]:
    """Per axis (offset before, offset the run left), mm."""
    before, final = result.offsets_before, result.offsets_final
    if before is None or final is None:
        raise ExportError("result.json: the run states no offsets_before/offsets_final "
                          "(it stopped before reading the controller)")
    out: dict[str, tuple[float, float]] = {}
    for a in AXES:
        b, f = before.get(a), final.get(a)
        if b is None or f is None:
            raise ExportError("result.json: offsets_before/offsets_final do not give a "
                              f"number for each of {', '.join(AXES)}")
        out[a] = (b, f)
    return out


def reversals(result: RunResult) -> dict[str, tuple[float, float | None]]:
    """Per axis the measured reversal and its standard error (mm), where measured (a
    record from before the statement: its legacy reading)."""
    rev = result.reversal
    if rev is None:
        return {}
    return {a: (value, rev.std_errors_mm.get(a)) for a in AXES
            if (value := rev.value_mm.get(a)) is not None}


#: The decision table's words on a reversal that act (station.statement.decisions):
#: a controller is told the play where the statement says to compensate or repair it.
PLAY_ACTS = ("compensate", "repair")


@dataclass(frozen=True)
class Play:
    """A joint's reversal as an export takes it: its value (mm), whether the controller
    is told it, and why, in words."""

    value: float
    acts: bool
    why: str


def plays(result: RunResult) -> dict[str, Play]:
    """Per axis the joint's reversal, where the run states one: the statement's
    ``reversal_*`` and its decision (the decision table's one rule: beyond k_act
    combined standard uncertainties); a record from before the statement, the legacy
    rule (positive and beyond two standard errors)."""
    stated = {q.name: q for q in result.statement or []}
    if any(n.startswith("reversal_") for n in stated):
        out = {}
        for a in AXES:
            q = stated.get(f"reversal_{a}")
            if q is None or q.value is None:
                continue
            acts = q.decision in PLAY_ACTS
            said = f"the run's statement: reversal_{a} {plus_minus(q)} (95 %), " + (
                f"the decision table: {q.decision}" if acts else
                f"not beyond its uncertainty (the decision table: {q.decision})")
            out[a] = Play(q.value, acts, said)
        return out
    return {a: Play(v, backlash_stands_out(v, se),
                    "the joint's reversal as measured (ISO 230-2)"
                    if backlash_stands_out(v, se) else not_beyond_noise(v, se))
            for a, (v, se) in reversals(result).items()}


def backlash_stands_out(value: float, se: float | None) -> bool:
    """A record from before the statement: a reversal a controller may be told to
    compensate, positive and beyond 2 standard errors (legacy)."""
    return se is not None and value > 2.0 * se


def not_beyond_noise(value: float, se: float | None) -> str:
    """Why a reversal is not written as backlash, in words (legacy)."""
    shown = f"{value:+.6f}" + ("" if se is None else f" ± {se:.6f}")
    return f"the reversal measured {shown} mm is not beyond its noise"


def _backlash_line(play: Play) -> str:
    """BACKLASH where the statement says to compensate the joint's play; otherwise
    why not, as a comment."""
    if play.acts:
        return f"BACKLASH = {play.value:.6f}    # {play.why}"
    return f"# BACKLASH not written: {play.why}"


def home_changes(result: RunResult, controller: str) -> dict[str, float]:
    """Per axis the change of a controller's home (reference) position that moves
    the carriage as the run's offsets did: −(offsets_final − offsets_before), mm.
    Where a controller sets the joint position at its home switch to H, a carriage
    commanded to ρ sits at switch + ρ − H, and the station's offset o puts it at
    ρ + o: raising o by Δo is lowering H by Δo. Refused where the drive itself holds
    the offsets the run wrote: ``controller`` would correct the machine twice."""
    changes = offset_changes(result)
    if result.offsets_held_by == "controller" and any(
            abs(final - before) > 0 for before, final in changes.values()):
        raise ExportError(f"the drive holds the offsets this run wrote (offsets_held_by = "
                          f"controller): writing them into {controller} as well would "
                          "correct the machine twice")
    return {a: before - final for a, (before, final) in changes.items()}  # no −0.0


def linuxcnc(result: RunResult, ini_text: str, joints: Sequence[int] = (0, 1, 2),
             source: str = "INI", backlash: bool = False, forced: bool = False,
             words: Sequence[str] = (), tabled: Collection[str] = ()) -> str:
    """The machine's INI ``ini_text`` with each ``[JOINT_n] HOME_OFFSET`` calibrated (the
    new value, the old in a comment above it) and everything else kept as it was,
    under the export's header (station.record.exportable; ``forced``: exported with
    --force, and why it needed it; an earlier export's header replaced) and the
    header lines ``words`` (what the export takes into account); ``backlash``:
    BACKLASH too, where the run's statement decides to compensate the joint's reversal
    (:func:`plays`), except for the
    joints ``tabled`` (axes), whose compensation file carries the reversal and makes
    LinuxCNC ignore BACKLASH. Refused where the drive itself holds the offsets the run
    wrote: the controller would correct the machine twice."""
    home = home_changes(result, "LinuxCNC")
    old = _home_offsets(ini_text, joints, source)
    changes = offset_changes(result)
    reversal = plays(result) if backlash else {}
    machine = result.machine.id or "no [machine] id"
    edits: dict[str, tuple[str, list[str]]] = {}
    for axis, joint in zip(AXES, joints, strict=True):
        before, final = changes[axis]
        value = old[joint] + home[axis]
        note = (f"# orthocal: HOME_OFFSET was {old[joint]:.6f}; o_{axis} {before:+.6f} -> "
                f"{final:+.6f} mm (run {result.run_dir}, machine {machine}; a commanded "
                "rho puts the carriage at rho + o, so HOME_OFFSET moves by -(o change))")
        extra = [_backlash_line(reversal[axis])] if axis in reversal else []
        if extra and axis in tabled:
            extra = ["# BACKLASH not written: the joint's COMP_FILE carries its reversal "
                     "(LinuxCNC ignores BACKLASH where a joint has a COMP_FILE)"]
        edits[f"JOINT_{joint}"] = (f"HOME_OFFSET = {value:.6f}", [note, *extra])
    out: list[str] = [*header_lines(result, forced), *words]
    section = ""
    for line in ini_text.splitlines():
        if line.startswith(HEADER):
            continue  # an earlier export's header: this one's stands above
        header = re.match(r"\s*\[([^\]]+)\]", line)
        if header:
            section = header.group(1).strip()
        key = re.match(r"\s*(HOME_OFFSET|BACKLASH)\s*=", line)
        if section in edits and key and key.group(1) == "HOME_OFFSET":
            value_line, notes = edits[section]
            out += [notes[0], value_line, *notes[1:]]
            continue
        if section in edits and key and key.group(1) == "BACKLASH" and len(edits[section][1]) > 1:
            out.append(f"# orthocal: replaced {line.strip()}")
            continue
        out.append(line)
    return "\n".join(out) + "\n"


def _home_offsets(ini_text: str, joints: Sequence[int], source: str) -> dict[int, float]:
    """Each joint's HOME_OFFSET in the INI, checked: a section or value missing is said."""
    ini = configparser.ConfigParser(strict=False, interpolation=None,
                                    inline_comment_prefixes=("#", ";"))
    # LinuxCNC's keys are upper case, kept as written. Assigning optionxform is the
    # configparser docs' own idiom; typeshed declares it a method only.
    ini.optionxform = str  # type: ignore[method-assign,assignment]
    try:
        ini.read_string(ini_text, source=source)
    except configparser.Error as exc:
        raise ExportError(f"{source}: not an INI file ({exc.message.splitlines()[0]})") \
            from None
    out: dict[int, float] = {}
    for axis, joint in zip(AXES, joints, strict=True):
        section = f"JOINT_{joint}"
        if not ini.has_option(section, "HOME_OFFSET"):
            raise ExportError(f"{source}: [{section}] has no HOME_OFFSET (joint of axis "
                              f"{axis}; --joints says which joint drives which axis)")
        raw = ini.get(section, "HOME_OFFSET")
        try:
            out[joint] = float(raw)
        except ValueError:
            raise ExportError(f"{source}: [{section}] HOME_OFFSET = {raw!r} is not a "
                              "number") from None
    return out


def csv_lines(result: RunResult, forced: bool = False, words: Sequence[str] = ()) -> str:
    """One row per axis: the offsets before and after, their change, the reversal;
    under the export's header as comment lines (``forced``, ``words``: as in
    :func:`linuxcnc`)."""
    changes = offset_changes(result)
    reversal = plays(result)
    machine = result.machine.id or ""
    rows = [*header_lines(result, forced), *words,
            "axis,offset_before_mm,offset_final_mm,change_mm,reversal_mm,machine_id,run_dir,"
            "convention"]
    for axis in AXES:
        before, final = changes[axis]
        rev = f"{reversal[axis].value:.6f}" if axis in reversal else ""
        rows.append(f"{axis},{before:.6f},{final:.6f},{final - before:+.6f},{rev},{machine},"
                    f"{result.run_dir},commanded rho puts the carriage at rho + o")
    return "\n".join(rows) + "\n"
