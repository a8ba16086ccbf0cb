"""Intermediate test postures Π_i(s): keys, deviations, Jacobian, identification."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import orthocal
from orthocal import Geometry
from orthocal.postures import check_posture, posture_name, stop_order, stroke

G = Geometry()
AXES = ("x", "y", "z")


def keys_for(postures) -> list[tuple[str, str, str]]:
    return [(p, i, j) for p in postures for i in AXES for j in AXES if i != j]


def test_stroke_resolves_paper_postures_and_signed_strokes() -> None:
    assert stroke("+", G) == 60.0 and stroke("-", G) == -100.0
    assert stroke("+30", G) == 30.0 and stroke("-50.5", G) == -50.5
    for bad in ("0", "+0", "30", "+x", "", "++3", "+."):
        with pytest.raises(ValueError):
            check_posture(bad)
    with pytest.raises(ValueError, match="leg_length"):
        stroke("+400", G)


def test_posture_name_keeps_the_paper_keys() -> None:
    assert posture_name(60.0, G) == "+" and posture_name(-100.0, G) == "-"
    assert posture_name(30.0, G) == "+30" and posture_name(-12.5, G) == "-12.5"
    for s in (30.0, -12.5, 1.0 / 3.0):
        assert stroke(posture_name(s, G), G) == s


def test_stop_order_sweeps_out_and_back() -> None:
    assert stop_order([-100, 60]) == [60, -100]  # the paper's Π+ → Π−
    assert stop_order([-50, 30, -100, 60]) == [30, 60, -50, -100]
    # Leg i's joint travel of a cycle 0 → stops → 0 is 2·(max − min), the least possible.
    order = [0.0, *stop_order([-50, 30, -100, 60]), 0.0]
    assert sum(abs(b - a) for a, b in itertools.pairwise(order)) == 2 * 160


def test_intermediate_posture_keeps_leg_parallel() -> None:
    for leg in AXES:
        rho = orthocal.posture("+30", leg, G)
        p = orthocal.forward(rho, G)
        expected = np.zeros(3)
        expected[AXES.index(leg)] = 30.0
        np.testing.assert_allclose(p, expected, atol=1e-9)


@pytest.mark.parametrize(
    "params", [None, np.array([0.8, -1.2, 2.1, 0.3, -0.4, 0.2, 0.4, -0.6, 0.9])])
def test_stroke_keys_equal_sign_keys_at_rho_max_and_min(params) -> None:
    g = Geometry(rho_min=-80.0, rho_max=45.0)
    signs = keys_for(["+", "-"])
    strokes = [("+45" if k[0] == "+" else "-80", k[1], k[2]) for k in signs]
    np.testing.assert_array_equal(orthocal.deviations(strokes, g, params),
                                  orthocal.deviations(signs, g, params))
    np.testing.assert_array_equal(orthocal.jacobian(strokes, g, "full+tilt"),
                                  orthocal.jacobian(signs, g, "full+tilt"))


def test_linear_jacobian_is_the_exact_derivative_at_intermediate_strokes() -> None:
    keys = keys_for(["+60", "+30", "-50", "-100", "+12.5"])
    for model in ("rho", "L", "full", "rho+tilt", "full+tilt"):
        J = orthocal.jacobian(keys, G, model)
        np.testing.assert_allclose(orthocal.exact_jacobian(keys, G, None, model), J,
                                   atol=1e-9)


def test_deviations_vanish_on_the_nominal_machine_at_any_stroke() -> None:
    keys = keys_for(["+30", "-50", "+1", "-150"])
    np.testing.assert_allclose(orthocal.deviations(keys, G), 0.0, atol=1e-12)


@pytest.mark.parametrize("model", ["rho", "full", "rho+tilt", "full+tilt"])
def test_identify_with_four_strokes_recovers_noiseless_offsets(model) -> None:
    """Four stops per leg; full+tilt, rank-deficient with two, is identifiable."""
    truth = np.zeros(len(orthocal.PARAM_NAMES))
    truth[:3] = [1.7, -2.4, 0.9]
    if model.startswith("full"):
        truth[3:6] = [0.6, -0.3, 0.45]
    if model.endswith("tilt"):
        truth[6:9] = [0.5, -0.8, 0.3]  # mrad
    keys = keys_for(["+", "+30", "-50", "-"])
    data = dict(zip(keys, orthocal.deviations(keys, G, truth), strict=True))
    result = orthocal.identify(data, G, model=model, method="nonlinear")
    np.testing.assert_allclose(result.vector, truth, atol=1e-4)
    assert result.residual_rms < 1e-6


def test_identify_refuses_a_bad_stroke_key() -> None:
    with pytest.raises(orthocal.IdentificationError, match="posture"):
        orthocal.identify({("+0", "x", "y"): 0.1}, G)
