"""docs/model.md, "Tilts or bows": the check values, on the exact model at the legs'
middles (the paper's 12 deviations), noise 0."""

from __future__ import annotations

import numpy as np
import pytest

from orthocal import FORM, Geometry, deviations, identify

G = Geometry()
GAUGES = [(leg, d) for leg in "xyz" for d in "xyz" if d != leg]
KEYS = [(s, leg, d) for leg, d in GAUGES for s in "+-"]
DRHO = np.array([0.6, -0.4, 0.9])


def _bows(h: tuple[float, float, float]) -> dict[tuple[str, str], float]:
    return {(leg, d): h["xyz".index(leg)] for leg, d in GAUGES}


def _off_um(fit, truth: np.ndarray) -> np.ndarray:
    return 1000 * (np.array([fit.parameters[f"drho_{a}"] for a in "xyz"]) - truth)


def test_tilted_gapped_axes_on_straight_legs_are_bows_as_well() -> None:
    truth = np.array([*DRHO, 0, 0, 0, 0.2, 0.1, -0.15, 0.15, -0.10, 0.12])
    data = dict(zip(KEYS, deviations(KEYS, G, truth), strict=True))
    tilts = identify(data, G, model="rho+tilt+gap")
    bows = identify(data, G, model="rho+gap" + FORM)
    assert np.abs(_off_um(tilts, DRHO)).max() < 1e-6
    # the bows fit to the nanometre too, with Δρ (−15.40, −2.71, +2.63) µm off
    assert 1000 * bows.residual_rms < 1e-6
    assert _off_um(bows, DRHO) == pytest.approx([-15.40, -2.71, 2.63], abs=0.01)
    assert max(abs(1000 * bows.parameters[n]) for n in bows.names
               if n.startswith("bow_")) == pytest.approx(10.4, abs=0.05)


def test_uniform_bows_on_square_axes_are_tilts_as_well() -> None:
    truth = np.array([*DRHO] + [0.0] * 9)
    data = dict(zip(KEYS, deviations(KEYS, G, truth, bow=_bows((0.008,) * 3)), strict=True))
    bows = identify(data, G, model="rho" + FORM)
    tilts = identify(data, G, model="rho+tilt")
    assert np.abs(_off_um(bows, DRHO[:3])).max() < 1e-6
    # the tilts leave 0.011 µm RMS of an 8 µm bow, with Δρ (15.85, 15.79, 15.87) µm off
    assert 1000 * tilts.residual_rms == pytest.approx(0.011, abs=0.001)
    assert _off_um(tilts, DRHO) == pytest.approx([15.85, 15.79, 15.87], abs=0.01)


def test_bows_of_both_signs_are_no_tilt() -> None:
    truth = np.array([*DRHO] + [0.0] * 9)
    data = dict(zip(KEYS, deviations(KEYS, G, truth, bow=_bows((0.008, -0.008, 0.008))),
                    strict=True))
    tilts = identify(data, G, model="rho+tilt")
    assert 1000 * tilts.residual_rms == pytest.approx(2.10, abs=0.01)


def test_the_largest_tilt_stated_bows_make() -> None:
    """orthocal.design.bow_tilts, the linear worst case, against exact fits: each plane
    bowed alone gives a tilt's sign there, and the legs bowed with those signs make the
    tilt the bound says (9.66 µrad for 0.5 µm, model.md); within it with signs mixed."""
    from orthocal.design import bow_tilts

    h = 0.0005
    bound = bow_tilts(KEYS, G, dict.fromkeys(GAUGES, h))
    assert 1000 * bound == pytest.approx([9.66] * 3, abs=0.01)
    truth = np.array([*DRHO] + [0.0] * 9)

    def tilt_yx(bow: dict[tuple[str, str], float]) -> float:
        data = dict(zip(KEYS, deviations(KEYS, G, truth, bow=bow), strict=True))
        return identify(data, G, model="rho+tilt+gap").parameters["tilt_yx"]

    signs = {p: float(np.sign(tilt_yx({p: h}))) for p in GAUGES}
    worst = tilt_yx({p: h * s for p, s in signs.items()})
    assert abs(worst) == pytest.approx(bound[0], rel=0.02)
    assert abs(tilt_yx(_bows((h, -h, h)))) < bound[0]
