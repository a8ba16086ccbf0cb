"""The joints' positioning errors in the statement of the tool (docs/model.md, "The tool
with the joints' errors"): what each route leaves of them, as the tool's figures take
it (station.statement.tool_figures).

- A joint with a table (the shop's test or the station's own): the table is in the
  plug-in where the route leaves the joint's error at the tool (offsets only, the
  kinematics alone), at the joints commanded, its bidirectional mean (the middle of
  the band Δρ refers to; the reversal's bound at the tool is stated apart); where the
  route compensates it (the kinematics and the joint tables, a compensated program)
  the plug-in holds none. Either way the table's own uncertainty, ±U(ρ), is a
  bounded input of the truth (orthocal.joint_compensation.joint_error_columns).
- A joint without one: its bound, a lead within ±b µm/m from Π0, is a bounded input
  of the truth at every route (nothing compensates it).

The tables were tested with the offsets the run started from: a joint commanded ρ
with the offsets moved by o stands on its screw where the test's ρ + o stood
(station.analysis.joints.round_tables)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthocal import JointErrors
from orthocal.field_mc import frame_projection
from orthocal.joint_compensation import ROUTES, joint_error_columns
from station.analysis.joints import JointKnowledge, round_tables

#: Which of orthocal.joint_compensation.ROUTES the tool's figures take, by figure.
OFFSETS, KINEMATICS, KINEMATICS_TABLES = "offsets", "kinematics", "kinematics+tables"
#: The routes whose joints are compensated by their tables.
COMPENSATING = (KINEMATICS_TABLES, "program+tables", "offsets+tables")


@dataclass(frozen=True)
class JointsAtTool:
    """The run's joints (``knowledge``; None: every joint exact) and how far the offsets
    the run leaves moved from its start (``moved``, mm per axis)."""

    knowledge: JointKnowledge | None
    moved: dict[str, float]

    @property
    def tabled(self) -> list[str]:
        return [] if self.knowledge is None else \
            [j.axis for j in self.knowledge.joints if j.table is not None]

    @property
    def assumed(self) -> list[str]:
        """The joints without a table whose bound moves anything."""
        return [] if self.knowledge is None else \
            [j.axis for j in self.knowledge.joints
             if j.table is None and j.bound_um_per_m]

    def compensated_route(self) -> str:
        """The route the statement's ``tool.compensated`` takes: the kinematics and the
        joint tables where the run has a table (the export writes both), else the
        kinematics."""
        return KINEMATICS_TABLES if self.tabled else KINEMATICS

    def _moved(self, which: str) -> dict[str, float]:
        return self.moved if which == "now" else dict.fromkeys("xyz", 0.0)

    def plug_in(self, which: str, route: str) -> JointErrors | None:
        """The tables in the joints commanded ``which`` ("start", "now") where ``route``
        leaves the joints' errors at the tool; None where it compensates them or
        there are none."""
        if route in COMPENSATING:
            return None
        return round_tables(self.knowledge, self._moved(which))

    def columns(self, rho, which: str) -> tuple[np.ndarray, tuple[str, ...]]:
        """The truth's bounded joint errors (3n × m, each uniform in ±1) at the points'
        commanded joints ``rho`` (n, 3): each table's uncertainty, each assumed
        joint's lead, where the joint stands on its screw (ρ + o)."""
        if self.knowledge is None:
            return np.zeros((np.asarray(rho).size, 0)), ()
        o = np.array([self._moved(which)[a] for a in "xyz"])
        k = self.knowledge
        bounds = [j.bound_um_per_m if j.table is None else None for j in k.joints]
        return joint_error_columns(np.asarray(rho, dtype=float) + o, k.errors(), bounds,
                                   k.x.pi0_mm)

    def framed(self, rho, which: str, J: np.ndarray, points, frame: str
               ) -> dict[str, np.ndarray]:
        """The truth's joint field of each joint's input (by axis, 3n each): :meth:`columns`
        through the tool's sensitivity to its joints ``J`` (n, 3, 3), in ``frame``."""
        cols, names = self.columns(rho, which)
        if not cols.shape[1]:
            return {}
        n = len(np.asarray(points))
        raw = cols.T.reshape(-1, n, 3)
        tool = np.einsum("kij,mkj->mki", J, raw)
        framed = frame_projection(points, frame)(tool).reshape(cols.shape[1], -1)
        return {name.split()[1]: f for name, f in zip(names, framed, strict=True)}

    def basis(self, route: str) -> list[str]:
        """The joints' part of a tool figure's basis, in words."""
        if self.knowledge is None:
            return []
        out = []
        for j in self.knowledge.joints:
            if j.table is not None:
                where = j.file or "the station's own test"
                how = ("compensated by its table" if route in COMPENSATING
                       else "its table's error at the tool")
                out.append(f"joint {j.axis}: {how} ({j.source}: {where}), within the "
                           "table's own uncertainty (Type B)")
            elif j.bound_um_per_m:
                said = "stated" if self.knowledge.bound.given else "assumed"
                out.append(f"joint {j.axis}: not compensated, a lead within "
                           f"±{j.bound_um_per_m:g} µm/m from Π0 ({said}; Type B)")
        return out


def route_words(route: str) -> str:
    """What a route takes into account (orthocal.joint_compensation.ROUTES)."""
    return ROUTES[route]
