"""The identification with the joints' errors (station.analysis.joint_fit,
station.analysis.joints.lead_inputs / round_tables; docs/model.md, "The identification
with joint tables"), and the joints' leads in the statement
(station.statement.quantities.lead_quantities): check values on the paper's twelve
deviations, both sides of each rule."""

from __future__ import annotations

import numpy as np
import pytest
from builders import PAPER_KEYS as PAPER
from builders import station_data

import orthocal
from orthocal.budget_columns import joint_lead_columns
from orthocal.joint_error import JointErrors, joint_error_deviations
from station.analysis import joint_fit, joints
from station.analysis.statistics import Measurement
from station.config import parse_config
from station.config.joint_tests import parse_joint_test
from station.statement.quantities import lead_quantities

G = orthocal.Geometry()
L = G.leg_length
DRHO = np.array([0.6, -0.4, 0.9])
THETA = np.concatenate([DRHO, np.zeros(9)])
LEADS = (100.0, -80.0, 60.0)


def laser(k_um_per_m: float, u: bool = True) -> str:
    """A test of a lead k, 3 µm off at Π0 and a 4 µm reversal, 10 mm targets, 0.5 µm."""
    rows = ["target_mm,forward_um,reverse_um" + (",u_um" if u else "")]
    for t in range(170, 390, 10):
        e = 3.0 + k_um_per_m * 1e-3 * (t - L)
        rows.append(f"{t},{e - 2.0:.4f},{e + 2.0:.4f}" + (",0.5" if u else ""))
    return "\n".join(rows)


def config(**uncertainty: float):
    return parse_config(station_data(uncertainty=uncertainty))


def measured(errors: JointErrors) -> Measurement:
    """The paper's deviations of the machine THETA with joints ``errors``, two cycles."""
    values = joint_error_deviations(PAPER, G, THETA, errors)
    return Measurement(phase="m", deviations={"".join(k): [float(v)] * 2
                                              for k, v in zip(PAPER, values, strict=True)},
                       setups=[], within_std=[])


def rho_fit(m: Measurement) -> orthocal.Identification:
    data = {k: float(np.mean(v)) for k, v in m.for_identify().items()}
    return orthocal.identify(data, G, "rho")


def test_the_tables_taken_out_leave_the_deviations_of_exact_joints() -> None:
    screws = JointErrors.screws(G, (150.0, 400.0), LEADS)
    m = measured(screws)
    fit = joint_fit.corrected(config(), m, screws)
    # the change is model.md's check value (J4's exact model), to 1e-4 µm at θ̂₀
    assert 1e3 * fit.change_mm["+yx"] == pytest.approx(-1.067, abs=6e-4)
    assert fit.largest_um == pytest.approx(1.154, abs=6e-4)
    corrected = rho_fit(fit.measurement)
    bias = [1e3 * (corrected.parameters[f"drho_{a}"] - d) for a, d in zip("xyz", DRHO, strict=True)]
    assert np.max(np.abs(bias)) < 1e-3
    assert corrected.residual_rms * 1e3 < 1e-3
    # the control: uncorrected, the leads bias Δρ by about a micrometre (model.md)
    blind = rho_fit(m)
    assert 1e3 * (blind.parameters["drho_y"] - DRHO[1]) == pytest.approx(-1.222, abs=0.002)
    # no tables: the measurement as it is
    assert joint_fit.corrected(config(), m, None).measurement is m


def test_a_round_sees_its_tables_where_the_offsets_moved_it_and_held_at_the_ends() -> None:
    know = joints.joint_knowledge(config(), {"x": parse_joint_test(laser(100.0), "x.csv")})
    assert joints.round_tables(joints.joint_knowledge(config()), {"x": 1.0}) is None
    moved = joints.round_tables(know, {"x": 0.5, "y": 0.0, "z": 0.0})
    assert moved is not None and moved.y is None and moved.z is None
    table, start = moved.x, know.x.table
    assert table is not None and start is not None
    # a joint commanded ρ stands where the test's ρ + 0.5 stood
    for rho in (200.0, L, 350.0):
        assert table.error(np.array([rho]), "mean")[0] == \
            pytest.approx(start.error(np.array([rho + 0.5]), "mean")[0], abs=1e-12)
    # ... held at the test's end value for as far as the offsets moved, never beyond
    a, z = start.span
    assert table.span == pytest.approx((a - 0.5 - 0.5, z - 0.5 + 0.5))
    assert table.error(np.array([a - 1.0]), "mean")[0] == \
        pytest.approx(start.error(np.array([a]), "mean")[0], abs=1e-12)
    assert joint_fit.moved(None, {"x": 1.0, "y": 0, "z": 0}) == dict.fromkeys("xyz", 0.0)
    assert joint_fit.moved({"x": 1.0, "y": 2.0, "z": 0.0},
                           {"x": 1.5, "y": 1.0, "z": 0.0}) == {"x": 0.5, "y": -1.0, "z": 0.0}


def test_the_leads_the_fit_cannot_see_are_bounded_inputs_named_by_source() -> None:
    assert joints.lead_inputs(None) == {}
    assumed = joints.lead_inputs(joints.joint_knowledge(config()))
    assert {a: b for a, (b, _) in assumed.items()} == dict.fromkeys("xyz", 170.0)
    assert "assumed ±170 µm/m" in assumed["x"][1]
    stated = joints.lead_inputs(joints.joint_knowledge(
        config(joint_positioning_um_per_m=120.0)))
    assert "stated ±120 µm/m" in stated["y"][1]
    exact = joints.lead_inputs(joints.joint_knowledge(config(joint_positioning_um_per_m=0.0)))
    assert exact == {}
    tests = {"x": parse_joint_test(laser(100.0), "x.csv"),
             "y": parse_joint_test(laser(-80.0, u=False), "y.csv")}
    tabled = joints.lead_inputs(joints.joint_knowledge(config(), tests))
    # x: what its 0.5 µm points leave of its lead, (J3)'s U_p (22 targets: ~7 µm/m);
    # y: a table without an uncertainty leaves none; z: the assumed bound
    assert 5.0 < tabled["x"][0] < 9.0 and "table" in tabled["x"][1]
    assert "y" not in tabled and tabled["z"][0] == 170.0


def test_an_assumed_lead_moves_each_offset_by_its_sensitivity_check_values() -> None:
    fit = orthocal.identify(dict(zip(PAPER, orthocal.deviations(PAPER, G, None),
                                     strict=True)), G, "rho")
    prop = orthocal.budget.propagation(fit, G)
    u = joint_lead_columns(prop, dict.fromkeys("xyz", 120.0))
    assert u.labels == ("joint lead:x", "joint lead:y", "joint lead:z")
    own, other = 0.903e-3, -0.410e-3
    want = np.full((3, 3), other) + np.eye(3) * (own - other)
    np.testing.assert_allclose(u.columns, want, atol=1e-6)
    assert joint_lead_columns(prop, {"x": 0.0}).columns.shape == (3, 0)
    with pytest.raises(ValueError, match="joint_lead_um_per_m"):
        orthocal.Allowance(joint_lead_um_per_m={"x": -1.0})


def test_a_tabled_lead_is_decided_and_an_assumed_one_is_not() -> None:
    tests = {"x": parse_joint_test(laser(100.0), "x.csv"),
             "y": parse_joint_test(laser(2.0), "y.csv")}
    q = {r.name: r for r in lead_quantities(joints.joint_knowledge(config(), tests))}
    x, y, z = q["lead_x"], q["lead_y"], q.get("lead_z")
    assert x.unit == "µm/m" and x.value == pytest.approx(100.0, abs=1e-6)
    assert x.decision == "compensate" and x.interval_95[0] < 100.0 < x.interval_95[1]
    assert y.decision == "none"  # 2 µm/m within its own table's uncertainty
    assert z is None  # no table: its bound is an input, no lead is known
    assert lead_quantities(None) == []
