"""``auto``: model selection by a lack-of-fit F test against the measured noise."""

from __future__ import annotations

import numpy as np
import pytest
from builders import station_deviations

from orthocal import Geometry, IdentificationError
from orthocal.noise import means_covariance, noise_from_cycles, noise_from_readings
from orthocal.selection import select_model

G = Geometry()
GAUGES = [(i, j) for i in "xyz" for j in "xyz" if i != j]


def station_run(truth, rng, noise=0.002, cycles=3, readings=5):
    """Per-cycle deviations as the station forms them, and each stop's readings' std."""
    return station_deviations(truth, rng, noise=noise, cycles=cycles, readings=readings)


def test_means_covariance_of_the_shared_zero_procedure():
    keys = [("+", "x", "y"), ("-", "x", "y")]
    _, C = means_covariance(keys)
    assert C == pytest.approx(np.array([[1, 1 / 3], [1 / 3, 1]]))
    # two cycles, in units of σ²: var of a mean (2 + 2/6)/4, +/- (2/3 + 2/6)/4
    keys2 = [("+", "x", "y"), ("+", "x", "y"), ("-", "x", "y"), ("-", "x", "y")]
    _, C2 = means_covariance(keys2)
    assert C2[0, 0] == pytest.approx((2 + 2 / 6) / 4)
    assert C2[0, 1] == pytest.approx((2 / 3 + 2 / 6) / 4)
    _, Ci = means_covariance(keys2, shared_zero=False)
    assert Ci == pytest.approx(np.eye(2) / 2)
    # different gauges never correlate
    _, Cg = means_covariance([("+", "x", "y"), ("+", "x", "z")])
    assert Cg == pytest.approx(np.eye(2))


def test_noise_estimates_recover_the_reading_noise():
    rng = np.random.default_rng(1)
    data, stop_std = station_run(np.zeros(9), rng, noise=0.002, cycles=30)
    expected = 0.002 * np.sqrt(1.5 / 5)  # one per-cycle deviation
    sigma, dof = noise_from_cycles(data)
    assert dof == 12 * 29
    assert sigma == pytest.approx(expected, rel=0.08)
    sigma_r, dof_r = noise_from_readings(stop_std, 5)
    assert sigma_r == pytest.approx(expected, rel=0.05) and dof_r == 6 * 91 * 4
    with pytest.raises(ValueError, match="two cycles"):
        noise_from_cycles({("+", "x", "y"): 0.1})


def test_untilted_machine_keeps_rho_and_a_tilted_one_gets_tilts():
    rng = np.random.default_rng(2)
    plain = np.r_[1.2, -0.8, 2.0, 0, 0, 0, 0, 0, 0]
    data, _ = station_run(plain, rng)
    sel = select_model(data, G)
    assert sel.model == "rho" and sel.supported
    assert sel.tests[0].passed and len(sel.tests) == 1
    assert "F = " in sel.reason and "0.001" in sel.reason
    tilted = np.r_[1.2, -0.8, 2.0, 0, 0, 0, 0.3, -0.2, 0.25]
    data, _ = station_run(tilted, rng)
    sel = select_model(data, G)
    assert sel.model == "rho+tilt"
    assert not sel.tests[0].passed and sel.tests[0].p_value < 1e-6
    assert "rho leaves more than the noise" in sel.reason
    ident = sel.identification
    for n, truth in zip(("drho_x", "drho_y", "drho_z", "tilt_yx", "tilt_zx", "tilt_zy"),
                        tilted[[0, 1, 2, 6, 7, 8]], strict=True):
        assert abs(ident.parameters[n] - truth) < 5 * ident.std_errors[n]
    doc = sel.to_dict()
    assert doc["model"] == "rho+tilt" and doc["level"] == 0.001
    # the lattice's second level: both of its candidates were tried, rho+tilt passed
    assert [c["model"] for c in doc["candidates"]] == ["rho", "rho+gap", "rho+tilt"]
    assert [c["passed"] for c in doc["candidates"]] == [False, False, True]


def test_the_f_statistic_follows_its_distribution_on_untilted_machines():
    rng = np.random.default_rng(3)
    p_values = []
    for _ in range(120):
        truth = np.r_[rng.uniform(-2, 2, 3), np.zeros(6)]
        data, _ = station_run(truth, rng, cycles=2)
        p_values.append(select_model(data, G).tests[0].p_value)
    p = np.array(p_values)
    # uniform under the null: a fifth below 0.2, half below 0.5 (binomial slack)
    assert 0.10 < np.mean(p < 0.2) < 0.32
    assert 0.36 < np.mean(p < 0.5) < 0.64


def test_nothing_explains_the_data_uses_the_largest_and_says_so():
    rng = np.random.default_rng(4)
    data, _ = station_run(np.zeros(9), rng)
    data[("+", "x", "y")] = [v + 0.05 for v in data[("+", "x", "y")]]  # a loose indicator
    sel = select_model(data, G)
    assert not sel.supported and sel.model == "rho+tilt+gap"
    assert "no candidate explains the data" in sel.reason
    unable = {t.model: t for t in sel.tests if not t.identifiable}
    assert set(unable) == {"full+tilt", "full+tilt+gap"}
    assert "ΔL cannot be separated from the tilts" in unable["full+tilt"].note


def test_auto_without_noise_information_is_refused():
    one_each = {(s, i, j): 0.001 for s in "+-" for i, j in GAUGES}
    with pytest.raises(IdentificationError, match="auto needs the noise"):
        select_model(one_each, G)
    with pytest.raises(IdentificationError, match="positive noise"):
        select_model(one_each, G, noise_sigma=0.0, noise_dof=10)


def test_measured_noise_standard_errors_are_honest_where_ordinary_ones_are_not():
    from orthocal import identify
    from orthocal.covariance import with_measured_noise

    rng = np.random.default_rng(6)
    names = ("drho_x", "drho_y", "drho_z", "tilt_yx", "tilt_zx", "tilt_zy")
    z_ols, z_noise = [], []
    for _ in range(150):
        truth = np.r_[rng.uniform(-2, 2, 3), 0, 0, 0, 0.5, -0.5, 0.3]
        data, _ = station_run(truth, rng, noise=0.001)
        r = identify(data, G, "rho+tilt")
        sigma, _ = noise_from_cycles(data)
        honest = with_measured_noise(r, G, sigma)
        err = r.vector[[0, 1, 2, 6, 7, 8]] - truth[[0, 1, 2, 6, 7, 8]]
        z_ols.append(err / [r.std_errors[n] for n in names])
        z_noise.append(err / [honest.std_errors[n] for n in names])
    rms_ols = np.sqrt(np.mean(np.square(z_ols), axis=0))
    rms_noise = np.sqrt(np.mean(np.square(z_noise), axis=0))
    # ordinary least squares' errors are too small for the tilts (shared Π0 stops) ...
    assert rms_ols[3:].mean() > 1.15
    # ... the measured noise with the stops' correlation gives errors of the right size
    # (expected sqrt(ν/(ν − 2)) ≈ 1.045 with the 24-dof noise estimate; ±~5 % Monte Carlo)
    assert 0.9 < rms_noise.mean() < 1.2
    assert rms_noise[3:].mean() < rms_ols[3:].mean() - 0.1
    assert np.all((rms_noise > 0.8) & (rms_noise < 1.3))
    # and the correlation matrix stays one
    assert np.allclose(np.diag(honest.correlation), 1.0)


def test_students_t_intervals_hold_the_truth_where_the_normals_do_not():
    """Two cycles (12 dof per run): ±k95·SE from Student's t holds the truth in
    95 % of runs, ±1.96·SE in visibly fewer; the identification carries its dof."""
    from orthocal import coverage_factor, identify
    from orthocal.covariance import with_measured_noise

    rng = np.random.default_rng(11)
    z, dofs = [], set()
    for _ in range(700):
        truth = np.r_[rng.uniform(-2, 2, 3), np.zeros(6)]
        data, _ = station_run(truth, rng, noise=0.001, cycles=2, readings=3)
        sigma, dof = noise_from_cycles(data)
        r = with_measured_noise(identify(data, G, "rho"), G, sigma, noise_dof=dof)
        assert r.se_dof == dof and r.to_dict()["std_errors_dof"] == dof
        dofs.add(dof)
        z += [(r.parameters[n] - t) / r.std_errors[n]
              for n, t in zip(("drho_x", "drho_y", "drho_z"), truth[:3], strict=True)]
    assert dofs == {12}
    z = np.abs(np.asarray(z))
    k95 = coverage_factor(12, 0.95)
    assert k95 == pytest.approx(2.179, abs=1e-3)
    inside_t, inside_normal = np.mean(z <= k95), np.mean(z <= coverage_factor(None))
    # 2100 values: the binomial's SE at 95 % is 0.5 %
    assert 0.935 < inside_t < 0.965
    assert inside_normal < inside_t - 0.01
    # without a noise estimate the fit's own residual dof stand behind the errors
    plain = identify(data, G, "rho")
    assert plain.se_dof is None and plain.std_error_dof == plain.dof
