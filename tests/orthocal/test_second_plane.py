"""A second gauge plane per leg (docs/model.md, "Leg form against tilts and gaps"):
the posture suffix "@f", the linearisation against the exact model in that plane,
the legs' bows as fitted parameters, and the simulator against the maths."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.sim.machine import VirtualOrthoglide
from orthocal import (
    BOW_NAMES,
    FIT_NAMES,
    FORM,
    Geometry,
    IdentificationError,
    deviations,
    exact_jacobian,
    identify,
    jacobian,
    posture,
)
from orthocal.postures import check_posture, plane_offset, split_plane, with_plane

G = Geometry()
GAUGES = [(leg, d) for leg in "xyz" for d in "xyz" if d != leg]
MIDDLE_KEYS = [(s, leg, d) for leg, d in GAUGES for s in "+-"]
QUARTER_KEYS = [(s + "@0.25", leg, d) for leg, d in GAUGES for s in "+-"]
TRUTH = np.array([0.6, -0.4, 0.9, 0, 0, 0, 0.2, 0.1, -0.15, 0.15, -0.10, 0.12])
LEG_BOW = (0.008, -0.006, 0.004)  # mm: each leg's sagitta, along +j in both its planes


def bow_of(leg_bow=LEG_BOW) -> dict[tuple[str, str], float]:
    return {(leg, d): leg_bow["xyz".index(leg)] for leg, d in GAUGES}


def test_a_plane_suffix_is_a_fraction_of_the_leg_and_nothing_else():
    assert split_plane("+@0.25") == ("+", 0.25)
    assert split_plane("-50@.75") == ("-50", 0.75)
    assert split_plane("+") == ("+", 0.5)
    assert plane_offset("+@0.25", G) == pytest.approx(G.leg_length / 4)
    assert plane_offset("-", G) == 0.0
    assert with_plane("+30", 0.5) == "+30" and with_plane("+30", 0.75) == "+30@0.75"
    for bad in ("+@0.5", "+@1", "+@0", "+@-0.2", "+@x", "0@0.25", "@0.25"):
        with pytest.raises(ValueError):
            check_posture(bad)
    # the posture itself is the one without the suffix
    assert posture("+@0.25", "y", G) == pytest.approx(posture("+", "y", G), abs=0)


def test_a_second_plane_is_the_middle_plane_moved_along_the_leg():
    """A key read at f is the middle key read by a stand L·(1/2 − f) off the middle."""
    params = np.r_[TRUTH, 0.01, -0.02, 0.0, 0.03, 0.0, -0.01]
    moved = deviations(MIDDLE_KEYS, G, params, [G.leg_length / 4] * len(MIDDLE_KEYS))
    assert deviations(QUARTER_KEYS, G, params) == pytest.approx(moved, abs=1e-12)
    # and without a suffix nothing changes, bit for bit
    assert np.array_equal(deviations(MIDDLE_KEYS, G, TRUTH),
                          deviations(MIDDLE_KEYS, G, TRUTH[:12]))


@pytest.mark.parametrize("plane", ["", "@0.25", "@0.75", "@0.3"])
def test_the_linearisation_is_the_exact_jacobian_in_every_plane(plane):
    keys = [(s + plane, leg, d) for leg, d in GAUGES for s in ("+", "-", "+30", "-55.5")]
    model = "full+tilt+gap" + FORM
    J_exact = exact_jacobian(keys, G, None, model)
    J_lin = jacobian(keys, G, model)
    assert J_lin.shape == (len(keys), len(FIT_NAMES))
    # per mm and per mrad: the central differences' error, far below a µm
    assert np.abs(J_exact - J_lin).max() < 1e-8
    # a bow changes only its own gauge's rows
    bows = J_lin[:, 12:]
    for c, name in enumerate(BOW_NAMES):
        own = np.array([f"bow_{k[1]}{k[2]}" == name for k in keys])
        assert np.all(bows[~own, c] == 0.0) and np.all(bows[own, c] != 0.0)


def test_with_the_middles_alone_a_bow_cannot_be_told_from_the_tilts():
    with pytest.raises(IdentificationError, match="cannot be separated"):
        identify({k: 0.0 for k in MIDDLE_KEYS}, G, model="rho+tilt" + FORM)


@pytest.mark.parametrize("second", ["@0.25", "@0.75"])
def test_two_planes_give_back_a_bowed_tilted_machine_with_gaps(second):
    keys = MIDDLE_KEYS + [(s + second, leg, d) for leg, d in GAUGES for s in "+-"]
    values = deviations(keys, G, TRUTH, bow=bow_of())
    got = identify(dict(zip(keys, values, strict=True)), G, model="rho+tilt+gap" + FORM)
    assert got.vector == pytest.approx(TRUTH, abs=1e-9)
    for leg, d in GAUGES:
        assert got.parameters[f"bow_{leg}{d}"] == pytest.approx(
            LEG_BOW["xyz".index(leg)], abs=1e-9)
    # the geometry alone, without the bows, is the machine's twelve parameters
    assert got.vector.shape == (12,) and got.fit_vector.shape == (18,)
    # and the linear fit lands within what (7) leaves at offsets of a millimetre
    lin = identify(dict(zip(keys, values, strict=True)), G, model="rho+tilt+gap" + FORM,
                   method="linear")
    assert lin.vector[:3] == pytest.approx(TRUTH[:3], abs=0.02)


def test_without_the_bows_a_bowed_machine_buys_tilts_in_the_middles():
    """Why the second plane: a uniform bow is a tilt signature at the middles."""
    values = deviations(MIDDLE_KEYS, G, np.zeros(12), bow=bow_of((0.008, 0.008, 0.008)))
    got = identify(dict(zip(MIDDLE_KEYS, values, strict=True)), G, model="rho+tilt")
    assert np.abs(got.residuals).max() < 1e-6  # fits to a nanometre of an 8 µm bow ...
    assert max(abs(got.parameters[n]) for n in ("tilt_yx", "tilt_zx", "tilt_zy")) > 0.05


def test_the_simulator_reads_a_bowed_leg_in_a_second_plane_as_the_maths_does():
    machine = VirtualOrthoglide(G, true_drho=TRUTH[:3], true_tilt=TRUTH[6:9],
                                true_gap=TRUTH[9:12], leg_bow=LEG_BOW)
    keys = MIDDLE_KEYS + QUARTER_KEYS
    got = []
    for sign, leg, d in keys:
        plane = G.mount_plane + plane_offset(sign, G)
        got.append(machine.readings(posture(sign, leg, G), leg, d, plane)
                   - machine.readings(posture("0", None, G), leg, d, plane))
    expected = deviations(keys, G, TRUTH, bow=bow_of())
    assert 1000 * np.array(got) == pytest.approx(1000 * expected, abs=1e-9)


def test_the_form_a_single_plane_cannot_see_is_carried_into_the_tilts():
    """A uniform bow of 8 µm reads as tilts of ~0.155 mrad in the middles; the legs'
    form stated at 10 µm must cover that in the tilts' form covariance, and with a
    second plane (bows fitted) it leaves the tilts nothing."""
    from orthocal.budget import form_covariance, propagation

    truth = np.r_[0.6, -0.4, 0.9, 0, 0, 0, 0.2, 0.1, -0.15, 0, 0, 0]
    bowed = bow_of((0.008, 0.008, 0.008))
    values = deviations(MIDDLE_KEYS, G, truth, bow=bowed)
    fit = identify(dict(zip(MIDDLE_KEYS, values, strict=True)), G, model="rho+tilt")
    tilts = [fit.names.index(n) for n in ("tilt_yx", "tilt_zx", "tilt_zy")]
    bias = fit.vector[6:9] - truth[6:9]
    assert np.abs(bias).min() > 0.1  # mrad: the bow, read as tilts
    sd = np.sqrt(np.diag(form_covariance(propagation(fit, G), 0.010)))[tilts]
    assert np.all(np.abs(bias) <= 2 * sd), (bias, sd)
    # the bows fitted from two planes: the form leaves the tilts nothing
    keys = MIDDLE_KEYS + [(s + "@0.75", leg, d) for leg, d in GAUGES for s in "+-"]
    both = identify(dict(zip(keys, deviations(keys, G, truth, bow=bowed), strict=True)), G,
                    model="rho+tilt" + FORM)
    assert both.vector[6:9] == pytest.approx(truth[6:9], abs=1e-6)
    cov = form_covariance(propagation(both, G), 0.010)
    assert np.sqrt(np.diag(cov))[[both.names.index(n) for n in ("tilt_yx", "tilt_zx",
                                                                 "tilt_zy")]].max() < 1e-6


def test_the_summary_writes_signs_as_the_rest_of_it_does():
    """The gaps' and bows' lines use the typographic minus, as the statement does."""
    import json
    from pathlib import Path

    from station.report import as_result, gaps
    from station.report import leg_form as form

    # a run's record (a tilted machine's) with these gaps and this bow stated
    doc = json.loads((Path(__file__).parents[1] / "data" / "result_tilted_joints.json").read_text())
    doc["accuracy"].update(gaps={"gap_xy": -0.0012, "gap_xz": 0.0004},
                           gap_interval_95={"gap_xy": [-0.004, 0.0016]})
    doc["identified"]["bow_xy"], doc["std_errors"]["bow_xy"] = -0.0031, 0.0007
    result = as_result(doc)
    (gap_line,) = gaps.summary_lines(result.accuracy)
    assert "XY −1 ± 3, XZ +0" in gap_line and "-" not in gap_line.split("µm")[0]
    (bow_line,) = form.summary_lines(result)
    assert "XY −3.1 ± 0.7 µm" in bow_line
