"""The drive's count (orthocal.joint_count; docs/model.md, "The drive's count"): the
rounding rule, the check values of (J15) on the paper's machine, and the exact change of
the deviations beside its first order (J16)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from builders import PAPER_KEYS as PAPER

import orthocal
from drivers.registers import Register, to_counts
from orthocal.joint_compensation import count_at_tool
from orthocal.joint_count import CountedJoints, counted
from orthocal.joint_error import JointErrors, joint_deviation_change

G = orthocal.Geometry()
L = G.leg_length
IAI = (0.01, 0.01, 0.01)


def test_a_value_is_rounded_half_away_from_zero_to_the_count() -> None:
    got = counted([[0.005, -0.005, 0.0149], [1.0005, -2.0, 0.0]], (0.01, 0.01, 0.001))
    np.testing.assert_allclose(got, [[0.01, -0.01, 0.015], [1.0, -2.0, 0.0]], atol=1e-12)
    # binary noise: 1.0005 / 0.001 = 1000.4999999999999 still rounds as the decimal does
    np.testing.assert_allclose(counted([1.0005, -1.0005, 0.0], (0.001,) * 3),
                               [1.001, -1.001, 0.0], atol=1e-12)
    # a count of 0 is a joint taken as continuous
    np.testing.assert_array_equal(counted([1.23456, 2.0, 3.0], (0.0, 0.0, 0.0)),
                                  [1.23456, 2.0, 3.0])
    with pytest.raises(ValueError, match="count_mm"):
        counted([1.0, 2.0, 3.0], (0.01, -0.01, 0.01))
    with pytest.raises(ValueError, match="count_mm"):
        counted([1.0, 2.0, 3.0], (0.01, math.nan, 0.01))


@pytest.mark.parametrize("scale", [100.0, 1000.0])
def test_the_drive_rounds_its_targets_by_the_models_rule(scale: float) -> None:
    # the drivers' rule and the model's, written twice (drivers use the mathematics only
    # in the simulator): a TARGET register holds what (J15) says the joint stands at
    reg = Register(name="TARGET_X", address=0, type="i32", scale=scale, unit="mm")
    c = (1.0 / scale,) * 3
    rng = np.random.default_rng(7)
    values = [304.39294095, 293.69212196, -0.005, 0.015, 1.0005, -1.0005, 0.0105,
              *rng.uniform(-400.0, 400.0, 200), *(np.arange(-50, 50) * 0.5 / scale)]
    for v in values:
        assert reg.decode(reg.encode(float(v))) == pytest.approx(
            counted([v, 0.0, 0.0], c)[0], abs=1e-12), v
    assert to_counts(1.0005, 1000.0) == 1001


def test_the_papers_postures_at_an_iai_count() -> None:
    # model.md's check values: Π_x^± with the two other joints at L·cos α
    plus, minus = orthocal.posture("+", "x", G), orthocal.posture("-", "x", G)
    np.testing.assert_allclose(1e3 * (counted(plus, IAI) - plus), [0.0, -2.941, -2.941],
                               atol=5e-4)
    np.testing.assert_allclose(1e3 * (counted(minus, IAI) - minus), [0.0, -2.122, -2.122],
                               atol=5e-4)
    # Π0 = (L, L, L) is whole counts: 310.25
    np.testing.assert_array_equal(counted(orthocal.posture("0", None, G), IAI), [L, L, L])


@pytest.mark.parametrize("count", [0.01, 0.001])
def test_the_exact_change_of_the_deviations_is_its_first_order(count: float) -> None:
    # (J16): at Π_i^s the two other joints stand δ_s off, P moves δ_s along each, and
    # leg i's gauge along j sees μ_s·δ_s, μ_s = 1/2 + sin α_s; Π0 is whole counts
    exact = joint_deviation_change(PAPER, G, np.zeros(12), CountedJoints((count,) * 3))
    first = []
    for sign, leg, along in PAPER:
        p = orthocal.posture(sign, leg, G)
        delta = counted(p, (count,) * 3) - p
        s = 60.0 if sign == "+" else -100.0
        first.append((0.5 + s / L) * delta["xyz".index(along)])
    np.testing.assert_allclose(exact, first, atol=2e-7)  # 2e-4 µm: second order
    # model.md's check values, µm, at the Π^+ and the Π^− stops of every leg
    plus, minus = {0.01: (-2.0392, -0.3770), 0.001: (0.0409, -0.0217)}[count]
    signs = np.array([k[0] for k in PAPER])
    np.testing.assert_allclose(1e3 * exact[signs == "+"], plus, atol=1e-4)
    np.testing.assert_allclose(1e3 * exact[signs == "-"], minus, atol=1e-4)


def test_counted_joints_stand_on_their_tables_where_they_were_commanded() -> None:
    screws = JointErrors.screws(G, (150.0, 400.0), (100.0, -80.0, 60.0))
    rho = orthocal.posture("+", "y", G)
    both = CountedJoints(IAI, screws)
    np.testing.assert_allclose(both.joints(rho), screws.joints(counted(rho, IAI)), atol=1e-15)
    assert both.any and not CountedJoints((0.0, 0.0, 0.0)).any
    np.testing.assert_array_equal(CountedJoints((0.0, 0.0, 0.0)).joints(rho), rho)


def test_at_the_tool_the_count_is_its_closed_form_at_the_centre_and_its_draws_elsewhere(
) -> None:
    # (J17) at P = 0, J = I: RMS c/2 (three uniform ±c/2), max c·√3/2 (a corner)
    rms, top = count_at_tool([[0.0, 0.0, 0.0]], G, IAI)
    assert rms == pytest.approx(0.005, rel=1e-12) and top == pytest.approx(
        0.01 * math.sqrt(3) / 2, rel=1e-12)
    # over the paper's workspace, against the exact kinematics with the joints drawn
    axis = np.linspace(-100.0, 60.0, 9)
    grid = np.array(np.meshgrid(axis, axis, axis, indexing="ij")).reshape(3, -1).T
    rms, top = count_at_tool(grid, G, IAI)
    rng = np.random.default_rng(3)
    rho = orthocal.inverse(grid, G)
    drawn = [np.linalg.norm(orthocal.forward(rho + rng.uniform(-0.005, 0.005, rho.shape), G)
                            - grid, axis=1) for _ in range(40)]
    mc = np.sqrt(np.mean(np.square(drawn)))
    assert 0.97 * mc < rms < 1.03 * mc, (rms, mc)
    corner = max(np.max(np.linalg.norm(orthocal.forward(rho + 0.005 * np.array(s), G) - grid,
                                       axis=1))
                 for s in np.array(np.meshgrid(*[(-1, 1)] * 3)).reshape(3, -1).T)
    assert top == pytest.approx(corner, rel=1e-3)
    assert rms > 0.005 and top > 0.0087  # the corners of the workspace reach further
    assert count_at_tool(grid, G, (0.0, 0.0, 0.0)) == (0.0, 0.0)
