"""Rounds that carry an earlier round share its error (docs/model.md, "Rounds that
carry an earlier round", (14)): the carried prior enters a round's Δρ̂ through a known
gain, and the joined rounds are combined as the GUM combines correlated estimates.

The exact covariance the fits make is read off the fits themselves: each is linear in
its data to first order, so perturbing one deviation at a time and fitting again (the
first round, then the verification that carries its layout and bows, orthocal.carry.
joined_fit) gives every response, and σ²·Σ responses' products is the covariance. The
gain's formula must give the same, and the joined standard error must be the joined
value's own."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from orthocal import BOW_NAMES, GAP_NAMES, TILT_NAMES, Geometry, identify
from orthocal.carry import CarriedPrior, Prior, cross_covariance, drho_gain, joined_fit
from orthocal.loop import joined_axis, joined_with_previous
from orthocal.measurement import deviations
from station.analysis.verdict import joined_round

G = Geometry()
GAUGES = [(leg, d) for leg in "xyz" for d in "xyz" if d != leg]
MIDDLES = [(s, leg, d) for leg, d in GAUGES for s in "+-"]
SECOND = [(s + "@0.75", leg, d) for leg, d in GAUGES for s in "+-"]
# docs/model.md (12)'s check machine: tilted, gapped, every gauge plane bowed
TILT, GAP = (0.2, 0.1, -0.15), (0.015, -0.010, 0.012)
BOW = (0.008, -0.008, 0.006, 0.008, -0.004, 0.007)
MODEL = "rho+tilt+gap+form"
LAYOUT = (*TILT_NAMES, *GAP_NAMES, *BOW_NAMES)
SIGMA, CYCLES = 0.001, 3  # 1 µm on each deviation, three cycles a round
DRHO = [f"drho_{a}" for a in "xyz"]
STEP = 1e-6  # mm: the perturbation; the linear fits respond exactly


def machine(drho: tuple[float, float, float]) -> np.ndarray:
    return np.r_[drho, 0.0, 0.0, 0.0, TILT, GAP, BOW]


FIRST_KEYS = (MIDDLES + SECOND) * CYCLES
LATER_KEYS = MIDDLES * CYCLES
FIRST_Y = deviations(FIRST_KEYS, G, machine((0.6, -0.4, 0.9)))
LATER_Y = {"v2": deviations(LATER_KEYS, G, machine((0.012, -0.006, 0.004))),
           "v3": deviations(LATER_KEYS, G, machine((-0.003, 0.002, 0.001)))}


def first(noise: np.ndarray):
    """The round that read both planes (linear method: its response is exact)."""
    return identify(list(zip(FIRST_KEYS, FIRST_Y + noise, strict=True)), G, model=MODEL,
                    method="linear", sigma=SIGMA)


def later(phase: str, noise: np.ndarray, source):
    """A verification at the middles alone, carrying ``source``'s layout and bows."""
    return joined_fit(list(zip(LATER_KEYS, LATER_Y[phase] + noise, strict=True)), G, MODEL,
                      Prior.of(source, LAYOUT), SIGMA, method="linear")


def drho(fit) -> np.ndarray:
    return np.array([fit.parameters[n] for n in DRHO])


@cache
def responses() -> dict[str, np.ndarray]:
    """Each round's Δρ̂ response (3 × deviations) to the first round's noise ("r:…")
    and to its own ("own:…"): every deviation perturbed in turn, the rounds fitted
    again as the loop fits them."""
    zero_r, zero_k = np.zeros(len(FIRST_KEYS)), np.zeros(len(LATER_KEYS))
    base = first(zero_r)
    at = {p: drho(later(p, zero_k, base)) for p in LATER_Y}
    out: dict[str, list[np.ndarray]] = {"r:m": [], "r:v2": [], "r:v3": [], "own:v2": []}
    for i in range(len(FIRST_KEYS)):
        e = zero_r.copy()
        e[i] = STEP
        fit = first(e)
        out["r:m"].append((drho(fit) - drho(base)) / STEP)
        for p in LATER_Y:
            out[f"r:{p}"].append((drho(later(p, zero_k, fit)) - at[p]) / STEP)
    for i in range(len(LATER_KEYS)):
        e = zero_k.copy()
        e[i] = STEP
        out["own:v2"].append((drho(later("v2", e, base)) - at["v2"]) / STEP)
    return {k: np.array(v).T for k, v in out.items()}


def carried(fit) -> CarriedPrior:
    """What a later round carried: the first round's fit, whole."""
    return CarriedPrior(LAYOUT, drho_gain(fit, LAYOUT), {"first": np.eye(len(LAYOUT))})


def test_the_carried_gain_gives_the_covariance_the_fits_make() -> None:
    R = responses()
    zero_r = np.zeros(len(FIRST_KEYS))
    base = first(zero_r)
    v2 = later("v2", np.zeros(len(LATER_KEYS)), base)
    v3 = later("v3", np.zeros(len(LATER_KEYS)), base)
    rows = [base.names.index(n) for n in DRHO]
    cols = [base.names.index(n) for n in LAYOUT]
    own = {"first": np.asarray(base.covariance)[np.ix_(rows, cols)]}
    prior_cov = np.asarray(base.covariance)[np.ix_(cols, cols)]

    def source_cov(a: str, b: str) -> np.ndarray:
        return prior_cov

    # (14) with the first round: its layout's own covariance with its Δρ
    exact = SIGMA**2 * R["r:v2"] @ R["r:m"].T
    formula = cross_covariance(carried(v2), None, own, source_cov)
    assert formula == pytest.approx(exact, rel=1e-6, abs=1e-15)
    # two rounds that carried the same prior share it: G_k·Σ_p·G_rᵀ
    exact = SIGMA**2 * R["r:v3"] @ R["r:v2"].T
    formula = cross_covariance(carried(v3), carried(v2), {}, source_cov)
    assert formula == pytest.approx(exact, rel=1e-6, abs=1e-15)
    # the fits' own standard errors are what their responses make
    assert np.diag(np.asarray(base.covariance)[np.ix_(rows, rows)]) == pytest.approx(
        SIGMA**2 * np.sum(R["r:m"] ** 2, axis=1), rel=1e-6)
    assert [v2.std_errors[n] ** 2 for n in DRHO] == pytest.approx(
        SIGMA**2 * (np.sum(R["r:v2"] ** 2, axis=1) + np.sum(R["own:v2"] ** 2, axis=1)),
        rel=1e-6)


def test_the_check_values_of_model_md() -> None:
    # docs/model.md, (14): on (12)'s machine the verification's Δρ̂ shares 6.10 µm² of
    # its 8.62 with the first round's 7.12: correlation 0.78 on every axis
    R = responses()
    shared = SIGMA**2 * np.sum(R["r:v2"] * R["r:m"], axis=1) * 1e6
    var_m = SIGMA**2 * np.sum(R["r:m"] ** 2, axis=1) * 1e6
    var_v = SIGMA**2 * (np.sum(R["r:v2"] ** 2, axis=1) + np.sum(R["own:v2"] ** 2, axis=1)) * 1e6
    assert shared == pytest.approx([6.10] * 3, abs=0.01)
    assert var_m == pytest.approx([7.12] * 3, abs=0.01)
    assert var_v == pytest.approx([8.62] * 3, abs=0.01)
    assert shared / np.sqrt(var_m * var_v) == pytest.approx([0.778] * 3, abs=0.001)


def test_the_joined_standard_error_is_the_joined_values() -> None:
    R = responses()
    base = first(np.zeros(len(FIRST_KEYS)))
    v2 = later("v2", np.zeros(len(LATER_KEYS)), base)
    rows = [base.names.index(n) for n in DRHO]
    cols = [base.names.index(n) for n in LAYOUT]
    own = {"first": np.asarray(base.covariance)[np.ix_(rows, cols)]}
    shared = cross_covariance(carried(v2), None, own, lambda a, b: None)
    before = joined_round(base, None, None, None)
    # the offsets written between the two rounds moved every joint as the truth says
    o0 = dict.fromkeys("xyz", 0.0)
    moved = {a: b - a0 for a, b, a0 in zip("xyz", (0.012, -0.006, 0.004), (0.6, -0.4, 0.9),
                                          strict=True)}
    gum = joined_round(v2, before, o0, moved, [shared])
    naive = joined_round(v2, before, o0, moved)
    for i, name in enumerate(DRHO):
        w_m, w_v = gum.weights[name]
        assert w_m + w_v == pytest.approx(1.0, abs=1e-12)
        # the joined value's exact response: its weights on the two rounds' responses
        response_first = w_m * R["r:m"][i] + w_v * R["r:v2"][i]
        true_se = SIGMA * math.sqrt(np.sum(response_first**2)
                                    + np.sum((w_v * R["own:v2"][i]) ** 2))
        assert gum.std_errors[name] == pytest.approx(true_se, rel=1e-6)
        # taken as independent, the same two rounds claimed a quarter less: 1.97 µm for
        # the 2.61 µm the joined value scatters by
        assert 1000 * naive.std_errors[name] == pytest.approx(1.975, abs=0.01)
        assert 1000 * true_se == pytest.approx(2.61, abs=0.01)
        # the joined value is the weighted one
        assert gum.values[name] == pytest.approx(
            w_m * (base.parameters[name] + moved[name[-1]]) + w_v * v2.parameters[name],
            abs=1e-12)


def test_the_gum_combination_of_two_estimates() -> None:
    # independent: inverse variance
    v, se, lam = joined_axis(1.0, 1.0, 0.0, 1.0, 0.0, 5.0)
    assert (v, se, lam) == pytest.approx((0.5, math.sqrt(0.5), 0.5))
    # correlated 0.6 at equal variances: the same mean, a larger standard error
    v, se, lam = joined_axis(1.0, 1.0, 0.0, 1.0, 0.6, 5.0)
    assert (v, se) == pytest.approx((0.5, math.sqrt(0.8)))
    # a noisier estimate correlated beyond its share adds nothing: λ clipped at 0
    v, se, lam = joined_axis(1.0, 1.0, 0.0, 2.0, 1.5, 5.0)
    assert (v, se, lam) == pytest.approx((1.0, 1.0, 0.0))
    # disagreement is judged on the difference's own standard error, √(se² + se_p² − 2c):
    # 2 apart is 1.4 σ of independent unit estimates, 2 / √0.4 = 3.2 σ correlated 0.8
    assert joined_axis(2.0, 1.0, 0.0, 1.0, 0.0, 3.0) is not None
    assert joined_axis(4.5, 1.0, 0.0, 1.0, 0.0, 3.0) is None
    assert joined_axis(2.0, 1.0, 0.0, 1.0, 0.8, 3.0) is None
    # the mapping form agrees, and without a covariance is inverse variance as before
    values, ses = joined_with_previous({"drho_x": 1.0}, {"drho_x": 1.0}, {"drho_x": 0.0},
                                       {"drho_x": 1.0}, {}, 5.0, {"drho_x": 0.6})
    assert (values["drho_x"], ses["drho_x"]) == pytest.approx((0.5, math.sqrt(0.8)))
