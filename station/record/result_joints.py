"""result.json's ``joints``: each joint's positioning error as the run took it (docs/
design.md, "Joints"; docs/model.md, "Joint positioning errors"), built by
station.analysis.joints from what the shop stated and the run measured."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from station.record.result_base import Closed, Interval
from station.record.result_sections import StatedInput

JointSource = Literal["test", "station", "assumed"]


class JointTableRecord(Closed):
    """The table of one joint's error ε as the station uses it: referred to Π0 (its
    bidirectional mean at ρ = L is 0), actual − target (ISO 230-2)."""

    targets_mm: list[float] = Field(description="the joint coordinate ρ as the station "
                                                "commands it (absolute, Π0 at ρ = L)")
    forward_um: list[float] = Field(description="ε approached in +ρ")
    reverse_um: list[float] = Field(description="ε approached in −ρ")
    u95_um: list[float] | None = Field(description="the expanded uncertainty (95 %) per "
                                                   "target (null: not given)")
    shift_um: float = Field(description="the constant taken out to refer the table to Π0 "
                                        "(the zero error Δρ takes it): the table as given "
                                        "is this one plus shift_um")
    reversal_from: Literal["test", "station"] = Field(
        description='whose reversal forward − reverse holds: the test\'s, or "station": '
                    "the run's measured lost motion B (forward = mean − B/2, reverse = "
                    "mean + B/2), which wins where both exist")


class StationTestRecord(Closed):
    """How the station's own test found a joint's table (source "station"; docs/model.md,
    "The station's own joint test"): the reference and the gauge, the test's shape, the
    datum's drift, the repeatability and each target's standard uncertainties by
    source, in the table's order."""

    reference: str = Field(description='the reference\'s kind: "gauge blocks", "step gauge" '
                                       'or "length bar"')
    gauge: str = Field(description="the indicator on the carriage")
    plunger: Literal["-", "+"] = Field(description='"-": pointing toward lower ρ')
    faces_mm: list[float] = Field(description="the face set at each target, its distance "
                                              "from the datum face (as calibrated, at 20 °C)")
    repeats: int = Field(description="approaches of each target from each side")
    readings: int = Field(description="readings per approach")
    temperature_c: float = Field(description="the reference's temperature its lengths were "
                                             "taken at (given, or assumed 20)")
    drift_um: float = Field(description="the datum's reading at the end less at the start, "
                                        "taken out linearly in the targets' order")
    noise_um: float = Field(description="one approach's repeatability (standard deviation)")
    noise_dof: int
    u_um: dict[str, list[float]] = Field(
        description="per target, the standard uncertainty of each source: reference, "
                    "gauge, temperature, noise (u95_um is twice their quadrature)")
    inferred: list[str] = Field(description="the sides not approached (the soft limits "
                                            "leave no room), taken from a neighbour's reversal")
    assumed: list[str] = Field(description="what the uncertainty rests on without being "
                                           "stated, with why")


class JointRecord(Closed):
    """One joint: where its error comes from, its lead and the table used."""

    source: JointSource = Field(description='"test": the shop\'s ISO 230-2 test ([joints] '
                                            'tests); "station": the station\'s own test '
                                            'against a length reference; "assumed": neither, '
                                            "a bound")
    file: str | None = Field(description="the test's file (source test)")
    lead_um_per_m: float = Field(description="the least-squares slope of the table's "
                                             "bidirectional mean; 0 where assumed")
    lead_interval_95_um_per_m: Interval = Field(
        description="its 95 % interval (assumed: ±0.95 × the bound, rectangular)")
    bound_um_per_m: float | None = Field(description="the assumed bound per metre of "
                                                     "travel from home (source assumed)")
    table: JointTableRecord | None = Field(description="the table used (null where assumed)")
    station_test: StationTestRecord | None = Field(
        None, description="how the station's own test found it (source station)")


class Joints(Closed):
    """joints: each joint's positioning error as the run took it, per joint x, y, z."""

    x: JointRecord
    y: JointRecord
    z: JointRecord
    bound: StatedInput = Field(description="[uncertainty] joint_positioning_um_per_m (µm/m), "
                                           "given or assumed")
    assumed: list[str] = Field(description="what the joints were taken to be without a "
                                           "measurement of them, with why")
    in_identification: str | None = Field(
        None, description="what the identification made of the joints: the deviations "
                          "corrected for the tables, the bounds as Type B inputs "
                          "(docs/model.md, \"The identification with joint tables\")")
    convention: str
