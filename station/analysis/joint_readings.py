"""From the readings of the station's own test of a joint to its table and its journal
record (docs/model.md, "The station's own joint test"; docs/design.md, "Joints"), and
back from the record to the table the run uses.

The inputs of its uncertainty as the config states them, else at defaults named as
assumed: the reference's calibration (``[joints.reference] u_mm``, always given),
the gauge's MPE (``[[indicators]] mpe_mm``, as the run's budget takes it), the
reference's temperature (``[joints.reference] temperature_c``: its lengths taken at
it, within ``[uncertainty] temperature_change_c`` over the test; absent: 20 °C,
within :data:`ASSUMED_TEMPERATURE_BOUND_K`), and the noise of the repeats.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from orthocal import JointTable
from orthocal.joint_test import REFERENCE_TEMPERATURE_C, reference_lengths, station_table
from station.analysis import run_budget
from station.config import StationConfig
from station.plan.joint_test_plan import JointTestPlan
from station.record.journal import JointTested
from station.record.result_joints import StationTestRecord

#: The reference's temperature where the config does not give it: a workshop within
#: 20 ± 5 °C. A steel reference 5 K off is 58 µm/m off: state the temperature.
ASSUMED_TEMPERATURE_BOUND_K = 5.0


@dataclass
class Approaches:
    """What a joint's test read: per (target, side) the mean of each approach's
    readings (the target the test's count of targets for the datum read again), and per
    target the joint as counted at each reading."""

    means: dict[tuple[int, str], list[float]] = field(default_factory=dict)
    positions: dict[int, list[float]] = field(default_factory=dict)

    def add(self, target: int, side: str, mean: float, position: float | None) -> None:
        self.means.setdefault((target, side), []).append(float(mean))
        if position is not None:
            self.positions.setdefault(target, []).append(float(position))


def _rows(got: Approaches, targets: int, repeats: int, side: str) -> np.ndarray:
    out = np.full((targets, repeats), np.nan)
    for k in range(targets):
        values = got.means.get((k, side), [])[:repeats]
        out[k, :len(values)] = values
    return out


def _inputs(config: StationConfig, gauge: str) -> tuple[float, float, float, list[str]]:
    """(the gauge's MPE, the reference's temperature and the bound on it over the test,
    what of these is assumed)."""
    ref = config.joints.reference
    assert ref is not None  # a station test has one
    given = run_budget.inputs(config)
    mpe = given.mpe_mm[gauge]
    assumed = [] if mpe.given else [f"mpe_mm of {gauge}: {mpe.value} ({mpe.assumed})"]
    if ref.temperature_c is None:
        temperature, bound = REFERENCE_TEMPERATURE_C, ASSUMED_TEMPERATURE_BOUND_K
        assumed.append(f"the reference at {REFERENCE_TEMPERATURE_C:g} ± {bound:g} °C (a "
                       "workshop; not stated: [joints.reference] temperature_c)")
    else:
        change = given.temperature_change_c
        temperature, bound = float(ref.temperature_c), _number(change.value)
        if not change.given:
            assumed.append(f"the reference's temperature within ±{bound:g} K over the "
                           f"test ({change.assumed})")
    return _number(mpe.value), temperature, bound, assumed


def _number(value: float | list[float]) -> float:
    """An input stated as one number (StatedInput.value)."""
    return float(value[0] if isinstance(value, list) else value)


def tested_record(config: StationConfig, jp: JointTestPlan, got: Approaches
                  ) -> dict[str, object]:
    """The journal's ``joint-test`` record of joint ``jp.axis``'s test from what it read
    (orthocal.joint_test.station_table); ValueError where the readings cannot make a
    table (a target read from neither side)."""
    ref = config.joints.reference
    assert ref is not None  # a station test has one
    n, r = len(jp.targets), jp.repeats
    mpe, temperature, bound, assumed = _inputs(config, jp.gauge)
    faces = reference_lengths(jp.faces, ref.expansion_per_k, temperature)
    positions = [float(np.mean(got.positions[k])) if got.positions.get(k) else jp.targets[k]
                 for k in range(n)]
    found = station_table(
        jp.targets, faces, jp.plunger, _rows(got, n, r, "forward"), _rows(got, n, r, "reverse"),
        got.means.get((n, "forward"), []), got.means.get((n, "reverse"), []),
        reference_u95_mm=[ref.u95_of(k) for k in range(n)], mpe_mm=mpe,
        alpha_per_k=ref.expansion_per_k, temperature_change_k=bound, positions_mm=positions)
    t = found.table
    order = np.argsort(jp.targets)
    test = StationTestRecord(
        reference=ref.kind, gauge=jp.gauge, plunger=ref.plunger,
        faces_mm=[float(jp.faces[k]) for k in order], repeats=r, readings=jp.readings,
        temperature_c=temperature, drift_um=1e3 * found.drift_mm, noise_um=1e3 * found.noise_mm,
        noise_dof=found.noise_dof,
        u_um={name: [1e3 * float(v) for v in u] for name, u in found.parts.items()},
        inferred=[f"ρ = {rho:.3f} mm {'from below' if side == 'forward' else 'from above'}: "
                  "the other side less the reversal at the nearest target approached from "
                  "both (the soft limits leave no room)" for rho, side in found.inferred],
        assumed=assumed)
    assert t.u95_mm is not None  # station_table gives one
    return {"type": "joint-test", "joint": jp.axis,
            "targets_mm": [float(v) for v in t.targets_mm],
            "forward_um": [1e3 * float(v) for v in t.forward_mm],
            "reverse_um": [1e3 * float(v) for v in t.reverse_mm],
            "u95_um": [1e3 * float(v) for v in t.u95_mm],
            "test": test.model_dump(mode="json")}


def table_of(record: JointTested) -> JointTable:
    """The table a ``joint-test`` record holds (mm), as found: relative to the datum."""
    return JointTable(np.asarray(record.targets_mm, dtype=float),
                      1e-3 * np.asarray(record.forward_um, dtype=float),
                      1e-3 * np.asarray(record.reverse_um, dtype=float),
                      1e-3 * np.asarray(record.u95_um, dtype=float))


def tables_of(records: Mapping[str, JointTested]) -> dict[str, JointTable]:
    """Each tested joint's table, by axis (station.analysis.joints.joint_knowledge's
    ``station``)."""
    return {axis: table_of(rec) for axis, rec in sorted(records.items())}


def details_of(records: Mapping[str, JointTested]) -> dict[str, StationTestRecord]:
    """How each tested joint's table was found, by axis (result.json's
    ``joints.<axis>.station_test``)."""
    return {axis: rec.test for axis, rec in sorted(records.items())}
