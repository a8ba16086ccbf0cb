"""Each joint's positioning error ε_i(ρ, direction) (orthocal.joint_error; docs/model.md,
"Joint positioning errors"): the table, its constructors and lead, the deviations
and the tool field with it, and the check values model.md gives."""

from __future__ import annotations

import numpy as np
import pytest
from builders import PAPER_KEYS as PAPER

import orthocal
from orthocal.accuracy import error_field, optimal_offsets, tool_error, workspace_grid
from orthocal.compensation import compensated_field
from orthocal.joint_error import (
    JointErrors,
    JointRangeError,
    JointTable,
    iso230_table,
    joint_error_deviations,
    lead_deviation_change,
    lead_table,
    lead_um_per_m,
    pitch_table,
    posture_joint_range,
    screw_table,
    workspace_joint_range,
)

G = orthocal.Geometry()
L = G.leg_length
DRHO = np.array([0.6, -0.4, 0.9])
THETA = np.concatenate([DRHO, np.zeros(9)])
LEADS = (100.0, -80.0, 60.0)
SPAN = (150.0, 400.0)
BOX = [[-100.0, 60.0]] * 3


def leads(k=LEADS) -> JointErrors:
    return JointErrors.screws(G, SPAN, k)


# --- the table -----------------------------------------------------------------------


def test_a_table_interpolates_each_direction_linearly_and_never_extrapolates() -> None:
    t = JointTable(np.array([200.0, 300.0, 400.0]), np.array([0.001, 0.003, 0.002]),
                   np.array([0.003, 0.005, 0.006]))
    assert t.error(250.0, "forward") == pytest.approx(0.002, abs=1e-15)
    assert t.error(250.0, "reverse") == pytest.approx(0.004, abs=1e-15)
    assert t.error(350.0, "mean") == pytest.approx(0.5 * (0.0025 + 0.0055), abs=1e-15)
    # a side per value: +1 forward, −1 reverse, 0 the mean
    got = t.error(np.array([250.0, 250.0, 250.0]), np.array([1, -1, 0]))
    assert got == pytest.approx([0.002, 0.004, 0.003], abs=1e-15)
    assert t.error(200.0) == pytest.approx(0.002) and t.error(400.0) == pytest.approx(0.004)
    for outside in (199.99, 400.01, np.nan):
        with pytest.raises(JointRangeError, match="outside the table's span"):
            t.error(outside)
    with pytest.raises(ValueError, match="direction"):
        t.error(250.0, "up")


@pytest.mark.parametrize("targets, forward, why", [
    ([200.0, 200.0, 300.0], [0, 0, 0], "strictly increasing"),
    ([300.0, 200.0], [0, 0], "strictly increasing"),
    ([200.0], [0], "at least two"),
    ([200.0, 300.0], [0, np.nan], "finite"),
    ([200.0, 300.0], [0, 0, 0], "one value per target"),
])
def test_a_bad_table_is_refused(targets, forward, why) -> None:
    with pytest.raises(ValueError, match=why):
        JointTable(np.array(targets), np.array(forward, dtype=float),
                   np.zeros(len(targets)))


def test_a_table_is_referred_to_pi0_and_says_by_how_much() -> None:
    t = iso230_table([200.0, 300.0, 400.0], [5.0, 9.0, 12.0], [7.0, 11.0, 16.0],
                     u95_um=[0.5, 0.5, 0.6], pi0_mm=L)
    assert t.error(L, "mean") == pytest.approx(0.0, abs=1e-15)
    # the test as given is the table plus its shift: the mean at L was 10.1 + 1.025·…
    given_mean_at_L = np.interp(L, [200, 300, 400], [6.0, 10.0, 14.0]) * 1e-3
    assert t.shift_mm == pytest.approx(given_mean_at_L, abs=1e-15)
    assert t.forward_mm + t.shift_mm == pytest.approx([0.005, 0.009, 0.012], abs=1e-15)
    assert t.u95_mm == pytest.approx([0.0005, 0.0005, 0.0006])
    # its reversal is the test's: forward − reverse
    assert t.reversal_mm == pytest.approx([-0.002, -0.002, -0.004], abs=1e-15)
    with pytest.raises(JointRangeError):
        t.referred_to_pi0(450.0)


def test_the_measured_reversal_replaces_the_tables_keeping_its_mean() -> None:
    t = iso230_table([200.0, 300.0, 400.0], [5.0, 9.0, 12.0], [7.0, 11.0, 16.0])
    b = t.with_reversal(0.004)
    assert b.mean_mm == pytest.approx(t.mean_mm, abs=1e-15)
    assert b.reversal_mm == pytest.approx([-0.004] * 3, abs=1e-15)
    with pytest.raises(ValueError, match=">= 0"):
        t.with_reversal(-0.001)


def test_a_lead_is_exact_between_targets_and_zero_at_home() -> None:
    t = lead_table(100.0, SPAN, L)
    rho = np.array([151.3, L, 287.77, 399.9])
    assert t.error(rho) == pytest.approx(1e-4 * (rho - L), abs=1e-15)
    assert t.error(L) == pytest.approx(0.0, abs=1e-15)
    assert t.span == (150.0, 400.0)
    assert np.all(np.diff(t.targets_mm) <= 10.0 + 1e-12)


def test_a_periodic_error_is_tabulated_finely_enough() -> None:
    a_um, p_mm = 3.0, 5.0
    t = pitch_table(a_um, p_mm, SPAN, L)
    rho = np.linspace(160.0, 390.0, 2001)
    exact = 1e-3 * a_um * np.sin(2 * np.pi * (rho - L) / p_mm)
    assert np.max(np.abs(t.error(rho) - exact)) <= 0.0013 * 1e-3 * a_um
    assert np.max(np.abs(t.error(rho))) > 0.99e-3 * a_um  # not a flat table
    both = screw_table(SPAN, L, 50.0, a_um, p_mm)
    assert both.error(rho) == pytest.approx(5e-5 * (rho - L) + t.error(rho), abs=1e-12)
    with pytest.raises(ValueError, match="period"):
        screw_table(SPAN, L, pitch_um=1.0)


# --- the lead a table shows ----------------------------------------------------------


def test_the_lead_of_a_pure_lead_table_is_its_k_with_no_width() -> None:
    lead = lead_um_per_m(lead_table(-80.0, SPAN, L))
    assert lead.value_um_per_m == pytest.approx(-80.0, abs=1e-9)
    assert lead.interval_95_um_per_m == pytest.approx((-80.0, -80.0), abs=1e-9)


def test_the_leads_interval_carries_the_points_and_the_scatter() -> None:
    targets = np.arange(180.0, 381.0, 10.0)
    rng = np.random.default_rng(3)
    scatter = rng.normal(0.0, 0.4, targets.size)  # µm
    mean = 0.12 * (targets - L) + scatter  # 120 µm/m
    t = iso230_table(targets, mean - 1.0, mean + 1.0, u95_um=np.full(targets.size, 0.5),
                     pi0_mm=L)
    lead = lead_um_per_m(t)
    slope = np.polyfit(targets, mean, 1)[0] * 1e3
    assert lead.value_um_per_m == pytest.approx(slope, rel=1e-12)
    d = targets - targets.mean()
    # the points: 0.5 µm everywhere, correlated in the worst way → 0.5·Σ|d|/Σd²
    assert lead.points_um_per_m == pytest.approx(0.5e-3 * np.abs(d).sum() / (d @ d) * 1e6)
    resid = (mean - np.polyval(np.polyfit(targets, mean, 1), targets))
    se = np.sqrt(resid @ resid / (targets.size - 2)) / np.sqrt(d @ d) * 1e3
    assert lead.scatter_um_per_m == pytest.approx(se, rel=1e-9)
    assert lead.dof == targets.size - 2
    half = np.hypot(lead.points_um_per_m, orthocal.coverage_factor(lead.dof) * se)
    lo, hi = lead.interval_95_um_per_m
    assert (lo, hi) == pytest.approx((slope - half, slope + half))
    assert lo < 120.0 < hi and hi - lo < 20.0


# --- the three joints ----------------------------------------------------------------


def test_joint_errors_name_the_joint_out_of_its_table_and_leave_exact_ones_alone() -> None:
    e = JointErrors.of({"y": lead_table(100.0, (200.0, 380.0), L)})
    rho = np.array([[100.0, 250.0, 500.0]])
    assert e.error(rho)[0] == pytest.approx([0.0, 1e-4 * (250.0 - L), 0.0], abs=1e-15)
    with pytest.raises(JointRangeError, match=r"joint y: ρ = 190\.000 mm"):
        e.error(np.array([300.0, 190.0, 300.0]))
    with pytest.raises(ValueError, match="unknown joint"):
        JointErrors.of({"w": None})


def test_the_workspace_and_postures_joint_ranges_are_exact() -> None:
    lo, hi = workspace_joint_range(BOX, G)
    axes = [np.linspace(-100.0, 60.0, 33)] * 3
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    rho = orthocal.inverse(grid, G)
    assert lo == pytest.approx(rho.min(axis=0), abs=1e-9)
    assert hi == pytest.approx(rho.max(axis=0), abs=1e-9)
    assert lo[0] == pytest.approx(-100.0 + np.sqrt(L**2 - 2e4), abs=1e-12)
    # a box off the origin: the nearest |p_j| sets the upper end
    lo2, hi2 = workspace_joint_range([[0.0, 10.0], [20.0, 30.0], [-40.0, -30.0]], G)
    assert hi2[0] == pytest.approx(10.0 + np.sqrt(L**2 - 20.0**2 - 30.0**2))
    assert lo2[0] == pytest.approx(0.0 + np.sqrt(L**2 - 30.0**2 - 40.0**2))
    plo, phi = posture_joint_range(G)
    assert plo == pytest.approx([L - 100.0] * 3) and phi == pytest.approx([L + 60.0] * 3)
    plo, _ = posture_joint_range(G, [60.0, 30.0, 20.0])  # the others' L·cos α is least
    assert plo[0] == pytest.approx(L * np.cos(np.arcsin(60.0 / L)))


# --- the deviations: docs/model.md's check values ------------------------------------

#: δΔ of leads (+100, −80, +60) µm/m at Δρ = (0.6, −0.4, 0.9) mm, paper order, µm
EXACT_CHANGE_UM = [-1.067, +1.154, -0.757, +0.866, +0.102, +0.605, +0.059, +0.405,
                   +0.826, -0.909, +0.619, -0.632]
#: (J4), the same in closed form (first order in k, exact in the strokes)
CLOSED_FORM_UM = [-1.062, +1.145, -0.778, +0.840, +0.086, +0.576, +0.069, +0.428,
                  +0.817, -0.900, +0.598, -0.661]


def test_exact_joints_give_the_deviations_of_the_model() -> None:
    got = joint_error_deviations(PAPER, G, THETA, JointErrors())
    assert got == pytest.approx(orthocal.deviations(PAPER, G, THETA), abs=1e-13)


def test_what_a_lead_does_to_the_deviations_check_values() -> None:
    base = orthocal.deviations(PAPER, G, THETA)
    change = (joint_error_deviations(PAPER, G, THETA, leads()) - base) * 1e3
    assert change == pytest.approx(EXACT_CHANGE_UM, abs=0.0006)
    closed = lead_deviation_change(PAPER, G, LEADS) * 1e3
    assert closed == pytest.approx(CLOSED_FORM_UM, abs=0.0006)
    # first order in k: exact at the nominal machine to its second order ...
    at_zero = (joint_error_deviations(PAPER, G, None, leads())
               - orthocal.deviations(PAPER, G, None)) * 1e3
    assert np.max(np.abs(at_zero - closed)) < 2e-4
    # ... and within 0.03 µm at the offsets
    assert 0.01 < np.max(np.abs(change - closed)) < 0.03
    # per 100 µm/m at Π^+ the joint's own lead adds 0.820 µm, the other's −0.406
    coefficient = [lead_deviation_change([(s, "x", "y")], G, k)[0] * 1e3
                   for s in "+-" for k in ([100, 0, 0], [0, 100, 0])]
    assert coefficient == pytest.approx([0.8201, -0.4061, 0.6050, -0.2942], abs=1e-4)


def test_a_rho_fit_takes_a_lead_for_a_micrometre_of_offset_and_residual() -> None:
    base = orthocal.deviations(PAPER, G, THETA)
    measured = joint_error_deviations(PAPER, G, THETA, leads())
    fit = orthocal.identify(dict(zip(PAPER, measured, strict=True)), G, "rho")
    bias = [(fit.parameters[f"drho_{a}"] - d) * 1e3 for a, d in zip("xyz", DRHO, strict=True)]
    assert bias == pytest.approx([0.842, -1.222, 0.409], abs=0.002)
    assert fit.residual_rms * 1e3 == pytest.approx(0.711, abs=0.002)
    exact = orthocal.identify(dict(zip(PAPER, base, strict=True)), G, "rho")
    assert exact.residual_rms < 1e-9


# --- the tool ------------------------------------------------------------------------


def grid() -> np.ndarray:
    return workspace_grid(np.array(BOX), 7, G).points


def test_no_joint_errors_leave_the_field_bit_for_bit() -> None:
    p = grid()
    theta = np.concatenate([DRHO, [0, 0, 0], [0.2, 0.1, -0.15], [0.15, -0.1, 0.12]])
    before = tool_error(p, G, theta, -DRHO)
    assert np.array_equal(tool_error(p, G, theta, -DRHO, None), before)
    # all three exact: the same numbers
    assert np.array_equal(tool_error(p, G, theta, -DRHO, JointErrors()), before)


def test_what_a_lead_does_to_the_tool_check_values() -> None:
    p = grid()
    e = leads()
    trans = error_field(p, G, THETA, -DRHO, "translation", e)
    assert (trans.rms_mm * 1e3, trans.max_mm * 1e3) == pytest.approx((8.567, 22.460), abs=0.002)
    rigid = error_field(p, G, THETA, -DRHO, "rigid", e)
    assert (rigid.rms_mm * 1e3, rigid.max_mm * 1e3) == pytest.approx((8.212, 18.029), abs=0.002)
    # offsets cannot take it: the best leave 7.83 µm, 8 µm away from −Δρ
    best = optimal_offsets(p, G, THETA, "translation", joint_errors=e)
    assert best.field.rms_mm * 1e3 == pytest.approx(7.832, abs=0.005)
    # without the joints the same machine is exact
    assert error_field(p, G, THETA, -DRHO).rms_mm < 1e-12
    # linear in k: one joint's lead alone, and half of every lead
    alone = error_field(p, G, THETA, -DRHO, "translation", leads((100.0, 0.0, 0.0)))
    assert (alone.rms_mm * 1e3, alone.max_mm * 1e3) == pytest.approx((5.901, 14.155), abs=0.002)
    half = error_field(p, G, THETA, -DRHO, "translation", leads((50.0, -40.0, 30.0)))
    assert half.rms_mm == pytest.approx(trans.rms_mm / 2, rel=2e-3)


def test_the_field_of_a_lead_is_the_jacobian_times_epsilon_to_first_order() -> None:
    p = grid()
    e = leads()
    rho = orthocal.inverse(p, G) - DRHO
    h = 1e-4
    jac = np.stack([(orthocal.forward(rho + h * np.eye(3)[j], G, DRHO)
                     - orthocal.forward(rho - h * np.eye(3)[j], G, DRHO)) / (2 * h)
                    for j in range(3)], -1)
    linear = np.einsum("nij,nj->ni", jac, e.error(rho))
    exact = tool_error(p, G, THETA, -DRHO, e)
    assert np.max(np.abs(exact - linear)) < 2e-6  # 22 µm of field, 1 nm apart
    assert np.max(np.abs(exact)) > 0.02


def test_each_side_of_a_joint_with_play_is_the_mean_shifted_by_half_its_band() -> None:
    p = grid()
    b = 0.008
    e = JointErrors(*(lead_table(k, SPAN, L).with_reversal(b) for k in LEADS))
    mean = tool_error(p, G, THETA, -DRHO, e, "mean")
    fwd = tool_error(p, G, THETA, -DRHO, e, "forward")
    rev = tool_error(p, G, THETA, -DRHO, e, "reverse")
    # the kinematics' second order in B/2 (4 µm over 310 mm) apart
    assert 0.5 * (fwd + rev) == pytest.approx(mean, abs=1e-6)
    assert np.max(np.linalg.norm(fwd - rev, axis=1)) > 0.9 * b
    # one side per point and joint: x from below, y and z from above, as tables
    # holding that side both ways
    sides = np.broadcast_to([1, -1, -1], p.shape)
    mixed = tool_error(p, G, THETA, -DRHO, e, sides)
    fixed = [JointTable(t.targets_mm, side, side) for t, side in
             ((e.x, e.x.forward_mm), (e.y, e.y.reverse_mm), (e.z, e.z.reverse_mm))]
    assert mixed == pytest.approx(tool_error(p, G, THETA, -DRHO, JointErrors(*fixed)),
                                  abs=1e-15)
    assert np.max(np.abs(mixed - mean)) > 0.3 * b


def test_a_controller_told_the_machine_but_not_its_joints_leaves_their_field() -> None:
    p = grid()
    e = leads()
    truth = np.concatenate([DRHO, np.zeros(9)])
    told = compensated_field(p, G, truth, truth, "translation")
    assert told.rms_mm < 1e-9
    untold = compensated_field(p, G, truth, truth, "translation", e)
    # ε taken at the joints commanded: the field of the leads with the offsets right,
    # but for ε'·Δρ (< 0.1 µm)
    at_offsets = error_field(p, G, THETA, -DRHO, "translation", e)
    assert untold.rms_mm == pytest.approx(at_offsets.rms_mm, abs=1e-4)
    assert untold.rms_mm * 1e3 > 8.0
