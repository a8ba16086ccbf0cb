"""Each joint's positioning error as a controller takes it (docs/design.md, "Joint
tables in the controller"): the tables of result.json's ``joints`` in the joints the
controller commands once the run's offsets are in, and the words that say what a
route out of the station takes into account (orthocal.joint_compensation.ROUTES).

A table's targets are the joint coordinate ρ as the station commanded it when the
joint was tested, with the offsets the run started from (``offsets_before``). The
controller, given the run's offsets (the drive holding ``offsets_final``, or
HOME_OFFSET moved by the export), puts a joint commanded to ρ where the station's
ρ + (o_final − o_before) stood then: on the same spot of its screw. So the table the
controller takes is the test's with its targets moved by −(o_final − o_before)
(orthocal.joint_compensation.shifted); its deviations are the same.

A joint whose error is assumed (no table) is not compensated: the route's words say
so, with the bound it rests on.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass

import numpy as np

from orthocal import AXES, JointErrors, JointTable
from orthocal.joint_compensation import ROUTES, held_ends, shifted
from station.record.exportable import HEADER, WIDTH
from station.record.result import RunResult


class NoJointFrame(ValueError):
    """A run whose record cannot place its tables in the controller's joints."""


@dataclass(frozen=True)
class ControllerJoint:
    """One joint as the controller takes it: ``table`` in the joints it commands (None:
    no table, not compensated), the ``source`` of result.json's joints, the test's
    ``file``, ``shift_mm`` (−(o_final − o_before), what the targets moved by), whose
    reversal the table holds, and the bound an assumed joint rests on (µm/m)."""

    axis: str
    source: str
    table: JointTable | None
    shift_mm: float
    file: str | None
    reversal_from: str | None
    bound_um_per_m: float | None

    def describe(self) -> str:
        """The joint in a few words: where its table comes from, or its bound."""
        if self.table is not None:
            where = self.file or "the station's own test"
            return f"{self.axis} ({self.source}: {where})"
        bound = "" if self.bound_um_per_m is None else \
            f", within ±{self.bound_um_per_m:g} µm per metre from Π0"
        return f"{self.axis} ({self.source}{bound})"


@dataclass(frozen=True)
class ControllerTables:
    """The three joints (x, y, z) as the controller takes them."""

    joints: tuple[ControllerJoint, ControllerJoint, ControllerJoint]

    def joint(self, axis: str) -> ControllerJoint:
        return self.joints[AXES.index(axis)]

    @property
    def tabled(self) -> list[ControllerJoint]:
        """The joints that have a table, in order x, y, z."""
        return [j for j in self.joints if j.table is not None]

    def errors(self) -> JointErrors:
        """The tables as orthocal's joint errors (a joint without one: exact), each held
        at its end values for as far as the offsets moved (orthocal.joint_compensation.
        held_ends): a test that spans just the travel the run needed from its start (the
        station's own) still covers the joints the controller commands, as the
        identification and the statement took it. The exports write the tables as
        tested (:attr:`ControllerJoint.table`)."""
        return JointErrors(*(None if j.table is None else held_ends(j.table, abs(j.shift_mm))
                             for j in self.joints))

    def route(self, base: str) -> str:
        """The key of ROUTES for a route ``base`` (offsets, kinematics, program) with
        these tables: ``base+tables`` where a joint has one."""
        key = f"{base}+tables" if self.tabled else base
        if key not in ROUTES:
            raise ValueError(f"no route {key!r}")
        return key

    def words(self, base: str) -> list[str]:
        """What a route ``base`` with these tables takes into account, and which joints'
        errors stay at the tool: the lines (without a comment mark) every export's
        header and the compensated program's header carry."""
        lines = [f"takes into account: {ROUTES[self.route(base)]}"]
        tabled, rest = self.tabled, [j for j in self.joints if j.table is None]
        if tabled:
            lines.append("joint tables: " + "; ".join(j.describe() for j in tabled))
        if rest:
            lines.append("no table, not compensated: " + "; ".join(j.describe()
                                                                   for j in rest))
        return lines


def header_words(tables: ControllerTables, base: str) -> list[str]:
    """:meth:`ControllerTables.words` as export header lines (each beginning with the
    export header's mark, so that an export onto the same file replaces them)."""
    return [HEADER + line for paragraph in tables.words(base)
            for line in textwrap.wrap(paragraph, WIDTH, subsequent_indent="  ",
                                      break_long_words=False, break_on_hyphens=False)]


def _frame_shift(result: RunResult) -> dict[str, float]:
    """−(o_final − o_before) per axis, mm."""
    before, final = result.offsets_before, result.offsets_final
    if before is None or final is None or any(
            before.get(a) is None or final.get(a) is None for a in AXES):
        raise NoJointFrame("result.json: the run states no offsets_before/offsets_final for "
                           "each joint, so its joint tables cannot be placed in the "
                           "controller's joints")
    return {a: -(float(final[a] or 0.0) - float(before[a] or 0.0)) for a in AXES}


def controller_tables(result: RunResult) -> ControllerTables:
    """The joints of ``result`` as the controller takes them: each table of
    ``joints`` (referred to Π0, with the reversal the run used) with its targets moved
    into the joints commanded after the run; a run without a ``joints`` section (from
    before it) has no tables. NoJointFrame where a table cannot be placed."""
    record = result.joints
    if record is None:
        none = [ControllerJoint(a, "assumed", None, 0.0, None, None, None) for a in AXES]
        return ControllerTables((none[0], none[1], none[2]))
    shift = _frame_shift(result) if any(getattr(record, a).table is not None
                                        for a in AXES) else dict.fromkeys(AXES, 0.0)
    joints = []
    for axis in AXES:
        j = getattr(record, axis)
        table = None
        if j.table is not None:
            t = j.table
            u95 = None if t.u95_um is None else 1e-3 * np.asarray(t.u95_um, dtype=float)
            table = shifted(JointTable(np.asarray(t.targets_mm, dtype=float),
                                       1e-3 * np.asarray(t.forward_um, dtype=float),
                                       1e-3 * np.asarray(t.reverse_um, dtype=float), u95),
                            shift[axis])
        joints.append(ControllerJoint(axis, j.source, table, shift[axis], j.file,
                                      None if j.table is None else j.table.reversal_from,
                                      j.bound_um_per_m))
    return ControllerTables((joints[0], joints[1], joints[2]))
