"""The identification with the joints' errors (docs/model.md, "The identification with
joint tables"): leg parallelism sees a joint's lead only at second order, (J4), but a
fit that models the stands (a stand's placement changes the deviations much as a lead
does) turns a micrometre of it into ten of Δρ. So where a joint has a table (the
shop's test or the station's own), what the tables make of the deviations is taken
out of every measured deviation before the fit and the model test; where a joint's
error is only bounded (assumed), the bound is a Type B input of the deviations and of
the model test's allowance (station.analysis.joints.lead_inputs,
station.analysis.run_budget).

Pure: a measurement and the tables in, the corrected measurement out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

import orthocal
from orthocal import PARAM_NAMES, JointErrors
from orthocal.joint_count import CountedJoints, count_words
from orthocal.joint_error import JointRangeError, joint_deviation_change
from station.analysis.joints import JointKnowledge
from station.analysis.statistics import Measurement
from station.config import StationConfig
from station.errors import RunFailed


def moved(start: Mapping[str, float] | None, held: Mapping[str, float] | None
          ) -> dict[str, float]:
    """How far the offsets ``held`` in a round lie from those the run started with
    (``start``), per axis, mm: where on its screw a joint commanded ρ now stands,
    beside where the test's ρ stood (0 where either is unknown)."""
    if start is None or held is None:
        return dict.fromkeys("xyz", 0.0)
    return {a: float(held[a]) - float(start[a]) for a in "xyz"}


@dataclass(frozen=True)
class Corrected:
    """A measurement with what the joints' tables make of its deviations taken out
    (``measurement``), and by how much each deviation was corrected (``change_mm``,
    by key; empty where no joint has a table)."""

    measurement: Measurement
    change_mm: dict[str, float] = field(default_factory=dict)
    #: what the drive's count alone made of each deviation (empty: no count)
    count_change_mm: dict[str, float] = field(default_factory=dict)
    count_mm: tuple[float, float, float] | None = None

    @property
    def largest_um(self) -> float:
        """The largest correction of a deviation, µm."""
        return 1000.0 * max((abs(v) for v in self.change_mm.values()), default=0.0)

    @property
    def largest_table_um(self) -> float:
        """The largest correction less what the count alone made of it, µm: the tables'."""
        return 1000.0 * max((abs(v - self.count_change_mm.get(k, 0.0))
                             for k, v in self.change_mm.items()), default=0.0)

    @property
    def largest_count_um(self) -> float:
        return 1000.0 * max((abs(v) for v in self.count_change_mm.values()), default=0.0)


def first_estimate(data, geometry: orthocal.Geometry) -> np.ndarray:
    """The machine the correction is taken at: Δρ of a first ``rho`` fit of the
    uncorrected deviations, the rest nominal (12-vector). The correction follows Δρ
    (the legs move under the gauges) by 0.03 µm over a millimetre and the layout by
    nanometres (docs/model.md's check values), so a fit's error of micrometres moves it
    by 1e-4 µm: one step, no iteration. Nominal where Δρ cannot be fitted."""
    try:
        ident = orthocal.identify(data, geometry, model="rho", method="nonlinear")
    except orthocal.IdentificationError:
        return np.zeros(len(PARAM_NAMES))
    return np.array([float(ident.parameters.get(n, 0.0)) if n.startswith("drho_") else 0.0
                     for n in PARAM_NAMES])


def corrected(config: StationConfig, m: Measurement, tables: JointErrors | None,
              count_mm: Sequence[float] | np.ndarray | None = None) -> Corrected:
    """``m`` with every cycle of each deviation less what ``tables`` (the round's: in
    the joints it commanded, station.analysis.joints.round_tables) and the drive's
    count ``count_mm`` (x, y, z, mm: each stop commanded at (J15)) make of it
    (orthocal.joint_deviation_change: the tables' bidirectional mean, exact, at
    :func:`first_estimate`); ``m`` itself where no joint has a table or a count."""
    counts = CountedJoints(three_counts(count_mm), tables)
    if (tables is None and not counts.any) or not m.deviations:
        return Corrected(m)
    geometry = config.machine.geometry()
    data = m.for_identify()
    at = first_estimate(data, geometry)
    try:
        change = joint_deviation_change(list(data), geometry, at, counts)
    except JointRangeError as exc:  # the plan checks each table's span: not expected
        raise RunFailed(f"joint tables: {exc}, where this round's postures stand on its "
                        "screw") from None
    by_key = {key: float(c) for key, c in zip(m.deviations, change, strict=True)}
    deviations = {key: [v - by_key[key] for v in values]
                  for key, values in m.deviations.items()}
    by_count: dict[str, float] = {}
    if counts.any:  # what the count alone makes of them, for the record's words
        alone = joint_deviation_change(list(data), geometry, at,
                                       CountedJoints(counts.count_mm))
        by_count = {key: float(c) for key, c in zip(m.deviations, alone, strict=True)}
    return Corrected(replace(m, deviations=deviations), by_key, by_count,
                     counts.count_mm if counts.any else None)


def three_counts(count_mm: Sequence[float] | np.ndarray | None
                 ) -> tuple[float, float, float]:
    """The drive's count per joint (x, y, z, mm) as a tuple; None: none (0)."""
    if count_mm is None:
        return (0.0, 0.0, 0.0)
    x, y, z = (float(v) for v in count_mm)
    return (x, y, z)


def words(knowledge: JointKnowledge, fit: Corrected) -> str:
    """What the identification made of the joints (``fit``: the round's correction),
    for result.json's ``joints``."""
    tabled = [j.axis for j in knowledge.joints if j.table is not None]
    rest = [j for j in knowledge.joints if j.table is None and j.bound_um_per_m]
    parts = []
    if tabled:
        parts.append(f"the deviations were corrected for what the tables of joint(s) "
                     f"{', '.join(tabled)} make of them (up to "
                     f"{fit.largest_table_um:.2f} µm) before the fit and the model test; "
                     "what a table's own uncertainty leaves of its lead is a Type B input "
                     "of the deviations")
    if rest:
        parts.append(f"joint(s) {', '.join(j.axis for j in rest)}: a lead within "
                     f"±{rest[0].bound_um_per_m:g} µm/m from Π0 (the bound) is a Type B "
                     "input of the deviations, (J4) through the fit's sensitivity, and of "
                     "the model test's allowance")
    if fit.count_mm is not None:
        parts.append(f"each stop stood at the drive's count ({count_words(fit.count_mm)}, "
                     f"J15): what that makes of the deviations (up to "
                     f"{fit.largest_count_um:.2f} µm) was taken out before the fit")
    return "; ".join(parts) or "every joint taken as exact"
