"""A verification measured at the legs' middles alone, joined with the bows and the
layout the first round measured in two gauge planes (orthocal.carry.joined_fit;
docs/model.md, "The second gauge plane", equation (12))."""

from __future__ import annotations

import numpy as np
import pytest

from orthocal import (
    BOW_NAMES,
    GAP_NAMES,
    TILT_NAMES,
    Geometry,
    IdentificationError,
    carry,
    identify,
)
from orthocal.calibration import jacobian
from orthocal.carry import Prior, joined_fit
from orthocal.covariance import with_measured_noise
from orthocal.measurement import deviations
from orthocal.sensitivities import sensitivity

G = Geometry()
GAUGES = [(leg, d) for leg in "xyz" for d in "xyz" if d != leg]
MIDDLES = [(s, leg, d) for leg, d in GAUGES for s in "+-"]
SECOND = [(s + "@0.75", leg, d) for leg, d in GAUGES for s in "+-"]
DRHO = (0.6, -0.4, 0.9)
TILT = (0.2, 0.1, -0.15)  # mrad
GAP = (0.015, -0.010, 0.012)  # mm
# 8 µm of sagitta, a different one in every gauge plane (BOW_NAMES order)
BOW = (0.008, -0.008, 0.006, 0.008, -0.004, 0.007)
MODEL = "rho+tilt+gap+form"
LAYOUT = (*TILT_NAMES, *GAP_NAMES, *BOW_NAMES)
SIGMA = 0.001  # what weighs the data against the prior (the noise it would have)


def machine(drho: tuple[float, float, float]) -> np.ndarray:
    """The 18 parameters (FIT_NAMES order) of the machine with offsets off by ``drho``."""
    return np.r_[drho, 0.0, 0.0, 0.0, TILT, GAP, BOW]


def first_round() -> tuple[dict, Prior]:
    """Round 0, noise-free, both planes: its fit, and its layout and bows as the prior
    a later round carries (covariance that of 1 µm of noise)."""
    keys = MIDDLES + SECOND
    fit = identify(dict(zip(keys, deviations(keys, G, machine(DRHO)), strict=True)), G,
                   model=MODEL, sigma=SIGMA)
    return fit.parameters, Prior.of(fit, LAYOUT)


def verification(drho: tuple[float, float, float]) -> dict:
    """The same machine after a write-back left the joints off by ``drho``: the
    legs' middles alone, noise-free."""
    return dict(zip(MIDDLES, deviations(MIDDLES, G, machine(drho)), strict=True))


def test_round_zero_with_both_planes_tells_the_bows_from_the_tilts() -> None:
    params, _ = first_round()
    for name, true in zip(BOW_NAMES, BOW, strict=True):
        assert params[name] == pytest.approx(true, abs=1e-8), name
    for name, true in zip(TILT_NAMES, TILT, strict=True):
        assert params[name] == pytest.approx(true, abs=1e-6), name


def test_the_middles_alone_cannot_tell_a_bow_from_a_tilt() -> None:
    # twelve deviations for twelve parameters, and still a uniform bow is a tilt
    with pytest.raises(IdentificationError, match="not identifiable"):
        identify(verification((0.01, -0.005, 0.003)), G, model="rho+tilt+form")


@pytest.mark.parametrize("method", ["nonlinear", "linear"])
def test_a_verification_carrying_the_bows_finds_the_offsets(method: str) -> None:
    after = (0.012, -0.006, 0.004)  # what the write-back left
    _, prior = first_round()
    joined = joined_fit(verification(after), G, MODEL, prior, SIGMA, method=method)
    tol_drho = 1e-4 if method == "nonlinear" else 2e-3  # (7) is a linearisation
    for axis, true in zip("xyz", after, strict=True):
        assert joined.parameters[f"drho_{axis}"] == pytest.approx(true, abs=tol_drho), axis
    if method == "nonlinear":
        for name, true in zip(TILT_NAMES, TILT, strict=True):
            assert joined.parameters[name] == pytest.approx(true, abs=1e-3), name
        assert joined.converged and joined.residual_rms < 1e-8


def test_without_the_carried_bows_the_same_verification_is_micrometres_off() -> None:
    after = (0.012, -0.006, 0.004)
    params, _ = first_round()
    # the layout alone carried (tilts and gaps as round 0 found them), no bows: the
    # bows' misfit goes into Δρ
    tilt_gap = [*TILT_NAMES, *GAP_NAMES]
    prior = Prior(tuple(tilt_gap), np.array([params[n] for n in tilt_gap]),
                  np.eye(len(tilt_gap)) * 1e-10)
    joined = joined_fit(verification(after), G, "rho+tilt+gap", prior, SIGMA)
    off = [abs(joined.parameters[f"drho_{a}"] - t) for a, t in zip("xyz", after, strict=True)]
    assert 0.002 < max(off) < 0.05, off  # several µm, not noise


def test_the_joined_covariance_is_the_inverse_of_the_information() -> None:
    _, prior = first_round()
    data = verification((0.012, -0.006, 0.004))
    joined = joined_fit(data, G, MODEL, prior, SIGMA)
    keys = list(data)
    J = jacobian(keys, G, MODEL)  # exact at this small Δρ to 1e-3 of its entries
    info_data = J.T @ J / SIGMA**2
    info_prior, _ = prior.over(joined.names)
    expected = np.linalg.inv(info_data + info_prior)
    cov = np.asarray(joined.covariance)
    assert np.allclose(np.diag(cov), np.diag(expected), rtol=0.01, atol=0.0)
    # never smaller than either part alone says: the prior's own variances bound it
    idx = [joined.names.index(n) for n in prior.names]
    assert np.all(np.diag(cov)[idx] <= np.diag(prior.covariance) * (1 + 1e-9))
    assert np.all(np.diag(cov) > 0.0)
    # with the noise measured (the same σ, rows correlated through shared Π0 stops
    # left out) the covariance is the same: the sandwich of a fit weighed right
    again = with_measured_noise(joined, G, SIGMA, shared_zero=False)
    assert np.allclose(again.covariance, cov, rtol=1e-6, atol=0.0)
    # and the sensitivity is the data's share of the joined gain, (JᵀJ/σ² + I_p)⁻¹Jᵀ/σ²
    K = sensitivity(joined, G)
    assert np.allclose(K @ np.ones(len(keys)) * SIGMA**2,
                       cov @ (J.T @ np.ones(len(keys))), rtol=0.02, atol=1e-8)


def test_the_floor_is_what_the_carried_bows_leave_of_the_offsets() -> None:
    # docs/model.md (13): the data a hundred times over shrink Δρ's standard error
    # only to the part the carried bows hold; carried ten times looser, that part
    # grows about tenfold, and with the data pinned no prior is needed (it vanishes)
    _, prior = first_round()
    data = verification((0.012, -0.006, 0.004))
    joined = joined_fit(data, G, MODEL, prior, SIGMA)
    floor = carry.prior_floor(joined, G)
    for axis in "xyz":
        name = f"drho_{axis}"
        assert 0.0 < floor[name] < joined.std_errors[name], name
    loose = Prior(prior.names, prior.values, prior.covariance * 100.0)
    looser = carry.prior_floor(joined_fit(data, G, MODEL, loose, SIGMA), G)
    for axis in "xyz":
        ratio = looser[f"drho_{axis}"] / floor[f"drho_{axis}"]
        assert 5.0 < ratio <= 10.0 + 1e-9, (axis, ratio)
    # the layout alone carried (no bows, model without +form): the middles tell every
    # remaining parameter, so the floor is the data's own error a hundred times over
    tilt_gap = [*TILT_NAMES, *GAP_NAMES]
    params, _ = first_round()
    layout = Prior(tuple(tilt_gap), np.array([params[n] for n in tilt_gap]),
                   np.eye(len(tilt_gap)) * 1e-6)
    bare = joined_fit(data, G, "rho+tilt+gap", layout, SIGMA)
    bare_floor = carry.prior_floor(bare, G)
    for axis in "xyz":
        assert bare_floor[f"drho_{axis}"] <= 0.2 * bare.std_errors[f"drho_{axis}"], axis
    assert carry.prior_floor(identify(data, G, model="rho"), G) == {}
