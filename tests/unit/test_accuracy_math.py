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


@pytest.mark.parametrize("tilts", [(0.0, 0.0, 0.0), (0.2, 0.1, -0.15)])
def test_interval_covers_the_true_after_rms(grid, tilts):
    """Seeded simulation: a true machine θ (residual Δρ ≈ 1 µm; square, or tilted),
    an estimate θ̂ ~ N(θ, Σ) of a rho+tilt fit (Δρ SE 1 µm, tilt SE 0.03 mrad),
    −Δρ̂ written; the interval from θ̂, Σ must cover the true after-RMS.

    One-sided on purpose: the interval is a bound that covers with probability ≥ 95 %
    whatever θ is (after_interval), and here it covers more (199 and 200 of 200 for
    the RMS, 192 and 197 for the max), so an upper limit on its coverage would fail
    a correct bound. That it is not wider than it says is the next test's, where the
    bound is exact."""
    rng = np.random.default_rng(2024)
    cov = _rho_tilt_covariance(1e-3, 0.03)
    root = np.linalg.cholesky(cov[np.ix_(RHO_TILT, RHO_TILT)])
    pts = grid[::4]  # 86 points spread over the box: the same field, a quarter of the time
    n, hits, hits_max = 200, 0, 0
    for k in range(n):
        truth = machine(tilts, drho=rng.normal(0, 1e-3, 3))
        est = truth.copy()
        est[RHO_TILT] += root @ rng.standard_normal(6)
        o = -est[:3]
        true = error_field(pts, G, truth, o, "translation")
        iv = after_interval(est, cov, None, o, pts, G, draws=300, seed=k)
        hits += iv.rms_interval_mm[0] <= true.rms_mm <= iv.rms_interval_mm[1]
        hits_max += iv.max_interval_mm[0] <= true.max_mm <= iv.max_interval_mm[1]
    # At a coverage of exactly 95 %, 183 or more of 200 with probability 0.988 (the
    # binomial); an interval that covers 90 % falls under it with probability 0.72.
    assert hits >= 183 and hits_max >= 183


def test_the_upper_end_is_exact_where_the_field_lies_along_its_least_certain_direction(grid):
    """after_interval's upper end, r ≤ T + z·s (T the stated after-RMS, z = 1.96 for
    97.5 % on one side), is exact rather than a bound where the true field is large
    and lies along the direction in which the estimate is least certain: there T ≈
    r + a, a of standard deviation s. Built so from outside the code: B = G·Σ^½ with G
    from this test's own central differences of error_field, the truth the nominal
    machine moved 30 times along B's first singular vector (a field of 30·s RMS, tilts
    ~0.7 mrad), nothing written. Over seeded estimates θ̂ ~ N(θ, Σ) the spread of T
    about the true r must be the s the interval states (an inflated s, an interval
    wider than it says, fails; a small one too), and the upper end must miss the
    truth in about 2.5 % of them."""
    pts, zero = grid[::4], np.zeros(3)
    cov = _rho_tilt_covariance(1e-3, 0.03)
    root = np.linalg.cholesky(cov[np.ix_(RHO_TILT, RHO_TILT)])
    step = 1e-4
    G_fd = np.empty((pts.size, len(RHO_TILT)))
    for k, c in enumerate(RHO_TILT):
        d = np.zeros(9)
        d[c] = step
        G_fd[:, k] = (error_field(pts, G, d, zero).field
                      - error_field(pts, G, -d, zero).field).ravel() / (2 * step)
    _, singular, vt = np.linalg.svd(G_fd @ root)
    s = singular[0] / np.sqrt(len(pts))  # the RMS norm's: over the points
    truth = np.zeros(9)
    truth[RHO_TILT] = 30 * root @ vt[0]
    r = error_field(pts, G, truth, zero).rms_mm
    assert r == pytest.approx(30 * s, rel=1e-3)  # linear at this size
    rng = np.random.default_rng(2025)
    n, off, stated, misses = 300, [], [], 0
    for k in range(n):
        est = truth.copy()
        est[RHO_TILT] += root @ rng.standard_normal(6)
        # draws: only the lower end's quantile uses them, and it is not tested here
        iv = after_interval(est, cov, None, zero, pts, G, draws=100, seed=k)
        off.append(iv.rms_mm - r)
        stated.append((iv.rms_interval_mm[1] - iv.rms_mm) / 1.959964)
        misses += r > iv.rms_interval_mm[1]
    # The ratio is sqrt(χ²₃₀₀/300) for an honest s (the ‖Bδ‖²/2r term shifts T by
    # 0.01·s here): within [0.87, 1.13] with probability 0.9986. An s inflated by 25 %
    # (ratio 0.8) passes with probability 0.016, one 20 % too small (1.25) with 0.009.
    assert 0.87 <= np.sqrt(np.mean(np.square(off))) / np.mean(stated) <= 1.13
    # Misses ~ binomial(300, 0.025), mean 7.5: 2 to 15 with probability 0.992. Coarser
    # than the ratio: an s inflated by 25 % (0.7 % misses) fails it with probability
    # 0.37, one 20 % too small (5.8 % misses) with 0.68.
    assert 2 <= misses <= 15


def test_interval_near_zero_reaches_zero_and_plug_in_would_not(grid):
    cov = _rho_tilt_covariance(1e-3, 0.03)
    est = machine((0.02, -0.01, 0.015), drho=(1e-3, 0, -1e-3))
    iv = after_interval(est, cov, None, -est[:3], grid, G)
    assert iv.rms_interval_mm[0] == 0.0 and iv.rms_interval_mm[1] > iv.rms_mm > 0
    assert iv.to_dict().keys() == {"rms_mm", "max_mm", "rms_interval_95_mm",
                                   "max_interval_95_mm"}


def test_interval_for_a_large_field_is_near_the_delta_method(grid):
    cov = _rho_tilt_covariance(1e-3, 0.03)
    est = machine((0.2, 0.1, -0.15))
    iv = after_interval(est, cov, None, -DRHO, grid, G)
    lo, hi = iv.rms_interval_mm
    assert lo < iv.rms_mm < hi and iv.rms_mm / UM == pytest.approx(14.0, abs=0.05)
    assert 1 * UM < hi - lo < 15 * UM
    # Student t with few dof widens it; no covariance at all leaves a point
    wide = after_interval(est, cov, 3, -DRHO, grid, G)
    assert wide.rms_interval_mm[1] - wide.rms_interval_mm[0] > hi - lo
    point = after_interval(est, np.zeros((9, 9)), None, -DRHO, grid, G)
    assert point.rms_interval_mm == (point.rms_mm, point.rms_mm)


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
