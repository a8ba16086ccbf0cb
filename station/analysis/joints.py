"""What the station knows of each joint's positioning error (docs/design.md, "Joints";
docs/model.md, "Joint positioning errors"), as one typed object,
:class:`JointKnowledge`: what the statement of the tool and the exports consume, and
what result.json's ``joints`` records.

Per joint, one of three sources:

- ``"test"``: a test the shop already has ([joints] tests, an ISO 230-2 table: a
  laser interferometer's or any), referred to Π0;
- ``"station"``: the station's own test against a length reference (its tables are
  given to :func:`joint_knowledge`; they win over a shop's test, being of the
  machine as it stands);
- ``"assumed"``: neither. The joint is taken to err by at most a bound per metre of
  travel from home, rectangular ([uncertainty] joint_positioning_um_per_m, or
  :data:`DEFAULT_JOINT_POSITIONING_UM_PER_M`, named as assumed wherever used).

Where the run measured a joint's lost motion B, B wins over a table's own reversal
(:meth:`JointKnowledge.with_reversal`). Pure: the tests' files are read by the
caller (station.config.joint_tests), except in :func:`of_run_config`, which reads
them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from orthocal import JointErrors, JointTable, iso230_table, lead_um_per_m
from orthocal.joint_compensation import held_ends, shifted
from station.config import StationConfig
from station.config.joint_tests import Joint, JointTest, read_joint_tests
from station.record.result_joints import (
    JointRecord,
    Joints,
    JointSource,
    JointTableRecord,
    StationTestRecord,
)
from station.record.result_sections import StatedInput

#: [uncertainty] joint_positioning_um_per_m where the config says nothing: a rolled ball
#: screw of ISO 3408-3 class C7 (±50 µm per 300 mm of travel, 167 µm/m), the ordinary
#: grade of small machines. Not C5 (±18 µm, 60 µm/m): a bound taken too small makes the
#: tool's interval claim what the joints may not hold; one too large only widens it.
DEFAULT_JOINT_POSITIONING_UM_PER_M = 170.0
ASSUMED_WHY = ("a rolled ball screw of ISO 3408-3 class C7, ±50 µm per 300 mm, the ordinary "
               "grade of small machines; not measured ([uncertainty] "
               "joint_positioning_um_per_m)")
JOINTS: tuple[Joint, Joint, Joint] = ("x", "y", "z")
#: The 95 % interval of a rectangular ±b is ±0.95·b (GUM).
RECTANGULAR_95 = 0.95
CONVENTION = ("ε = actual − target (ISO 230-2) at the joint coordinate ρ as the station "
              "commands it (absolute, Π0 at ρ = L), forward approached in +ρ, referred to "
              "Π0 (its bidirectional mean at ρ = L is 0: a constant is the zero error's); "
              "the true joint is ρ + o + Δρ + ε(ρ + o), linear between targets, never "
              "extrapolated; an assumed bound is |ε| ≤ b·|ρ − L|, rectangular")


@dataclass(frozen=True)
class KnownJoint:
    """One joint's positioning error as the station knows it.

    ``source``: "test", "station" or "assumed" (module docstring). ``table``: ε as an
    :class:`orthocal.JointTable` (mm, referred to Π0), its reversal ``reversal_from``
    the test's or the station's measured B; None where assumed. ``lead_um_per_m`` and
    ``lead_interval_95_um_per_m``: the table's lead (orthocal.lead_um_per_m, (J3)), or
    0 and ±0.95·bound where assumed. ``bound_um_per_m``: the assumed bound (None
    unless assumed). ``file``: the test's file (source "test"). ``pi0_mm``: the joint
    coordinate of Π0 (L), from which an assumed bound grows."""

    axis: str
    source: JointSource
    lead_um_per_m: float
    lead_interval_95_um_per_m: tuple[float, float]
    table: JointTable | None = None
    bound_um_per_m: float | None = None
    reversal_from: Literal["test", "station"] | None = None
    file: str | None = None
    pi0_mm: float = 0.0

    def bound_mm(self, rho) -> np.ndarray:
        """The assumed bound on |ε| at joint values ``rho`` (mm): b·1e-6·|ρ − L|.
        ValueError for a joint that has a table (its table says ε)."""
        if self.bound_um_per_m is None:
            raise ValueError(f"joint {self.axis} has a table ({self.source}), not a bound")
        return 1e-6 * self.bound_um_per_m * np.abs(np.asarray(rho, dtype=float) - self.pi0_mm)


@dataclass(frozen=True)
class JointKnowledge:
    """The three joints (:class:`KnownJoint` ``x``, ``y``, ``z``) and the bound the
    assumed ones rest on (``bound``: [uncertainty] joint_positioning_um_per_m, given
    or assumed, as the uncertainty budget states its inputs)."""

    x: KnownJoint
    y: KnownJoint
    z: KnownJoint
    bound: StatedInput

    def joint(self, axis: str) -> KnownJoint:
        return {"x": self.x, "y": self.y, "z": self.z}[axis]

    @property
    def joints(self) -> tuple[KnownJoint, KnownJoint, KnownJoint]:
        return self.x, self.y, self.z

    def sources(self) -> dict[str, JointSource]:
        """Each joint's source, by axis."""
        return {j.axis: j.source for j in self.joints}

    def errors(self) -> JointErrors:
        """The tables as orthocal's joint errors (an assumed joint: None, exact at its
        mean; its bound is :meth:`KnownJoint.bound_mm`'s)."""
        return JointErrors(*(j.table for j in self.joints))

    @property
    def assumed(self) -> list[str]:
        """What the joints were taken to be without a measurement, with why: the run
        JSON's ``joints.assumed`` (empty where every joint has a table)."""
        rest = [j.axis for j in self.joints if j.source == "assumed"]
        if not rest:
            return []
        said = "stated" if self.bound.given else f"assumed: {self.bound.assumed}"
        return [f"joint(s) {', '.join(rest)}: positioning within ±{self.bound.value:g} µm "
                f"per metre of travel from Π0, rectangular ({said})"]

    def with_reversal(self, reversal_mm: Mapping[str, float | None]) -> JointKnowledge:
        """The knowledge with each table's reversal replaced by the run's measured lost
        motion B where there is one (docs/model.md: the measured B wins); a negative
        B (noise about none) is none."""
        joints = []
        for j in self.joints:
            b = reversal_mm.get(j.axis)
            if j.table is None or b is None or not math.isfinite(b):
                joints.append(j)
                continue
            joints.append(replace(j, table=j.table.with_reversal(max(float(b), 0.0)),
                                  reversal_from="station"))
        return replace(self, x=joints[0], y=joints[1], z=joints[2])


#: A joint's lead as a bounded input of the deviations and the model test (docs/model.md,
#: "The identification with joint tables"): axis → (bound µm/m, the budget's name of it).
LeadInputs = dict[str, tuple[float, str]]


def lead_inputs(knowledge: JointKnowledge | None) -> LeadInputs:
    """Each joint's lead the identification cannot see, as a bounded input: an assumed
    joint's bound; a tabled joint's lead as its points' uncertainty leaves it (J3's
    U_p: the deviations were corrected by the table, what is left of it is its own
    error); none for a table without a stated uncertainty. Empty without knowledge."""
    out: LeadInputs = {}
    for j in () if knowledge is None else knowledge.joints:
        if j.table is None and j.bound_um_per_m:
            said = "stated" if knowledge is not None and knowledge.bound.given else "assumed"
            out[j.axis] = (float(j.bound_um_per_m),
                           f"joint {j.axis} positioning ({said} ±{j.bound_um_per_m:g} µm/m)")
        elif j.table is not None and (u := lead_um_per_m(j.table).points_um_per_m) > 0:
            out[j.axis] = (u, f"joint {j.axis} table ({j.source}, lead ±{u:.1f} µm/m)")
    return out


def round_tables(knowledge: JointKnowledge | None, moved: Mapping[str, float]
                 ) -> JointErrors | None:
    """The tables in the joints a round commands: each table's targets moved by −o,
    o the offsets' change since the joint was tested (the run's start; ``moved``, mm
    per axis): a joint commanded ρ stands on its screw where the test's ρ + o stood
    (orthocal.joint_compensation.shifted), held at its ends for as far as the
    offsets moved (orthocal.joint_compensation.held_ends). None where no joint has a table."""
    if knowledge is None or not any(j.table is not None for j in knowledge.joints):
        return None
    return JointErrors(*(None if j.table is None else
                         shifted(held_ends(j.table, abs(float(moved.get(j.axis, 0.0)))),
                                 -float(moved.get(j.axis, 0.0)))
                         for j in knowledge.joints))


def positioning_input(config: StationConfig) -> StatedInput:
    """[uncertainty] joint_positioning_um_per_m as given, else the default, named as
    assumed with why (station.analysis.run_budget's pattern for Type B inputs)."""
    given = config.uncertainty.joint_positioning_um_per_m
    if given is not None:
        return StatedInput(value=float(given), given=True)
    return StatedInput(value=DEFAULT_JOINT_POSITIONING_UM_PER_M, given=False,
                       assumed=ASSUMED_WHY)


def _tabled(axis: str, source: JointSource, table: JointTable, file: str | None,
            pi0_mm: float) -> KnownJoint:
    lead = lead_um_per_m(table)
    return KnownJoint(axis, source, lead.value_um_per_m, lead.interval_95_um_per_m,
                      table=table, reversal_from="test", file=file, pi0_mm=pi0_mm)


def joint_knowledge(config: StationConfig, tests: Mapping[Joint, JointTest] | None = None,
                    station: Mapping[str, JointTable] | None = None) -> JointKnowledge:
    """What ``config`` and the tests say of each joint (pure): the station's own
    tables first (``station``, joint → table, referred to Π0 here), then the shop's
    ``tests`` (joint → parsed test file), else the bound. The tables are referred to
    Π0 (ρ = L of [machine])."""
    bound = positioning_input(config)
    b = float(bound.value) if not isinstance(bound.value, list) else float(bound.value[0])
    L = config.machine.leg_length
    joints = []
    for axis in JOINTS:
        own = (station or {}).get(axis)
        test = (tests or {}).get(axis)
        if own is not None:
            joints.append(_tabled(axis, "station", own.referred_to_pi0(L), None, L))
        elif test is not None:
            table = iso230_table(test.targets_mm, test.forward_um, test.reverse_um,
                                 test.u_um, pi0_mm=L)
            joints.append(_tabled(axis, "test", table, test.source, L))
        else:
            half = RECTANGULAR_95 * b
            joints.append(KnownJoint(axis, "assumed", 0.0, (-half, half), bound_um_per_m=b,
                                     pi0_mm=L))
    return JointKnowledge(joints[0], joints[1], joints[2], bound)


def of_run_config(config: StationConfig, station: Mapping[str, JointTable] | None = None
                  ) -> JointKnowledge:
    """:func:`joint_knowledge` of ``config`` with its [joints] tests read from their
    files (BadInput naming a file and line), and the station's own tables where its
    test found them (``station``, station.analysis.joint_readings.tables_of)."""
    return joint_knowledge(config, read_joint_tests(config.joints.tests), station)


def _table_record(j: KnownJoint) -> JointTableRecord | None:
    t = j.table
    if t is None:
        return None
    return JointTableRecord(
        targets_mm=[float(v) for v in t.targets_mm],
        forward_um=[1e3 * float(v) for v in t.forward_mm],
        reverse_um=[1e3 * float(v) for v in t.reverse_mm],
        u95_um=None if t.u95_mm is None else [1e3 * float(v) for v in t.u95_mm],
        shift_um=1e3 * t.shift_mm, reversal_from=j.reversal_from or "test")


def fields(knowledge: JointKnowledge,
           station: Mapping[str, StationTestRecord] | None = None,
           in_identification: str | None = None) -> Joints:
    """result.json's ``joints`` of ``knowledge``; ``station``: how the station's own test
    found the tables of source "station" (station.analysis.joint_readings.details_of);
    ``in_identification``: what the identification made of them
    (station.analysis.joint_fit.words)."""
    def record(j: KnownJoint) -> JointRecord:
        out = JointRecord(source=j.source, file=j.file, lead_um_per_m=j.lead_um_per_m,
                          lead_interval_95_um_per_m=j.lead_interval_95_um_per_m,
                          bound_um_per_m=j.bound_um_per_m, table=_table_record(j))
        if j.source == "station" and station and j.axis in station:
            out.station_test = station[j.axis]
        return out

    return Joints(x=record(knowledge.x), y=record(knowledge.y), z=record(knowledge.z),
                  bound=knowledge.bound, assumed=knowledge.assumed,
                  in_identification=in_identification, convention=CONVENTION)
