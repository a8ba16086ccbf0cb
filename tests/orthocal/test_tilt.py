"""The extended model: actuator axes tilted off square (docs/model.md, "Extended model").
Exact kinematics with tilts, the measurement in the base-fixed indicator plane,
equation (7') against the exact model, identification and its refusals."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from orthocal import (
    MODELS,
    Geometry,
    IdentificationError,
    axis_directions,
    cannot_identify,
    deviations,
    exact_jacobian,
    forward,
    identify,
    inverse,
    jacobian,
    leg_reading,
    linear_deviations,
    posture,
    statistical_floor,
)

G = Geometry()
ALL_KEYS = [(s, i, j) for s in "+-" for i in "xyz" for j in "xyz" if i != j]

coord = st.floats(-100, 100, allow_nan=False)
offset = st.floats(-3, 3, allow_nan=False)
tilt_mrad = st.floats(-1, 1, allow_nan=False)
triple = st.tuples


def test_axis_directions_follow_the_convention():
    u = axis_directions([0.5, -0.3, 0.2])
    assert u[0] == pytest.approx([1, 0, 0], abs=0)
    assert np.linalg.norm(u, axis=1) == pytest.approx([1, 1, 1], abs=1e-15)
    # y leans toward +x by tilt_yx; z toward +x by tilt_zx and toward +y by tilt_zy
    assert u[1, 0] / u[1, 1] == pytest.approx(0.5e-3, rel=1e-12) and u[1, 2] == 0
    assert u[2, 0] / u[2, 2] == pytest.approx(-0.3e-3, rel=1e-12)
    assert u[2, 1] / u[2, 2] == pytest.approx(0.2e-3, rel=1e-12)
    assert axis_directions([0, 0, 0]) is None and axis_directions(None) is None


@settings(max_examples=200, deadline=None)
@given(p=triple(coord, coord, coord), drho=triple(offset, offset, offset),
       dL=triple(offset, offset, offset), tilt=triple(tilt_mrad, tilt_mrad, tilt_mrad))  # fmt: skip
def test_inverse_then_forward_is_identity_with_tilts(p, drho, dL, tilt):
    rho = inverse(p, G, drho, dL, tilt)
    p_back = forward(rho, G, drho, dL, tilt)
    assert p_back == pytest.approx(p, abs=1e-9)
    # each leg has its length from its carriage on the tilted axis (1')
    u = axis_directions(tilt)
    carriages = (rho + np.asarray(drho))[:, None] * (np.eye(3) if u is None else u)
    lengths = np.linalg.norm(p_back - carriages, axis=1)
    assert lengths == pytest.approx(G.leg_length + np.asarray(dL), abs=1e-9)


def test_forward_with_tilts_converges_to_1e_12_for_many_points_at_once():
    rng = np.random.default_rng(2)
    pts = rng.uniform(-100, 60, (500, 3))
    tilt = np.array([1.0, -1.0, 0.7])
    drho, dL = rng.uniform(-3, 3, 3), rng.uniform(-3, 3, 3)
    rho = inverse(pts, G, drho, dL, tilt)
    p = forward(rho, G, drho, dL, tilt)
    a = (rho + drho)[..., :, None] * axis_directions(tilt)
    err = np.linalg.norm(p[..., None, :] - a, axis=-1) - (G.leg_length + dL)
    assert np.abs(err).max() < 1e-11
    assert np.abs(p - pts).max() < 1e-11


def test_zero_tilts_give_todays_numbers_to_the_bit():
    x6 = np.random.default_rng(4).uniform(-3, 3, 6)
    x9 = np.concatenate([x6, np.zeros(3)])
    assert np.array_equal(deviations(ALL_KEYS, G, x9), deviations(ALL_KEYS, G, x6))
    rho = np.array([300.0, 320.0, 305.0])
    assert np.array_equal(forward(rho, G, x6[:3], x6[3:], [0, 0, 0]),
                          forward(rho, G, x6[:3], x6[3:]))  # fmt: skip
    assert np.array_equal(jacobian(ALL_KEYS, G, "full+tilt")[:, :6], jacobian(ALL_KEYS, G, "full"))


def test_tilted_machine_is_not_nominal_and_readings_match_deviations():
    x = np.array([1.0, -2.0, 0.5, 0.3, -0.2, 0.1, 0.5, -0.5, 0.3])
    dev = deviations(ALL_KEYS, G, x)
    one_by_one = [
        float(np.subtract(*leg_reading(np.stack([posture(s, i, G), posture("0", None, G)]),
                                       i, j, G, x[:3], x[3:6], tilt=x[6:])))
        for s, i, j in ALL_KEYS
    ]  # fmt: skip
    assert dev == pytest.approx(one_by_one, abs=1e-12)
    # tilts alone move the deviations by tens of µm per mrad (docs/model.md: 0.5 mrad → ~10 µm RMS)
    tilt_only = deviations(ALL_KEYS, G, np.r_[np.zeros(6), 0.5, -0.5, 0.3])
    assert 0.005 < np.sqrt(np.mean(tilt_only**2)) < 0.05


@pytest.mark.parametrize(
    "geometry", [G, Geometry(leg_length=250.0, rho_min=-80.0, rho_max=90.0)]
)
def test_equation_7_prime_is_the_derivative_of_the_exact_model(geometry):
    h = 1e-4
    numeric = np.empty((12, 9))
    for col in range(9):
        step = np.zeros(9)
        step[col] = h
        numeric[:, col] = (
            deviations(ALL_KEYS, geometry, step) - deviations(ALL_KEYS, geometry, -step)
        ) / (2 * h)
    assert np.abs(numeric[:, 6:]).max() > 0.01  # the tilt columns are not trivially zero
    assert jacobian(ALL_KEYS, geometry, "full+tilt") == pytest.approx(numeric, abs=1e-8)
    assert exact_jacobian(ALL_KEYS, geometry, model="full+tilt") == pytest.approx(
        numeric, abs=1e-8)
    assert exact_jacobian(ALL_KEYS, geometry, model="rho+tilt") == pytest.approx(
        numeric[:, list(MODELS["rho+tilt"])], abs=1e-8)


def test_exact_jacobian_away_from_zero_is_the_derivative_of_the_tilted_model():
    x = np.array([2.0, -1.5, 3.0, 0.0, 0.0, 0.0, 0.8, -1.0, 0.4])
    J = exact_jacobian(ALL_KEYS, G, x, "rho+tilt")
    cols = MODELS["rho+tilt"]
    h = 1e-3  # a coarser step than exact_jacobian's: an independent check
    for c, col in enumerate(cols):
        step = np.zeros(9)
        step[col] = h
        num = (deviations(ALL_KEYS, G, x + step) - deviations(ALL_KEYS, G, x - step)) / (2 * h)
        assert J[:, c] == pytest.approx(num, abs=1e-7)
    # and it is not (7') any more: the linearisation point matters at mm offsets
    assert np.abs(J - jacobian(ALL_KEYS, G, "rho+tilt")).max() > 1e-4


def test_noise_gains_of_rho_plus_tilt_match_model_md():
    floor = statistical_floor(ALL_KEYS, G, "rho+tilt", 1.0)
    assert floor[:3] == pytest.approx([2.9] * 3, abs=0.01)  # per Δρ, against 1.87 for Δρ alone
    assert floor[3:] * 1e-3 == pytest.approx([0.027] * 3, abs=0.001)  # mrad per µm


@settings(max_examples=25, deadline=None)
@given(drho=triple(offset, offset, offset), tilt=triple(tilt_mrad, tilt_mrad, tilt_mrad))
def test_rho_plus_tilt_recovers_a_tilted_machine_exactly(drho, tilt):
    truth = np.r_[drho, 0, 0, 0, tilt]
    data = dict(zip(ALL_KEYS, deviations(ALL_KEYS, G, truth), strict=True))
    r = identify(data, G, model="rho+tilt")
    assert r.names == ("drho_x", "drho_y", "drho_z", "tilt_yx", "tilt_zx", "tilt_zy")
    assert r.vector[:3] == pytest.approx(drho, abs=1e-4)  # mm
    assert r.vector[6:9] == pytest.approx(tilt, abs=1e-4)  # mrad
    assert r.residual_rms < 1e-9


def test_linear_rho_plus_tilt_is_exact_on_linear_data_and_rho_alone_is_biased():
    truth = np.array([0.01, -0.02, 0.015, 0, 0, 0, 0.5, -0.5, 0.3])
    lin = dict(zip(ALL_KEYS, linear_deviations(ALL_KEYS, G, truth), strict=True))
    assert identify(lin, G, "rho+tilt", "linear").vector[:9] == pytest.approx(truth, abs=1e-12)
    exact = dict(zip(ALL_KEYS, deviations(ALL_KEYS, G, truth), strict=True))
    rho_only = identify(exact, G, "rho")
    # left out, 0.5 mrad of tilt biases Δρ by tens of µm and leaves a residual ≫ 1 µm
    assert np.abs(rho_only.vector[:3] - truth[:3]).max() > 0.01
    assert rho_only.residual_rms > 0.005


def test_full_plus_tilt_from_two_postures_per_leg_is_refused_naming_the_cause():
    truth = np.array([0.5, -0.5, 0.2, 0.1, 0.0, -0.1, 0.3, 0.2, -0.1])
    data = dict(zip(ALL_KEYS, deviations(ALL_KEYS, G, truth), strict=True))
    with pytest.raises(IdentificationError,
                       match=r"two postures per leg ΔL cannot be separated from the tilts"):
        identify(data, G, model="full+tilt")
    with pytest.raises(IdentificationError, match=r"dL_x.*tilt_yx.*rank 8 < 9"):
        identify(data, G, model="full+tilt", method="linear")


def test_cannot_identify_says_rotation_always_and_the_rank_defect_when_there_is_one():
    notes = cannot_identify(ALL_KEYS, G, "rho+tilt")
    assert len(notes) == 1 and "rotation of the whole machine" in notes[0]
    notes = cannot_identify(ALL_KEYS, G, "full+tilt")
    assert len(notes) == 2 and "ΔL cannot be separated from the tilts" in notes[1]


def _rotated_machine_deviations(rotation: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Deviations of the machine ``x`` turned as a whole by ``rotation`` against the
    base (the indicator planes stay where the base holds them)."""
    from orthocal.kinematics import solve_spheres
    from orthocal.measurement import reading_at

    tilted = axis_directions(x[6:])
    u = (rotation @ (np.eye(3) if tilted is None else tilted).T).T  # rows: turned axes
    L = G.leg_length + x[3:6]
    rho0 = posture("0", None, G)
    out = []
    for s, leg, d in ALL_KEYS:
        i, j = "xyz".index(leg), "xyz".index(d)
        rho = posture(s, leg, G)
        r_s = reading_at(rho, solve_spheres(rho + x[:3], L, u), i, j, x[:3], G.mount_plane, u)
        r_0 = reading_at(rho0, solve_spheres(rho0 + x[:3], L, u), i, j, x[:3], G.mount_plane, u)
        out.append(float(r_s - r_0))
    return np.array(out)


def test_a_rotation_of_the_whole_machine_changes_no_deviation():
    # 1 mrad about an oblique axis: every leg still translates along its own line
    w = np.array([0.6, -0.5, 0.8])
    w = 1e-3 * w / np.linalg.norm(w)
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    R = np.eye(3) + K + K @ K / 2  # exp(K) to O(|w|³)
    R, _ = np.linalg.qr(R)
    R *= np.sign(np.diag(R))  # a proper rotation near the identity
    assert np.abs(_rotated_machine_deviations(R, np.zeros(9))).max() < 1e-12
    # ...while 1 mrad between two axes moves deviations by tens of µm
    as_tilt = np.abs(deviations(ALL_KEYS, G, np.r_[np.zeros(6), 1.0, 0, 0])).max()
    assert as_tilt > 0.04
    # On a machine with offsets and tilts, the turn changes the deviations only at
    # second order (turn × leg angles): a hundredth of what the same angle as a tilt does,
    # and half as much with half the offsets.
    x = np.array([1.0, -2.0, 0.5, 0.3, -0.2, 0.1, 0.5, -0.5, 0.3])
    change = np.abs(_rotated_machine_deviations(R, x) - deviations(ALL_KEYS, G, x)).max()
    assert change < 0.015 * as_tilt
    half = x * np.r_[[0.5] * 6, [1.0] * 3]
    change_half = np.abs(_rotated_machine_deviations(R, half) - deviations(ALL_KEYS, G, half)).max()
    assert change_half < 0.7 * change


def test_six_vector_still_accepted_and_bad_lengths_refused():
    x6 = np.array([0.1, 0.2, 0.3, 0.0, 0.0, 0.0])
    assert deviations(ALL_KEYS, G, x6) == pytest.approx(deviations(ALL_KEYS, G, np.r_[x6, 0, 0, 0]))
    with pytest.raises(ValueError, match="6, 9, 12 or 18 parameters"):
        deviations(ALL_KEYS, G, np.zeros(7))
