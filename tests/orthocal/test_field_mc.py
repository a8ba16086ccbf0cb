"""The tool's figures by Monte Carlo (orthocal/field_mc.py; docs/model.md, "Intervals at
the tool"): what the method must do whatever the machine. An exactly known machine
is a point; a parameter known to 5 % gives ±1.96·5 % of its effect; a bounded input
is drawn rectangular; Student's t widens; the max is never below the RMS, value and
ends; the field of the draws is the exact model's to the stated tolerance; the
joints' errors reach the field through the exact kinematics. Coverage against
simulated truths: tests/orthocal/test_tool_coverage.py."""

from __future__ import annotations

import numpy as np
import pytest

from orthocal import Geometry, workspace_grid
from orthocal.accuracy import error_field, fitted_field, tool_error
from orthocal.compensation import compensated_field, compensated_interval, truth_jacobian
from orthocal.field_mc import Bounded, Inputs, figures, frame_projection
from orthocal.joint_error import JointErrors
from orthocal.kinematics import forward, inverse
from orthocal.tool_interval import after_interval, field_jacobian, joint_jacobian

G = Geometry()
UM = 1e-3
TILT, GAP = (0.2, 0.1, -0.15), (0.15, -0.10, 0.12)
# the held-out machine, as a verification leaves it: Δρ of a few µm, tilted and gapped
MACHINE = np.array([0.002, -0.001, 0.0015, 0, 0, 0, *TILT, *GAP])
SE = np.array([0.001] * 3 + [0.0] * 3 + [0.01] * 3 + [0.002] * 3)
COV = np.diag(SE**2)


@pytest.fixture(scope="module")
def grid() -> np.ndarray:
    return workspace_grid(None, 5, G).points


def ordered(iv) -> None:
    """Each figure's value inside its interval, and the max never below the RMS."""
    (rlo, rhi), (mlo, mhi) = iv.rms_interval_mm, iv.max_interval_mm
    assert 0.0 <= rlo <= iv.rms_mm <= rhi
    assert 0.0 <= mlo <= iv.max_mm <= mhi
    assert mlo >= rlo and iv.max_mm >= iv.rms_mm and mhi >= rhi


def test_an_exactly_known_machine_is_a_point(grid) -> None:
    after = after_interval(MACHINE, np.zeros((12, 12)), None, None, grid, G)
    plug = error_field(grid, G, MACHINE, None)
    assert after.rms_interval_mm == (plug.rms_mm, plug.rms_mm) and after.rms_mm == plug.rms_mm
    assert after.max_interval_mm == (plug.max_mm, plug.max_mm) and after.max_mm == plug.max_mm
    told = after_interval(MACHINE, np.zeros((12, 12)), None, None, grid, G, bounded=Bounded(
        np.zeros((12, 1)), [0.01]))  # an input that moves nothing is no uncertainty
    assert told.rms_interval_mm == (plug.rms_mm, plug.rms_mm)
    comp = compensated_interval(MACHINE, MACHINE, np.zeros((12, 12)), None, grid, G)
    assert comp.rms_mm < 1e-9 and comp.rms_interval_mm[1] < 1e-9


@pytest.mark.parametrize("which", ["yx", "xz"])
def test_a_parameter_known_to_5_percent_gives_5_percent_of_its_effect(grid, which) -> None:
    """One tilt (0.2 mrad) or one gap (0.12 mm), nothing else: the field is its
    effect, linear in it, and a standard error of 5 % of it must give the RMS and the
    max ± 1.96·5 % (Student t would widen it, a Cauchy-Schwarz bound over every
    direction widen it more: both fail the upper bound)."""
    theta = np.zeros(12)
    c = {"yx": 6, "xz": 10}[which]
    theta[c] = 0.2 if which == "yx" else 0.12
    cov = np.zeros((12, 12))
    cov[c, c] = (0.05 * theta[c]) ** 2
    iv = after_interval(theta, cov, None, None, grid, G, draws=4000, seed=3)
    plug = error_field(grid, G, theta, None)
    for (lo, hi), value in ((iv.rms_interval_mm, plug.rms_mm), (iv.max_interval_mm, plug.max_mm)):
        assert (value - lo) / value == pytest.approx(1.96 * 0.05, abs=0.006)
        assert (hi - value) / value == pytest.approx(1.96 * 0.05, abs=0.006)
    assert iv.rms_mm == pytest.approx(plug.rms_mm, rel=0.01)
    ordered(iv)


def test_a_bounded_input_is_drawn_rectangular(grid) -> None:
    """A tilt known only to lie within ±b (rectangular): the figure's 95 % interval is
    its value ± 0.95·b of its effect (the uniform's 2.5 and 97.5 % points), not the
    ±1.96·b/√3 = ±1.13·b a normal of the same variance gives."""
    theta = np.zeros(12)
    theta[6] = 0.2
    b = 0.02
    cols = np.zeros((12, 1))
    cols[6, 0] = 1.0
    iv = after_interval(theta, np.zeros((12, 12)), None, None, grid, G, draws=4000, seed=4,
                        bounded=Bounded(cols, [b]))
    plug = error_field(grid, G, theta, None).rms_mm
    effect = b / 0.2 * plug  # the field is linear in the tilt
    lo, hi = iv.rms_interval_mm
    assert (plug - lo) / effect == pytest.approx(0.95, abs=0.02)
    assert (hi - plug) / effect == pytest.approx(0.95, abs=0.02)
    # the same input as a normal systematic part of its variance: wider
    cov = np.zeros((12, 12))
    cov[6, 6] = b**2 / 3
    normal = after_interval(theta, np.zeros((12, 12)), None, None, grid, G, draws=4000,
                            seed=4, systematic=cov)
    assert (normal.rms_interval_mm[1] - plug) / effect == pytest.approx(1.13, abs=0.03)
    # named rows reach the same parameter
    named = after_interval(theta, np.zeros((12, 12)), None, None, grid, G, draws=4000, seed=4,
                           bounded=Bounded([[1.0]], [b], ("tilt_yx",)))
    assert named.rms_interval_mm == pytest.approx(iv.rms_interval_mm, rel=1e-12)


def test_few_degrees_of_freedom_widen_the_interval(grid) -> None:
    wide = after_interval(MACHINE, COV, 3, None, grid, G, seed=1)
    normal = after_interval(MACHINE, COV, None, None, grid, G, seed=1)
    w = [iv.rms_interval_mm[1] - iv.rms_interval_mm[0] for iv in (wide, normal)]
    # Student t on 3 dof: 3.18 against 1.96, the same normal draws scaled per draw
    assert w[0] / w[1] == pytest.approx(3.18 / 1.96, rel=0.1)
    ordered(wide)
    assert "Student t, 3 dof" in wide.method and "normal" in normal.method


@pytest.mark.parametrize("case", ["large", "near zero", "rigid", "compensated", "absent"])
def test_the_max_is_never_below_the_rms_and_each_value_is_inside(grid, case) -> None:
    rng = np.random.default_rng(5)
    est = MACHINE + rng.standard_normal(12) * SE
    if case in ("near zero", "absent"):
        est[6:] = rng.standard_normal(6) * SE[6:]
    if case == "large":
        iv = after_interval(est, COV, 8, None, grid, G)
    elif case == "near zero":
        iv = after_interval(est, COV, None, None, grid, G)
    elif case == "rigid":
        iv = after_interval(est, COV, None, -est[:3] * 0.9, grid, G, frame="rigid")
    else:
        told = est.copy()
        absent = None
        if case == "absent":
            told[6:] = 0.0
            absent = [False] * 6 + [True] * 6
        iv = compensated_interval(told, est, COV, None, grid, G, absent=absent)
    ordered(iv)


def test_a_zero_field_within_the_noise_reaches_zero_and_the_plug_in_does_not(grid) -> None:
    """The plug-in's norm is biased upward by the noise: a square machine whose
    estimate is noise alone has an interval from 0, and a value below the plug-in."""
    rng = np.random.default_rng(6)
    est = np.r_[0, 0, 0, 0, 0, 0, rng.standard_normal(6) * SE[6:]]
    iv = after_interval(est, COV, None, None, grid, G)
    plug = error_field(grid, G, est, None)
    assert iv.rms_interval_mm[0] == 0.0 and iv.rms_mm < plug.rms_mm < iv.rms_interval_mm[1]
    assert iv.to_dict().keys() == {"rms_mm", "max_mm", "rms_interval_95_mm",
                                   "max_interval_95_mm"}


def test_a_plug_in_below_the_noise_keeps_the_noises_upper_end(grid) -> None:
    """An estimate exactly on the square machine (a plug-in of zero, below what the
    noise alone leaves almost always): the interval is not the point 0 it would
    claim, its upper end is the one a zero field's plug-in at its 16 % point gets
    (power-constrained), and a plug-in at the noise's level gets no less."""
    zero = after_interval(np.zeros(12), COV, None, None, grid, G, seed=3)
    assert zero.rms_interval_mm[0] == 0.0 and zero.rms_interval_mm[1] > 0.5 * UM
    assert zero.max_interval_mm[1] > zero.rms_interval_mm[1]
    rng = np.random.default_rng(8)
    noisy = [after_interval(np.r_[0, 0, 0, 0, 0, 0, rng.standard_normal(6) * SE[6:]], COV,
                            None, None, grid, G, seed=3) for _ in range(5)]
    assert zero.rms_interval_mm[1] <= min(iv.rms_interval_mm[1] for iv in noisy) * 1.02
    ordered(zero)


def test_a_large_field_is_plain_s1(grid) -> None:
    """Far from zero the interval is plain S1's (the truth F(θ̂ − δ), δ drawn; its
    probabilistically symmetric interval) within the Monte Carlo's own scatter."""
    est = MACHINE
    iv = after_interval(est, COV, None, None, grid, G, draws=4000, seed=7)
    cols = [0, 1, 2, 6, 7, 8, 9, 10, 11]
    J = field_jacobian(grid, G, est, None, "translation", cols)
    F0 = error_field(grid, G, est, None).field.ravel()
    d = np.random.default_rng(8).standard_normal((4000, 9)) * SE[cols]
    fields = (F0 - d @ J.T).reshape(4000, -1, 3)
    rms = np.sqrt(np.mean(np.sum(fields**2, axis=2), axis=1))
    mx = np.sqrt(np.max(np.sum(fields**2, axis=2), axis=1))
    width = iv.rms_interval_mm[1] - iv.rms_interval_mm[0]
    assert iv.rms_interval_mm == pytest.approx(np.quantile(rms, [0.025, 0.975]), abs=0.05 * width)
    mw = iv.max_interval_mm[1] - iv.max_interval_mm[0]
    assert iv.max_interval_mm == pytest.approx(np.quantile(mx, [0.025, 0.975]), abs=0.05 * mw)


@pytest.mark.parametrize("frame", ["translation", "rigid"])
def test_the_linear_field_is_the_exact_models_to_the_stated_tolerance(grid, frame) -> None:
    """docs/model.md: over draws of 4σ (Δρ 4 µm, tilts 0.04 mrad, gaps 8 µm) the
    linearised field is the exact one to 2e-6 mm; over errors as large as the legs'
    form can make (tilts 0.2 mrad, gaps 30 µm) to 2e-5 mm, 1e-3 of the change."""
    cols = [0, 1, 2, 6, 7, 8, 9, 10, 11]
    J = field_jacobian(grid, G, MACHINE, None, frame, cols)
    Jc = truth_jacobian(grid, G, MACHINE, MACHINE, frame, cols)
    F0 = fitted_field(grid, G, MACHINE, np.zeros(3), frame).ravel()
    rng = np.random.default_rng(9)
    for size, tol in (((4e-3,) * 3 + (0.04,) * 3 + (8e-3,) * 3, 2e-6),
                      ((5e-3,) * 3 + (0.2,) * 3 + (0.03,) * 3, 2e-5)):
        for _ in range(10):
            d = np.zeros(12)
            d[cols] = np.asarray(size) * rng.uniform(-1, 1, 9)
            exact = fitted_field(grid, G, MACHINE - d, np.zeros(3), frame).ravel()
            change = np.abs(J @ d[cols]).max()
            assert np.abs(F0 - J @ d[cols] - exact).max() < min(tol, 1e-3 * change)
            comp = compensated_field(grid, G, MACHINE - d, MACHINE, frame).field.ravel()
            assert np.abs(-Jc @ d[cols] - comp).max() < min(tol, 1e-3 * change)


def lead_columns(points: np.ndarray, offsets: np.ndarray | None = None) -> np.ndarray:
    """Joint errors (3n × 3) per unit lead error of each joint: e_i = ε_i·(ρ_i − L), the
    counted joint off in proportion to its travel from where it was zeroed (Π0)."""
    rho = inverse(points, G) + (np.zeros(3) if offsets is None else offsets)
    cols = np.zeros((len(points), 3, 3))
    for i in range(3):
        cols[:, i, i] = rho[:, i] - G.leg_length
    return cols.reshape(-1, 3)


def test_a_joints_error_reaches_the_tool_through_the_exact_kinematics(grid) -> None:
    """joint_jacobian against the exact model with a lead error of 50 µm/m on each
    joint: the carriages at ρ + o + Δρ + ε·(ρ − L)."""
    eps = np.array([5e-5, -3e-5, 4e-5])
    o = -MACHINE[:3]
    e = (lead_columns(grid, o) @ eps).reshape(-1, 3)
    exact = forward(inverse(grid, G) + o + e, G, MACHINE[:3], None, MACHINE[6:9],
                    MACHINE[9:]) - grid - tool_error(grid, G, MACHINE, o)
    linear = np.einsum("kij,kj->ki", joint_jacobian(grid, G, MACHINE, o), e)
    assert np.abs(exact).max() > 1e-3  # µm-sized: a real test
    assert np.abs(linear - exact).max() < 1e-3 * np.abs(exact).max()


def test_a_lead_error_is_a_field_error_drawn_per_draw(grid) -> None:
    """An exactly known machine (a point without it) whose joints may have a lead
    error within ±50 µm/m each: the truth's RMS is |ε|'s effect, so with one joint's
    lead alone its interval is the uniform's 2.5 and 97.5 % points of that effect;
    given as a Bounded or as a callable drawing the same, one distribution."""
    b = 5e-5
    only_x = np.zeros((len(grid) * 3, 1))
    only_x[:, 0] = lead_columns(grid)[:, 0]
    iv = after_interval(np.zeros(12), np.zeros((12, 12)), None, None, grid, G, draws=4000,
                        seed=2, joint_draws=Bounded(only_x, [b]))
    J = joint_jacobian(grid, G, np.zeros(12), None)
    unit = frame_projection(grid, "translation")(
        np.einsum("kij,kj->ki", J, only_x[:, 0].reshape(-1, 3)))
    effect = b * float(np.sqrt(np.mean(np.sum(unit**2, axis=1))))
    assert effect > 1e-3
    # each quantile of 4000 draws within 3 of its standard errors, 0.0025·effect
    assert iv.rms_interval_mm == pytest.approx((0.025 * effect, 0.975 * effect),
                                               abs=0.0075 * effect)
    assert iv.rms_mm == pytest.approx(0.5 * effect, abs=0.025 * effect)

    def draw(rng: np.random.Generator, n: int) -> np.ndarray:
        return (rng.uniform(-b, b, (n, 3)) @ lead_columns(grid).T).reshape(n, -1, 3)
    every = after_interval(np.zeros(12), np.zeros((12, 12)), None, None, grid, G, draws=4000,
                           seed=2, joint_draws=Bounded(lead_columns(grid), [b] * 3))
    called = after_interval(np.zeros(12), np.zeros((12, 12)), None, None, grid, G,
                            draws=4000, seed=5, joint_draws=draw)
    assert called.rms_interval_mm == pytest.approx(every.rms_interval_mm, rel=0.05)
    assert called.max_interval_mm == pytest.approx(every.max_interval_mm, rel=0.05)
    ordered(called)
    # a raw field error the same way: the tool off in x by ε·x is a field error
    scale = np.zeros((len(grid) * 3, 1))
    scale[0::3, 0] = grid[:, 0]
    fe = after_interval(np.zeros(12), np.zeros((12, 12)), None, None, grid, G, draws=4000,
                        seed=2, field_draws=Bounded(scale, [b]))
    x = grid[:, 0] - grid[:, 0].mean()
    assert fe.rms_interval_mm[1] == pytest.approx(0.975 * b * np.sqrt(np.mean(x**2)), rel=0.05)


def test_a_draw_of_joint_tables_is_a_joint_draw(grid) -> None:
    """The joints' tables (orthocal.joint_error) reach the interval two ways: a table
    known is in the plug-in (the field error_field gives with it), and a table drawn
    per draw (a lead within ±50 µm/m on each screw, homed at Π0) is the joint_draws
    hook, the same distribution as the lead's bounded columns."""
    b = 50.0  # µm/m
    x = inverse(grid, G)
    span = (float(x.min()) - 1.0, float(x.max()) + 1.0)

    def draw(rng: np.random.Generator, n: int) -> np.ndarray:
        return np.stack([JointErrors.screws(G, span, rng.uniform(-b, b, 3)).error(x)
                         for _ in range(n)])
    tables = after_interval(np.zeros(12), np.zeros((12, 12)), None, None, grid, G,
                            draws=1000, seed=4, joint_draws=draw)
    columns = after_interval(np.zeros(12), np.zeros((12, 12)), None, None, grid, G,
                             draws=1000, seed=4, joint_draws=Bounded(lead_columns(grid),
                                                                     [1e-6 * b] * 3))
    assert tables.rms_interval_mm == pytest.approx(columns.rms_interval_mm, rel=0.06)
    assert tables.max_interval_mm == pytest.approx(columns.max_interval_mm, rel=0.06)
    known = JointErrors.screws(G, span, (30.0, -20.0, 10.0))
    iv = after_interval(MACHINE, COV, None, None, grid, G, joint_errors=known)
    plug = error_field(grid, G, MACHINE, None, joint_errors=known)
    assert iv.field.rms_mm == plug.rms_mm != error_field(grid, G, MACHINE, None).rms_mm
    comp = compensated_interval(MACHINE, MACHINE, COV, None, grid, G, joint_errors=known)
    assert comp.field.rms_mm == compensated_field(grid, G, MACHINE, MACHINE,
                                                  joint_errors=known).rms_mm > 1e-3


def test_bad_inputs_are_named() -> None:
    with pytest.raises(ValueError, match="bounds"):
        Bounded(np.zeros((12, 2)), [0.1])
    with pytest.raises(ValueError, match="≥ 0"):
        Bounded(np.zeros((12, 1)), [-0.1])
    with pytest.raises(ValueError, match="level"):
        figures(np.zeros((2, 3)), Inputs(np.zeros((6, 1)), np.ones(1, bool)), level=1.0)
    pts = workspace_grid(None, 3, G).points
    with pytest.raises(ValueError, match="joint errors"):
        after_interval(np.zeros(12), np.zeros((12, 12)), None, None, pts, G,
                       joint_draws=Bounded(np.zeros((3, 1)), [1.0]))
    with pytest.raises(ValueError, match="dof"):
        after_interval(MACHINE, COV, -1, None, pts, G)
