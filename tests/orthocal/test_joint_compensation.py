"""Each joint's error compensated (orthocal.joint_compensation; docs/model.md, "Joint
errors compensated"): the counts (J5) that put a joint where it is wanted, the trims a
controller adds, the tool where a controller compensates with tables, what it leaves
(J7), and the check values model.md gives."""

from __future__ import annotations

import numpy as np
import pytest

import orthocal
from orthocal.accuracy import workspace_grid
from orthocal.compensation import compensated_error
from orthocal.joint_compensation import (
    ROUTES,
    counted,
    counted_joints,
    joint_residual,
    joint_sensitivity,
    shifted,
    standing,
    table_compensated_error,
    trims,
)
from orthocal.joint_error import JointErrors, JointRangeError, JointTable, screw_table

G = orthocal.Geometry()
L = G.leg_length
SPAN = (150.0, 400.0)
LEADS = (100.0, -80.0, 60.0)
THETA = np.array([0.002, -0.001, 0.0015, 0, 0, 0, 0.2, 0.1, -0.15, 0.15, -0.10, 0.12])


def screws(k=LEADS, pitch=0.0, band=0.0) -> JointErrors:
    """Three screws homed at Π0 with leads ``k``, a periodic error of ``pitch`` µm (P =
    20 mm) and a dead band ``band`` mm (forward = mean − B/2)."""
    tables = [screw_table(SPAN, L, v, pitch, 20.0 if pitch else None) for v in k]
    return JointErrors(*(t.with_reversal(band) if band else t for t in tables))


def test_a_count_puts_the_joint_where_it_is_wanted_in_each_direction() -> None:
    table = screw_table(SPAN, L, 100.0, 3.0, 20.0).with_reversal(0.012)
    q = np.linspace(160.0, 390.0, 47)
    for side in ("forward", "reverse", "mean"):
        c = counted(table, q, side)
        assert np.abs(c + table.error(c, side) - q).max() <= 1e-12  # (J5) solved
    # the two sides differ by the band (the count moving up stands B/2 lower, so it is
    # counted B/2 higher), to B·max|ε'| (the screw's slope between the two counts:
    # 2π·3 µm/20 mm = 1e-3, so 12 nm)
    up, down = counted(table, q, "forward"), counted(table, q, "reverse")
    assert (up - down) == pytest.approx(np.full_like(q, 0.012), abs=1.3e-5)
    assert np.abs(up - down - 0.012).max() > 1e-7  # and the slope does show
    # per value, +1 / −1 as the named sides
    mixed = counted(table, q, np.where(np.arange(q.size) % 2, 1.0, -1.0))
    assert mixed[1::2] == pytest.approx(up[1::2], abs=1e-15)
    assert mixed[::2] == pytest.approx(down[::2], abs=1e-15)
    with pytest.raises(JointRangeError, match="outside"):
        counted(table, [149.0], "forward")


def test_a_pure_lead_needs_its_closed_form_trim() -> None:
    # (J6): c = q − k·(c − L) ⇒ t = c − q = −k·(q − L)/(1 + k); at ρ = L + 60, k = 100 µm/m:
    # −5.99940006 µm (model.md's check value), and 0 at Π0
    k = 100e-6
    table = screw_table(SPAN, L, 100.0)
    t = trims(table)
    want = -k * (t.nominal_mm - L) / (1 + k)
    assert t.forward_mm == pytest.approx(want, abs=1e-13)
    assert t.reverse_mm == pytest.approx(want, abs=1e-13)
    at = float(counted(table, L + 60.0) - (L + 60.0))
    assert 1e3 * at == pytest.approx(-5.99940006, abs=1e-8)
    assert float(counted(table, L)) == pytest.approx(L, abs=1e-15)


def test_the_three_joints_are_counted_each_by_its_own_table() -> None:
    errors = JointErrors(screw_table(SPAN, L, 100.0), None, screw_table(SPAN, L, -50.0))
    q = np.array([[200.0, 250.0, 300.0], [390.0, 160.0, 170.0]])
    c = counted_joints(errors, q, "forward")
    assert c[:, 1] == pytest.approx(q[:, 1], abs=0)  # no table: counted as wanted
    assert standing(errors, c, "forward") == pytest.approx(q, abs=1e-12)
    with pytest.raises(JointRangeError, match="joint z"):
        counted_joints(errors, [[200.0, 200.0, 140.0]])
    # a count |ε| beyond its table's end where the joint itself stands at the end
    edge = np.array([[SPAN[1], SPAN[1], SPAN[0]]])
    ends = counted_joints(screws(), edge)
    assert ends[0, 0] < SPAN[1] and ends[0, 1] > SPAN[1]  # −80 µm/m counts beyond
    assert standing(screws(), ends) == pytest.approx(edge, abs=1e-9)


def test_a_table_shifted_is_the_same_screw_counted_from_another_zero() -> None:
    table = screw_table(SPAN, L, 100.0)
    moved = shifted(table, -0.6)
    assert moved.targets_mm == pytest.approx(table.targets_mm - 0.6, abs=1e-12)
    assert moved.error(L - 0.6) == pytest.approx(table.error(L), abs=1e-15)


def test_tables_told_rightly_leave_the_tool_where_it_is_sent() -> None:
    points = workspace_grid(n=4).points
    told = screws(band=0.010)
    for side in ("forward", "reverse"):
        exact = table_compensated_error(points, G, THETA, THETA, told, None, side)
        assert np.abs(exact).max() <= 1e-9
    # no table told: as orthocal.compensation with the joints' errors at the tool
    bare = table_compensated_error(points, G, THETA, THETA, JointErrors(), told, "forward")
    same = compensated_error(points, G, THETA, THETA, told, "forward")
    assert bare == pytest.approx(same, abs=1e-12)
    assert 1e3 * np.linalg.norm(bare, axis=1).max() > 10.0  # the control: tens of µm
    # a table off by 10 µm/m leaves about a tenth of what 100 µm/m did
    off = table_compensated_error(points, G, THETA, THETA, screws((90.0, -80.0, 60.0)),
                                  screws(), "mean")
    alone = table_compensated_error(points, G, THETA, THETA, JointErrors(),
                                    screws((100.0, 0.0, 0.0)), "mean")
    ratio = np.linalg.norm(off, axis=1).max() / np.linalg.norm(alone, axis=1).max()
    assert ratio == pytest.approx(0.1, abs=0.002)


def test_at_pi0_the_joints_move_the_tool_one_for_one() -> None:
    # J = ∂P/∂ρ is the identity at Π0 of the nominal machine: every leg along its axis
    J = joint_sensitivity(np.zeros((1, 3)), G, np.zeros(12))
    assert J[0] == pytest.approx(np.eye(3), abs=1e-7)


def test_what_a_compensated_table_leaves_is_its_uncertainty_and_the_side_not_known() -> None:
    u = np.full(26, 0.0005)
    t = screw_table(SPAN, L, 100.0, step_mm=10.0).with_reversal(0.010)
    table = JointTable(t.targets_mm, t.forward_mm, t.reverse_mm, u)
    tables = JointErrors(table, table, table)
    at = np.zeros((1, 3))
    known = joint_residual(at, G, np.zeros(12), tables)
    # model.md's check values at Π0 (J = I): the box corner |(U, U, U)| = 0.866 µm,
    # standard sqrt(3)·U/2 = 0.433 µm
    assert 1e3 * known.bound_mm[0] == pytest.approx(0.8660254, abs=1e-6)
    assert 1e3 * known.standard_tool_mm[0] == pytest.approx(0.4330127, abs=1e-6)
    unknown = joint_residual(at, G, np.zeros(12), tables, (False, True, True))
    assert 1e3 * unknown.bound_mm[0] == pytest.approx(np.sqrt(5.5**2 + 0.5), abs=1e-6)
    # a joint without a table: its assumed bound, 0 at Π0 and 0.95·b·|ρ − L| beyond
    bare = joint_residual(np.array([[60.0, 0.0, 0.0], [0.0, 0.0, 0.0]]), G, np.zeros(12),
                          JointErrors(None, table, table), bounds_um_per_m=(170.0, None, None))
    assert bare.halfwidth_mm[1, 0] == 0.0
    assert bare.halfwidth_mm[0, 0] == pytest.approx(0.95 * 170e-6 * 60.0, rel=1e-9)
    assert bare.bound_max_mm >= bare.bound_mm[1] > 0
    with pytest.raises(ValueError, match="one per joint"):
        joint_residual(at, G, np.zeros(12), tables, (True, True))


def test_every_route_says_what_it_takes_into_account() -> None:
    assert set(ROUTES) == {"offsets", "offsets+tables", "kinematics", "kinematics+tables",
                           "program", "program+tables"}
    assert ROUTES["offsets"].startswith("offsets only")
    assert ROUTES["kinematics+tables"].startswith("the kinematics and the joint tables")
    assert ROUTES["program+tables"].startswith("a compensated program")
    assert all("stay at the tool" in ROUTES[k] for k in ("offsets", "kinematics", "program"))
