"""The uncertainty budget, the mathematics (orthocal.budget; docs/design.md,
"Uncertainty budget"): the legs' form in the exact measurement model and its check
values (docs/model.md, "Leg form against tilts and gaps"), the identification's
sensitivity against finite differences, the Type B sources and their GUM
combination, and the lack of fit they let the residual have."""

from __future__ import annotations

import itertools
import json
import math
from typing import Any

import numpy as np
import pytest
from builders import station_deviations

import orthocal
from orthocal import (
    MODELS,
    Geometry,
    Stands,
    bow_at,
    contact_fraction,
    deviations,
    identify,
    leg_reading,
    posture,
)
from orthocal.budget import (
    STEEL_ALPHA,
    budget_sources,
    combine,
    form_columns,
    form_covariance,
    form_vector,
    mpe_sources,
    plunger_angle_source,
    propagation,
    resolution_sources,
    sagitta_from_straightness,
    straightness_sources,
    temperature_source,
    welch_satterthwaite,
)
from orthocal.lack_of_fit import expected_lack_of_fit
from orthocal.sensitivities import key_sensitivity, sensitivity
from orthocal.stands import GAUGES

G = Geometry()
UM = 1e-3
KEYS = [(s, i, j) for s in "+-" for i in "xyz" for j in "xyz" if i != j]  # the paper's 12
TRUTH = np.r_[0.6, -0.4, 0.9, 0, 0, 0, 0, 0, 0]  # the budget's check machine: Δρ only
STANDS_MM = [3.0, -4.0, 2.5, -1.0, 4.5, -2.0]  # GAUGES order


def student_t() -> Any:
    """scipy.stats' Student t, an independent check of the budget's coverage factor
    (the station computes it with scipy.special). Imported here, not with the module:
    every test worker imports each test module to collect it, and scipy.stats costs
    a second and a half of CPU to import."""
    from scipy.stats import t

    return t


def every_plane(h: float) -> dict[tuple[str, str], float]:
    return dict.fromkeys(GAUGES, h)


def rho_fit(y: np.ndarray, keys=KEYS) -> orthocal.Identification:
    return identify(dict(zip(keys, y, strict=True)), G, "rho", "nonlinear")


# --- the leg's form in the exact measurement model ----------------------------------------


def test_a_bow_is_the_parabola_through_both_ends_of_the_leg():
    t = np.linspace(0.0, 1.0, 11)
    assert bow_at(t, 0.01) == pytest.approx(0.04 * t * (1 - t), abs=1e-17)
    assert bow_at([0.0, 0.5, 1.0], 0.01) == pytest.approx([0.0, 0.01, 0.0], abs=1e-17)


def test_the_contact_fraction_is_the_papers_mu_on_the_nominal_machine():
    L = G.leg_length
    for leg in "xyz":
        assert contact_fraction(posture("0", None, G), leg, G) == pytest.approx(0.5, abs=1e-15)
        assert contact_fraction(posture("+", leg, G), leg, G) == pytest.approx(0.5 + 60 / L,
                                                                               abs=1e-12)
        assert contact_fraction(posture("-", leg, G), leg, G) == pytest.approx(0.5 - 100 / L,
                                                                               abs=1e-12)
    # the plane is fixed to the base: an offset slides the leg under the plunger by Δρ/L
    t0 = contact_fraction(posture("0", None, G), "x", G, TRUTH[:3])
    assert t0 == pytest.approx(0.5 + 0.6 / L, abs=1e-5)
    # a stand 5 mm off L/2 moves the contact by 5/L toward P
    t0m = contact_fraction(posture("0", None, G), "x", G, mount=G.mount_plane - 5.0)
    assert t0m == pytest.approx(0.5 + 5.0 / L, abs=1e-12)


def test_a_bowed_reading_adds_the_bow_at_the_contact_and_none_is_todays_reading():
    truth = np.r_[1.2, -0.9, 0.4, 0.1, -0.2, 0.05, 0.3, -0.2, 0.1]
    rho = np.stack([posture(s, "y", G) for s in ("0", "+", "-", "+30")])
    args = ("y", "z", G, truth[:3], truth[3:6], G.mount_plane + 2.0, truth[6:])
    plain = leg_reading(rho, *args)
    assert np.array_equal(leg_reading(rho, *args, bow=None), plain)
    t = contact_fraction(rho, "y", G, truth[:3], truth[3:6], G.mount_plane + 2.0, truth[6:])
    bowed = leg_reading(rho, *args, bow=0.02)
    assert bowed - plain == pytest.approx(0.08 * t * (1 - t), abs=1e-15)


def test_bowed_deviations_are_the_bowed_readings_of_each_gauge():
    truth = np.r_[1.2, -0.9, 0.4, 0, 0, 0, 0.3, -0.2, 0.1]
    bows = {g: 0.004 * (n - 2.5) for n, g in enumerate(GAUGES)}
    offsets = np.linspace(-3, 3, len(KEYS))
    got = deviations(KEYS, G, truth, offsets, bow=bows)
    rho0 = posture("0", None, G)
    for (sign, leg, d), off, value in zip(KEYS, offsets, got, strict=True):
        args = (leg, d, G, truth[:3], truth[3:6], G.mount_plane + off, truth[6:])
        h = bows[(leg, d)]
        want = (leg_reading(posture(sign, leg, G), *args, bow=h)
                - leg_reading(rho0, *args, bow=h))
        assert value == pytest.approx(want, abs=1e-13)
    # without bows, or with no argument: today's deviations to the bit
    assert np.array_equal(deviations(KEYS, G, truth, bow=None), deviations(KEYS, G, truth))
    # a gauge not named is straight; a named gauge must be one
    only_xy = deviations(KEYS, G, truth, bow={("x", "y"): 0.01})
    moved = np.abs(only_xy - deviations(KEYS, G, truth)) > 1e-6
    assert moved.tolist() == [(k[1], k[2]) == ("x", "y") for k in KEYS]
    with pytest.raises(ValueError, match="two different axes"):
        deviations(KEYS, G, truth, bow={("x", "x"): 0.01})


def test_the_form_vector_is_the_exact_change_per_unit_sagitta():
    truth = np.r_[1.5, -1.2, 0.8, 0, 0, 0, 0.2, -0.1, 0.3]
    offsets = np.linspace(-5, 5, len(KEYS))
    g = form_vector(KEYS, G, truth, offsets)
    for h in (0.005, 0.02):
        bowed = deviations(KEYS, G, truth, offsets, bow=every_plane(h))
        assert bowed - deviations(KEYS, G, truth, offsets) == pytest.approx(h * g, abs=1e-15)
    # nominally −4(s/L)²: −0.150 at Π^+, −0.416 at Π^−
    g0 = form_vector(KEYS, G)
    L = G.leg_length
    assert g0 == pytest.approx([-4 * ((60 if k[0] == "+" else 100) / L) ** 2 for k in KEYS],
                               abs=1e-12)
    assert sagitta_from_straightness(0.266 * 0.01, (60 + 100) / L) == pytest.approx(0.01, rel=2e-3)


# --- the budget's check values ---------------------------------------------------------------

# docs/model.md, "Leg form against tilts and gaps", the check values of "What a bow does
# to rho, in closed form": rho, the 12 deviations, no noise, nonlinear, stands at L/2.


def bias_by_7(bows: dict[tuple[str, str], float]) -> tuple[np.ndarray, float]:
    """The rho fit's bias (mm per axis) and residual RMS (mm) that bows of sagitta
    ``bows`` (mm per gauge plane) make at the nominal machine, from docs/model.md alone,
    not from the code: deviation (s, i, j) moves by h_ij·e_s, e_s = −4·sin²α ("The
    second gauge plane"), and rho fits that by least squares through (7)'s columns
    b·Δρ_i + a·Δρ_j, a = sin α, b = (1/2 + sin α)·tan α ("The paper's system (7)")."""
    A, y = np.zeros((len(KEYS), 3)), np.zeros(len(KEYS))
    for row, (sign, i, j) in enumerate(KEYS):
        a = (G.rho_max if sign == "+" else G.rho_min) / G.leg_length  # sin α
        A[row, "xyz".index(i)] = (0.5 + a) * a / math.sqrt(1.0 - a * a)
        A[row, "xyz".index(j)] = a
        y[row] = -4.0 * a * a * bows[(i, j)]
    bias = np.linalg.lstsq(A, y, rcond=None)[0]
    return bias, float(np.sqrt(np.mean((y - A @ bias) ** 2)))


@pytest.mark.parametrize("h", [0.005, 0.010, 0.020])
def test_a_uniform_bow_biases_rho_as_the_closed_form_says(h):
    bias, rms = bias_by_7(every_plane(h))
    # model.md's β = 0.4294·h on every axis, residual 0.2720·h RMS (its 4 digits)
    assert bias / h == pytest.approx([0.4294] * 3, abs=5e-5)
    assert rms / h == pytest.approx(0.2720, abs=5e-5)
    # the exact model at the nominal machine: what separates it from (7) is of second
    # order in h (model.md: within 1e-3 µm; measured 7e-4 µm at 20 µm)
    r = rho_fit(deviations(KEYS, G, np.zeros(9), bow=every_plane(h)))
    assert r.vector[:3] / UM == pytest.approx(bias / UM, abs=1e-3)
    assert r.residual_rms / UM == pytest.approx(rms / UM, abs=1e-3)


# model.md's check values at Δρ = (0.6, −0.4, 0.9) mm (TRUTH), per mm of sagitta: the
# plane is fixed to the base, so the offsets slide each leg under its plungers and
# move the stops: 1-4 % under the closed form's 0.4294 on each axis.
BIAS_PER_H = (0.4222, 0.4126, 0.4249)
RESIDUAL_PER_H = 0.2717


@pytest.mark.parametrize("h", [0.005, 0.010, 0.020])
def test_bows_bias_the_offsets_as_measured_with_the_base_fixed_plane(h):
    r = rho_fit(deviations(KEYS, G, TRUTH, bow=every_plane(h)))
    # 0.01 µm: model.md rounds the coefficients to 5e-5 (0.001 µm at 20 µm), and the
    # exact model is linear in h to 0.0005 µm over 5-20 µm
    assert (r.vector[:3] - TRUTH[:3]) / UM == pytest.approx(
        [c * h / UM for c in BIAS_PER_H], abs=0.01)
    assert r.residual_rms / UM == pytest.approx(RESIDUAL_PER_H * h / UM, abs=0.01)


# Legs x and z bowed oppositely in their two planes, leg y alike: the axes' biases
# differ ((−1.68, 7.65, −1.68) µm at 10 µm by the closed form).
MIXED_BOWS = {("x", "y"): 1, ("x", "z"): -1, ("y", "x"): 1, ("y", "z"): 1,
              ("z", "x"): -1, ("z", "y"): 1}


def test_bows_of_mixed_sign_bias_rho_as_the_closed_form_says():
    # and every leg's planes opposite, its first direction (x, y, z order) +h: ±8.92 µm
    # on x and z by the closed form, none on y
    first_plus = {(i, j): 1 if j == next(d for d in "xyz" if d != i) else -1
                  for i, j in GAUGES}
    for pattern in (MIXED_BOWS, first_plus):
        bows = {g: 0.010 * s for g, s in pattern.items()}
        bias, rms = bias_by_7(bows)
        r = rho_fit(deviations(KEYS, G, np.zeros(9), bow=bows))
        assert r.vector[:3] / UM == pytest.approx(bias / UM, abs=1e-3)
        assert r.residual_rms / UM == pytest.approx(rms / UM, abs=1e-3)
    assert bias / UM == pytest.approx([8.92, 0.0, -8.92], abs=0.005)


@pytest.mark.parametrize("h", [0.005, 0.010, 0.020])
def test_the_linearised_bias_K_h_g_is_the_exact_one(h):
    straight = rho_fit(deviations(KEYS, G, TRUTH))
    _, K = key_sensitivity(straight, G)
    linear = K @ (h * form_vector(KEYS, G, straight.vector))
    exact = rho_fit(deviations(KEYS, G, TRUTH, bow=every_plane(h))).vector[:3] - TRUTH[:3]
    assert linear == pytest.approx(exact, rel=1e-3)  # measured 8e-5 at 20 µm
    # and with bows of mixed sign, where the axes differ
    bows = {g: h * s for g, s in MIXED_BOWS.items()}
    gp = form_vector(KEYS, G, straight.vector) * [bows[(k[1], k[2])] for k in KEYS]
    exact = rho_fit(deviations(KEYS, G, TRUTH, bow=bows)).vector[:3] - TRUTH[:3]
    assert K @ gp == pytest.approx(exact, rel=1e-3, abs=1e-6 * UM)


# --- the sensitivity against finite differences ----------------------------------------------


def finite_difference(r, model, step, rng, **options):
    """The change of the identified parameters for a small change ``d`` of the rows."""
    d = rng.normal(0.0, step, len(r.keys))
    again = identify(list(zip(r.keys, r.values + d, strict=True)), G, model, r.method,
                     **options)
    cols = list(MODELS[model])
    return (again.vector - r.vector)[cols], d


@pytest.mark.parametrize(("model", "method"), [("rho", "nonlinear"), ("rho+tilt", "nonlinear"),
                                               ("full", "nonlinear"), ("rho", "linear")])
def test_the_sensitivity_is_the_identifications_own_derivative(model, method):
    rng = np.random.default_rng(11)
    truth = np.r_[0.6, -0.4, 0.9, 0, 0, 0, 0.2, -0.1, 0.15] if "tilt" in model else TRUTH
    data, _ = station_deviations(truth, rng, noise=0.002, cycles=2)
    r = identify(data, G, model, method)
    K = sensitivity(r, G)
    assert K.shape == (len(r.names), len(r.keys)) == (len(MODELS[model]), 24)
    moved, d = finite_difference(r, model, 1e-4, rng)
    assert np.linalg.norm(moved - K @ d) <= 1e-3 * np.linalg.norm(moved)
    # a systematic error of a key is the same in all its cycles
    distinct, Kd = key_sensitivity(r, G)
    assert len(distinct) == 12
    assert Kd[:, 0] == pytest.approx(K[:, [k == distinct[0] for k in r.keys]].sum(axis=1))


@pytest.mark.parametrize("model", ["rho", "rho+tilt"])
def test_with_stands_modelled_the_sensitivity_still_matches(model):
    rng = np.random.default_rng(5)
    truth = np.r_[1.2, -0.9, 1.4, 0, 0, 0, 0, 0, 0]
    data, _ = station_deviations(truth, rng, noise=0.002, cycles=3, stands=STANDS_MM)
    options = {"sigma": 0.002, "stands": Stands(tolerance=5.0)}
    r = identify(data, G, model, **options)
    assert r.stand_model is not None and any(e.observable for e in r.stands.values())
    K = sensitivity(r, G)
    moved, d = finite_difference(r, model, 1e-5, rng, **options)
    assert np.linalg.norm(moved - K @ d) <= 1e-3 * np.linalg.norm(moved)  # measured ≤ 2e-5


def test_a_geometry_the_fit_was_not_made_with_is_refused():
    r = rho_fit(deviations(KEYS, G, TRUTH))
    with pytest.raises(ValueError, match="geometry"):
        sensitivity(r, Geometry(leg_length=300.0))


# --- the sources ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def fit() -> orthocal.Identification:
    data, _ = station_deviations(TRUTH, np.random.default_rng(1), noise=0.002, cycles=3)
    return identify(data, G, "rho")


def test_each_source_is_its_gum_formula(fit):
    prop = propagation(fit, G)
    keys, K = list(prop.keys), prop.K
    g = form_vector(keys, G, fit.vector)
    on = {gauge: np.array([(k[1], k[2]) == gauge for k in keys]) for gauge in GAUGES}
    # (a) one source, every plane with the worst sign (the legs may bow alike),
    # Σ |K·g_plane|·s_leg/√3
    s = 0.010
    (src,) = straightness_sources(prop, s)
    planes = [K @ (g * on[(i, j)]) for i in "xyz" for j in "xyz" if j != i]
    want = sum(np.abs(v) for v in planes) * s / math.sqrt(3)
    assert list(src.contributions.values()) == pytest.approx(want, rel=1e-12)
    assert src.u_mm == pytest.approx(s / math.sqrt(3))
    # per-leg values: [x, y, z], each leg's planes at its own
    (per_leg,) = straightness_sources(prop, [0.01, 0.0, 0.02])
    assert per_leg.inputs == {"straightness_x_mm": 0.01, "straightness_y_mm": 0.0,
                              "straightness_z_mm": 0.02}
    want = sum(np.abs(K @ (g * on[(i, j)])) * {"x": 0.01, "y": 0.0, "z": 0.02}[i]
               for i in "xyz" for j in "xyz" if j != i) / math.sqrt(3)
    assert list(per_leg.contributions.values()) == pytest.approx(want, rel=1e-12)
    # (b) and (c): sqrt(Σ K² u²) over the gauge's deviations, u = e/√3 and r/√6
    for src in mpe_sources(prop, 0.003, span_mm=None) + resolution_sources(prop, 0.001):
        gauge = (src.name[-2], src.name[-1])
        u = 0.003 / math.sqrt(3) if "MPE" in src.name else 0.001 / math.sqrt(6)
        want = np.sqrt((K[:, on[gauge]] ** 2).sum(axis=1)) * u
        assert list(src.contributions.values()) == pytest.approx(want, rel=1e-12)
    # (b) over a short travel: e in proportion to |Δ| below span_mm
    for src in mpe_sources(prop, 0.003, span_mm=0.2):
        gauge = (src.name[-2], src.name[-1])
        u = 0.003 * np.minimum(1.0, np.abs(prop.measured) / 0.2) / math.sqrt(3)
        want = np.sqrt((K[:, on[gauge]] ** 2 * u[on[gauge]] ** 2).sum(axis=1))
        assert list(src.contributions.values()) == pytest.approx(want, rel=1e-12)
    # (d) per gauge |K·(c·Δ_gauge)|/√3, in quadrature over the gauges
    c = 1 - math.cos(math.radians(3.0))
    src = plunger_angle_source(prop, 3.0)
    want = np.sqrt(sum((K @ (c * prop.measured * on[gg])) ** 2 for gg in GAUGES) / 3)
    assert list(src.contributions.values()) == pytest.approx(want, rel=1e-12)
    assert src.inputs["scale_error"] == pytest.approx(c)
    # (e) ±α·ΔT·L/2 on every deviation, independent
    src = temperature_source(prop, 2.0)
    half = STEEL_ALPHA * 2.0 * G.leg_length / 2
    assert src.value_mm == pytest.approx(half)
    want = np.sqrt((K**2).sum(axis=1)) * half / math.sqrt(3)
    assert list(src.contributions.values()) == pytest.approx(want, rel=1e-12)


def test_the_form_as_bounded_inputs_is_each_planes_bow(fit):
    """form_columns: one column K·g_p per gauge plane, bound the leg's straightness
    (rectangular, for the tool's Monte Carlo); their covariance is form_covariance's
    per-plane part, the planes' sum its shared bow; alike = 1 is that shared bow alone,
    drawn within ±s like every plane's."""
    prop = propagation(fit, G)
    s = 0.010
    b = form_columns(prop, s)
    g = form_vector(list(prop.keys), G, fit.vector)
    assert b.names == tuple(prop.names) and b.columns.shape == (len(prop.names), 6)
    for col, gauge in zip(b.columns.T, prop.gauges, strict=True):
        assert col == pytest.approx(prop.K @ (g * prop.mask(gauge)), rel=1e-12)
    assert np.all(b.bounds == s)
    per_plane = b.columns @ np.diag(b.bounds**2 / 3) @ b.columns.T
    shared = b.columns.sum(axis=1) * s / math.sqrt(3)
    assert form_covariance(prop, s) == pytest.approx(per_plane + np.outer(shared, shared),
                                                     rel=1e-12)
    alike = form_columns(prop, s, alike=1.0)
    assert np.all(alike.bounds[:6] == 0) and alike.bounds[6] == 1.0
    assert alike.columns[:, 6] == pytest.approx(b.columns.sum(axis=1) * s, rel=1e-12)
    half = form_columns(prop, [0.004, 0.010, 0.006], alike=0.5)
    legs = [gauge[0] for gauge in prop.gauges]
    assert half.bounds[:6] == pytest.approx([0.5 * {"x": 0.004, "y": 0.010, "z": 0.006}[leg]
                                             for leg in legs])
    with pytest.raises(ValueError, match="alike"):
        form_columns(prop, s, alike=1.5)


def test_a_source_given_zero_contributes_zero(fit):
    zero = budget_sources(fit, G, straightness=0.0, mpe=0.0, resolution=0.0,
                          plunger_angle_deg=0.0, temperature_change=0.0)
    assert len(zero) == 1 + 6 + 6 + 1 + 1
    assert all(v == 0.0 for src in zero for v in src.contributions.values())
    alone = combine(fit.std_errors, fit.std_error_dof, [])
    with_zero = combine(fit.std_errors, fit.std_error_dof, zero)
    for key in ("combined_mm", "effective_dof", "coverage_factor", "expanded_95_mm"):
        assert with_zero[key] == alone[key]
    assert alone["effective_dof"] == pytest.approx(dict.fromkeys(fit.names, fit.std_error_dof),
                                                   rel=1e-12)
    with pytest.raises(ValueError, match="≥ 0"):
        budget_sources(fit, G, mpe=-0.001)


def test_welch_satterthwaite_goes_from_the_type_a_dof_to_infinity(fit):
    nu_a = float(fit.std_error_dof)
    se = fit.std_errors
    dofs = []
    for s in (0.0, 0.002, 0.01, 0.05, 0.5):
        b = combine(se, nu_a, budget_sources(fit, G, straightness=s))
        dofs.append(b["effective_dof"]["drho_x"])
    assert dofs[0] == pytest.approx(nu_a, rel=1e-12)
    assert all(a < b for a, b in itertools.pairwise(dofs))
    assert dofs[-1] > 1e6 * nu_a
    # G.2b by hand: ν = u_c⁴/(u_A⁴/ν_A)
    assert welch_satterthwaite([(3.0, 10.0), (4.0, math.inf)]) == pytest.approx(
        5.0**4 / (3.0**4 / 10.0))
    assert welch_satterthwaite([(0.0, 10.0), (4.0, math.inf)]) == math.inf
    # no Type A part at all: infinite dof (null in JSON), the normal's k
    b = combine(dict.fromkeys(se, 0.0), nu_a, budget_sources(fit, G, mpe=0.003))
    assert b["effective_dof"]["drho_x"] is None
    assert b["coverage_factor"]["drho_x"] == pytest.approx(1.959964, abs=1e-6)


def test_the_expanded_uncertainty_is_k_times_the_combined(fit):
    sources = budget_sources(fit, G, straightness=[0.005, 0.010, 0.020], mpe=0.003,
                             resolution=0.001, plunger_angle_deg=2.0, temperature_change=0.5)
    b = combine(fit.std_errors, fit.std_error_dof, sources)
    json.dumps(b, allow_nan=False)  # JSON-ready
    assert [s["type"] for s in b["sources"]] == ["A"] + ["B"] * len(sources)
    assert b["sources"][0]["distribution"] == "normal"
    assert b["sources"][0]["dof"] == fit.std_error_dof
    for n in fit.names:
        uc2 = sum(s["contributions_mm"][n] ** 2 for s in b["sources"])
        assert b["combined_mm"][n] == pytest.approx(math.sqrt(uc2), rel=1e-12)
        nu = b["effective_dof"][n]
        assert nu == pytest.approx(uc2**2 / (fit.std_errors[n] ** 4 / fit.std_error_dof))
        k = b["coverage_factor"][n]
        assert k == pytest.approx(float(student_t().ppf(0.975, nu)), rel=1e-12)
        assert b["expanded_95_mm"][n] == pytest.approx(k * b["combined_mm"][n], rel=1e-12)
        assert 1.959963 < k < 2.1  # Student from above the normal's 1.959964
    # a leg's planes drive the offsets of the other axes: straighter leg z, smaller Δρ_x
    def form(straightness: list[float]) -> dict[str, float]:
        (src,) = straightness_sources(propagation(fit, G), straightness)
        return src.contributions

    assert form([0.02, 0.01, 0.005])["drho_x"] < form([0.005, 0.01, 0.02])["drho_x"]


# --- what the budget lets the residual be ------------------------------------------------------


def test_the_expected_lack_of_fit_is_dof_sigma_squared_without_sources(fit):
    sigma = 0.001
    e = expected_lack_of_fit(fit, [], sigma, G, shared_zero=False)
    assert e.noise == pytest.approx(fit.dof * sigma**2, rel=1e-9)
    assert e.sources == {} and e.stands == 0.0
    assert e.observed == pytest.approx(float(fit.residuals @ fit.residuals))


def test_the_expected_lack_of_fit_and_the_contributions_hold_in_simulation():
    """Random bows (±s per plane), MPE errors (±e per deviation, the same in both
    cycles) and noise, fitted by the linear method (linear in the data, so the
    figures are exact expectations): the mean residual sum of squares and the
    scatter of the identified Δρ against the budget's."""
    truth = np.r_[0.05, -0.03, 0.04, 0, 0, 0, 0, 0, 0]  # (7) is exact enough here
    keys = [k for k in KEYS for _ in range(2)]
    s, e, sigma = 0.010, 0.003, 0.002
    rng = np.random.default_rng(23)
    first = identify(list(zip(keys, deviations(keys, G, truth), strict=True)), G, "rho", "linear")
    # the errors drawn below are ±e on every deviation, whatever it spans
    sources = budget_sources(first, G, straightness=s, mpe=e, mpe_span_mm=None)
    expected = expected_lack_of_fit(first, sources, sigma, G, shared_zero=False)
    b = combine(first.std_errors, None, sources)
    se_a = sigma * np.sqrt(np.diag(np.linalg.inv(
        orthocal.jacobian(keys, G, "rho").T @ orthocal.jacobian(keys, G, "rho"))))
    u_b2 = np.array([b["combined_mm"][n] ** 2 - first.std_errors[n] ** 2 for n in first.names])
    rss, found = [], []
    for _ in range(2000):
        bows = {g: rng.uniform(-s, s) for g in GAUGES}
        mpe = dict(zip(KEYS, rng.uniform(-e, e, len(KEYS)), strict=True))
        y = (deviations(keys, G, truth, bow=bows) + np.array([mpe[k] for k in keys])
             + rng.normal(0, sigma, len(keys)))
        r = identify(list(zip(keys, y, strict=True)), G, "rho", "linear")
        rss.append(float(r.residuals @ r.residuals))
        found.append(r.vector[:3])
    assert np.mean(rss) == pytest.approx(expected.expected, rel=0.05)
    assert expected.noise == pytest.approx((len(keys) - 3) * sigma**2, rel=1e-9)
    # planes bowed independently here: the scatter is what their covariance gives,
    # within the budget, whose leg straightness takes each leg's planes with the
    # worst sign (one bow of unknown direction)
    prop = propagation(first, G)
    independent = np.array([sum(prop.contributions(src.covariance)[n] ** 2
                                for src in sources) for n in first.names])
    assert np.std(found, axis=0) == pytest.approx(np.sqrt(independent + se_a**2), rel=0.05)
    assert np.all(np.sqrt(independent) <= np.sqrt(u_b2) + 1e-12)


def test_with_stands_the_expected_lack_of_fit_carries_their_prior():
    rng = np.random.default_rng(5)
    truth = np.r_[1.2, -0.9, 1.4, 0, 0, 0, 0, 0, 0]
    data, _ = station_deviations(truth, rng, noise=0.002, cycles=3, stands=STANDS_MM)
    r = identify(data, G, "rho", sigma=0.002, stands=Stands(tolerance=5.0))
    e = expected_lack_of_fit(r, budget_sources(r, G, straightness=0.01), 0.002, G)
    assert e.stands > 0.0 and set(e.sources) == {"leg straightness"}
    assert e.expected == pytest.approx(e.noise + e.stands + sum(e.sources.values()))
    json.dumps(e.to_dict(), allow_nan=False)
