"""Accuracy at the tool, the mathematics (docs/model.md, "Accuracy at the tool"): the
tool-point error field, its frames, the optimal offsets, squareness and the
interval of the after-field."""

from __future__ import annotations

import numpy as np
import pytest

from orthocal import (
    PARAM_NAMES,
    Geometry,
    after_interval,
    assumes,
    covariance_matrix,
    error_field,
    exact_jacobian,
    field_stats,
    fit_frame,
    optimal_offsets,
    squareness,
    tool_error,
    workspace_grid,
)

G = Geometry(leg_length=310.25, rho_min=-100, rho_max=60)
DRHO = np.array([0.5, -0.3, 0.8])
UM = 1e-3
ALL_KEYS = [(s, i, j) for s in "+-" for i in "xyz" for j in "xyz" if i != j]
RHO_TILT = [0, 1, 2, 6, 7, 8]


def machine(tilts, drho=DRHO, dL=(0, 0, 0)) -> np.ndarray:
    return np.concatenate([drho, dL, tilts]).astype(float)


@pytest.fixture(scope="module")
def grid() -> np.ndarray:
    points, excluded = workspace_grid([[-100, 60]] * 3, 7, G)
    assert excluded == 0 and points.shape == (343, 3)
    return points


# --- docs/model.md's check values ---------------------------------------------------------

CHECKS = [  # tilts, frame, (rms, max) µm for offsets 0, −Δρ, optimal
    ((0.2, 0.1, -0.15), "translation", [(243.7, 487.6), (14.0, 35.5), (7.5, 16.3)]),
    ((0.2, 0.1, -0.15), "rigid", [(170.2, 471.6), (9.9, 26.1), (4.1, 13.8)]),
    ((0.5, -0.5, 0.3), "translation", [(256.5, 518.1), (40.9, 82.9), (39.9, 71.5)]),
]


@pytest.mark.parametrize(("tilts", "frame", "expected"), CHECKS)
def test_check_values_of_model_md(grid, tilts, frame, expected):
    theta = machine(tilts)
    fields = [error_field(grid, G, theta, np.zeros(3), frame),
              error_field(grid, G, theta, -DRHO, frame),
              optimal_offsets(grid, G, theta, frame).field]
    for fld, (rms, mx) in zip(fields, expected, strict=True):
        assert fld.frame == frame
        assert fld.rms_mm / UM == pytest.approx(rms, abs=0.05)
        assert fld.max_mm / UM == pytest.approx(mx, abs=0.05)


def test_square_machine_with_minus_drho_written_leaves_nothing(grid):
    theta = machine((0, 0, 0))
    raw = tool_error(grid, G, theta, -DRHO)
    assert np.max(np.abs(raw)) < 1e-9
    for frame in ("translation", "rigid"):
        fld = error_field(grid, G, theta, -DRHO, frame)
        assert fld.rms_mm < 1e-9 and fld.max_mm < 1e-9


def test_default_box_is_the_test_posture_cube(grid):
    points, excluded = workspace_grid(None, 7, G)
    assert excluded == 0 and np.array_equal(points, grid)
    assert points.min() == -100 and points.max() == 60  # the grid includes the box ends


def test_frames_remove_what_they_say(grid):
    rng = np.random.default_rng(3)
    theta = machine((0.4, -0.2, 0.3))
    e = tool_error(grid, G, theta, rng.normal(0, 0.2, 3))
    # a pure translation is removed by both frames, a pure rotation by the rigid one
    shift = np.array([0.3, -0.1, 0.2])
    assert np.allclose(fit_frame(grid, e + shift, "translation"), fit_frame(grid, e, "translation"))
    a = 2e-3
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rotated = grid @ R.T + shift - grid
    assert np.max(np.abs(fit_frame(grid, rotated, "rigid"))) < 1e-12
    with pytest.raises(ValueError, match="frame"):
        fit_frame(grid, e, "affine")
    assert field_stats(np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]])) == pytest.approx(
        (np.sqrt(12.5), 5.0))


def test_rigid_frame_never_gives_more_than_translation(grid):
    rng = np.random.default_rng(7)
    for _ in range(10):
        theta = np.concatenate([rng.normal(0, 0.5, 3), rng.normal(0, 0.1, 3),
                                rng.normal(0, 0.4, 3)])
        o = rng.normal(0, 0.5, 3)
        t = error_field(grid, G, theta, o, "translation")
        r = error_field(grid, G, theta, o, "rigid")
        assert r.rms_mm <= t.rms_mm + 1e-12


# --- the grid ------------------------------------------------------------------------


def test_points_outside_soft_limits_or_reach_are_excluded():
    box = [[-100, 60]] * 3
    L = G.leg_length
    full, _ = workspace_grid(box, 5, G)
    # joints ρ_i ≈ L + p_i: an upper limit at L + 20 drops every node with a p_i at 60
    lower, upper = np.full(3, L - 150.0), np.full(3, L + 20.0)
    points, excluded = workspace_grid(box, 5, G, soft_limits=(lower, upper))
    assert len(points) + excluded == 125 and len(points) == 4**3
    assert np.all(points <= 20)
    rho = np.array([p + np.sqrt(L**2 - (p @ p - p**2)) for p in points])
    assert np.all((rho >= lower) & (rho <= upper))
    # nodes beyond a leg's reach go too (and are counted)
    far, excluded = workspace_grid([[-300, 300]] * 3, 5, G)
    assert excluded > 0 and len(far) + excluded == 125
    assert np.all(np.sum(far**2, axis=1, keepdims=True) - far**2 <= L**2)
    assert len(full) == 125


# --- optimal offsets -----------------------------------------------------------------


def _brute_force_rms(grid, theta, frame) -> float:
    """Coarse-to-fine grid search over o, independent of scipy."""
    centre, half = -theta[:3], 0.2
    best = np.inf
    for _ in range(6):
        axis = np.linspace(-half, half, 7)
        trials = [centre + np.array([a, b, c]) for a in axis for b in axis for c in axis]
        values = [error_field(grid, G, theta, o, frame).rms_mm for o in trials]
        k = int(np.argmin(values))
        best, centre, half = values[k], trials[k], half / 3
    return best


@pytest.mark.parametrize("frame", ["translation", "rigid"])
def test_optimal_offsets_beat_minus_drho_and_a_brute_force_search(grid, frame):
    theta = machine((0.2, 0.1, -0.15))
    o, fld = optimal_offsets(grid, G, theta, frame)
    joints = error_field(grid, G, theta, -DRHO, frame)
    assert fld.rms_mm < 0.8 * joints.rms_mm
    assert fld.rms_mm <= 1.01 * _brute_force_rms(grid, theta, frame)
    assert np.allclose(fld.offsets, o)
    # from any start the same optimum
    other = optimal_offsets(grid, G, theta, frame, start=[0.5, 0.5, -0.5])
    assert other.field.rms_mm == pytest.approx(fld.rms_mm, rel=1e-6)


def test_optimal_offsets_respect_the_bound(grid):
    theta = machine((0.2, 0.1, -0.15))
    o, fld = optimal_offsets(grid, G, theta, "translation", max_abs_offset_mm=0.4)
    assert np.all(np.abs(o) <= 0.4 + 1e-12)
    free = optimal_offsets(grid, G, theta, "translation")
    assert fld.rms_mm >= free.field.rms_mm
    assert np.isclose(abs(o[2]), 0.4)  # the unbounded optimum wants about −0.8 on z


# --- squareness ----------------------------------------------------------------------


@pytest.mark.parametrize("tilts", [(0.2, 0.1, -0.15), (0.5, -0.5, 0.3), (-1.0, 0.7, 0.4)])
def test_squareness_equals_the_tilts_to_first_order(tilts):
    s = squareness(machine(tilts), G)  # joint zeros corrected (o = −Δρ)
    second_order = 1e-3 * max(abs(t) for t in tilts) ** 2 * 2
    assert s.values == pytest.approx(tilts, abs=second_order + 1e-9)
    assert s.as_dict().keys() == {"xy", "xz", "yz"}
    # offsets cannot fix it: the same tilts whatever Δρ was, once the zeros are corrected
    s2 = squareness(machine(tilts, drho=(-1.0, 2.0, 0.3)), G)
    assert s2.values == pytest.approx(s.values, abs=1e-9)


def test_squareness_sensitivity_matches_finite_differences():
    theta = machine((0.2, 0.1, -0.15), dL=(0.05, -0.02, 0.01))
    o = -DRHO + np.array([0.01, -0.02, 0.0])
    s = squareness(theta, G, offsets=o)
    h = 1e-3
    for c in range(9):
        step = np.zeros(9)
        step[c] = h
        fd = (squareness(theta + step, G, offsets=o).values - s.values) / h
        assert s.sensitivity[:, c] == pytest.approx(fd, abs=1e-4)
    # first order: the tilt columns are the identity, Δρ and ΔL shear by about 1/L per mm
    assert s.sensitivity[:, 6:9] == pytest.approx(np.eye(3), abs=2e-3)
    assert s.sensitivity[0, 0] == pytest.approx(-1e3 / G.leg_length, rel=1e-2)
    # standard errors follow from a covariance
    cov = np.diag([1e-6] * 3 + [0] * 3 + [0.03**2] * 3)
    se = squareness(theta, G, offsets=o, covariance=cov).std_errors
    S = s.sensitivity[:, :9]  # a 9×9 covariance: axes that meet
    assert se == pytest.approx(np.sqrt(np.diag(S @ cov @ S.T)))
    assert se == pytest.approx([0.03] * 3, rel=0.02)
    by_name = {"drho_x": 1e-3, "drho_y": 1e-3, "drho_z": 1e-3,
               "tilt_yx": 0.03, "tilt_zx": 0.03, "tilt_zy": 0.03}
    assert s.propagate(by_name) == pytest.approx(se)


def test_squareness_over_the_workspace_is_close_to_the_tilts(grid):
    tilts = (0.2, 0.1, -0.15)
    s = squareness(machine(tilts), G, points=grid)
    assert s.values == pytest.approx(tilts, abs=0.03)
    assert "affine" in s.method


# --- the interval --------------------------------------------------------------------


def test_covariance_forms_agree():
    names = ("drho_x", "drho_y", "drho_z", "tilt_yx", "tilt_zx", "tilt_zy")
    k = np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    k[0, 3] = k[3, 0] = 0.5
    full = covariance_matrix(k, names)
    assert full.shape == (12, 12) and full[0, 6] == 0.5 and full[3, 3] == 0
    nested = {a: {b: full[i, j] for j, b in enumerate(PARAM_NAMES) if full[i, j]}
              for i, a in enumerate(PARAM_NAMES) if full[i].any()}
    assert np.array_equal(covariance_matrix(nested), full)
    with pytest.raises(ValueError, match="unknown"):
        covariance_matrix({"drho_w": 1.0})


def _rho_tilt_covariance(se_drho: float, se_tilt: float) -> np.ndarray:
    """Σ of a rho+tilt fit from the 12 deviations: the exact model's correlations,
    scaled to the given standard errors (mm, mrad)."""
    J = exact_jacobian(ALL_KEYS, G, None, "rho+tilt")
    c = np.linalg.inv(J.T @ J)
    d = np.sqrt(np.diag(c))
    se = np.array([se_drho] * 3 + [se_tilt] * 3)
    out = np.zeros((9, 9))
    out[np.ix_(RHO_TILT, RHO_TILT)] = c / np.outer(d, d) * np.outer(se, se)
    return out


# The after-figures' intervals (Monte Carlo, orthocal.field_mc): their properties in
# tests/orthocal/test_field_mc.py, their coverage against simulated truths in
# tests/orthocal/test_tool_coverage.py.


def test_interval_for_a_large_field_is_its_value_plus_or_minus_the_noise(grid):
    cov = _rho_tilt_covariance(1e-3, 0.03)
    est = machine((0.2, 0.1, -0.15))
    iv = after_interval(est, cov, None, -DRHO, grid, G)
    lo, hi = iv.rms_interval_mm
    # the plug-in is docs/model.md's check value; the value stated lies within the
    # interval, a few tenths of a µm below the plug-in (the noise's bias of a norm)
    assert iv.field.rms_mm / UM == pytest.approx(14.0, abs=0.05)
    assert lo < iv.rms_mm < hi and 0 < iv.field.rms_mm - iv.rms_mm < 0.5 * UM
    assert 1 * UM < hi - lo < 6 * UM
    # Student t with few dof widens it; no covariance at all leaves a point
    wide = after_interval(est, cov, 3, -DRHO, grid, G)
    assert wide.rms_interval_mm[1] - wide.rms_interval_mm[0] > 1.3 * (hi - lo)
    point = after_interval(est, np.zeros((9, 9)), None, -DRHO, grid, G)
    assert point.rms_interval_mm == (point.rms_mm, point.rms_mm)
    assert point.rms_mm == point.field.rms_mm


def test_assumes_says_what_is_not_known():
    rho_tilt = " ".join(assumes("rho+tilt"))
    assert "ΔL = 0" in rho_tilt and "two postures per leg" in rho_tilt
    assert "tilts = 0" not in rho_tilt
    rho = assumes("rho", tilt_interval={"tilt_yx": (-0.05, 0.04), "tilt_zx": (-0.03, 0.06),
                                        "tilt_zy": (-0.02, 0.02)})
    assert any("tilts" in s and "95 %" in s and "rho+tilt" in s and "leaves out" in s
               for s in rho)
    carried = assumes("rho", tilt_interval={"tilt_yx": (-0.05, 0.04)}, tilts_in_interval=True)
    assert any("include that uncertainty" in s for s in carried)
    assert any("touching off" in s for s in assumes("rho"))
    assert any("probing" in s for s in assumes("rho", frame="rigid"))
    assert not any("ΔL = 0" in s for s in assumes("full+tilt", postures_per_leg=4))
    with pytest.raises(ValueError):
        assumes("auto")
