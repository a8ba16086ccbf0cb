"""Which model the station identifies: a named one, or ``auto`` resolved by
:func:`orthocal.select_model` against the noise this very measurement shows
(docs/design.md, "Models")."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import orthocal
from orthocal import carry
from orthocal.covariance import with_measured_noise
from orthocal.geometry import BOW_NAMES
from orthocal.measurement import Key
from orthocal.noise import noise_from_cycles, noise_from_readings
from orthocal.postures import MIDDLE, split_plane
from orthocal.selection import CANDIDATES, LEVEL, ModelTest, lack_of_fit
from station.analysis.statistics import Measurement
from station.config import StationConfig
from station.errors import RunFailed
from station.record.result_base import JsonObject


def measurement_noise(config: StationConfig, m: Measurement) -> tuple[float, float, str]:
    """(σ of one per-cycle deviation, its degrees of freedom, where it comes from).

    From two cycles on, the cycle-to-cycle scatter: it holds every noise the
    deviations carry (the machine's repeatability between stops too), which the
    scatter of readings at one stop misses. With one cycle, the within-stop
    scatter. Floored at the gauges' quantisation (resolution/√12 per reading),
    so quantised data that never scatter do not claim zero noise."""
    proc = config.procedure
    data = m.for_identify()
    resolution = min(ind.resolution_mm for ind in config.indicators)
    floor = resolution / math.sqrt(12.0) * math.sqrt(1.5 / proc.readings)
    if any(len(v) >= 2 for v in data.values()):
        sigma, dof = noise_from_cycles(data)
        source = "cycle-to-cycle scatter"
    elif m.within_std and proc.readings >= 2:
        sigma, dof = noise_from_readings(m.within_std, proc.readings)
        source = "scatter of the readings at each stop"
    else:
        raise RunFailed("model auto needs the noise of the measurement, and one cycle of one "
                        "reading per stop shows none: set [procedure] cycles >= 2 (or "
                        "readings >= 2), or name a model")
    if sigma < floor:
        sigma, source = floor, source + ", floored at the gauge resolution"
    return sigma, dof, source


def second_plane(keys) -> bool:
    """Whether any deviation was read in a second gauge plane (SetupConfig.at)."""
    return any(split_plane(k[0])[1] != MIDDLE for k in keys)


def planned_second_plane(config: StationConfig) -> bool:
    """Whether the plan reads any gauge in a second plane (SetupConfig.at)."""
    return any(setup.at != MIDDLE for setup in config.setups)


def with_form(model: str, keys) -> str:
    """``model`` with the legs' bows fitted beside it (orthocal.FORM) where the
    gauges were read in a second plane: the bows are then measured, not assumed."""
    if model.endswith(orthocal.FORM) or model == "auto" or not second_plane(keys):
        return model
    return model + orthocal.FORM


def carried_form(config: StationConfig, m: Measurement,
                 first: orthocal.Identification) -> orthocal.Identification | None:
    """A pass measured at the legs' middles alone after the ``first`` round that read
    a second gauge plane and fitted the legs' bows (station.plan.steps.Plan.setups_of:
    the run's second pass): that round's model fitted to this pass's data joined with
    what no offset changes, that round's tilts, gaps, leg lengths and bows with their
    joint covariance (orthocal.carry.joined_fit: the
    middles alone take a uniform bow for a tilt, and carried as fitted apart, the
    bows' strong correlation with the tilts would be lost). Standard errors from the
    noise this measurement shows (with_measured_noise). None where it does not
    apply: the verification is identified on its own (identify_measurement)."""
    data = m.for_identify()
    if second_plane(data) or not second_plane(first.keys) \
            or not first.model.endswith(orthocal.FORM):
        return None
    proc, geometry = config.procedure, config.machine.geometry()
    prior = carry.Prior.of(first, [n for n in first.names if not n.startswith("drho_")])
    try:
        noise: tuple[float, float, str] | None = measurement_noise(config, m)
    except RunFailed:
        noise = None
    # without a noise estimate, the gauges' quantisation weighs the data
    floor = min(ind.resolution_mm for ind in config.indicators) / math.sqrt(12.0)
    try:
        ident = carry.joined_fit(data, geometry, first.model, prior,
                                 noise[0] if noise else floor, method=proc.method)
    except orthocal.IdentificationError as exc:
        raise RunFailed(f"identification failed: {exc}") from None
    if noise is None:
        return ident
    return with_measured_noise(ident, geometry, noise[0], noise_dof=noise[1])


def identify_measurement(config: StationConfig, m: Measurement,
                         model: str | None = None,
                         leads: Mapping[str, tuple[float, str]] | None = None
                         ) -> tuple[orthocal.Identification, JsonObject | None]:
    """The identification of ``m`` with ``model`` (default: the config's) and, for
    auto, the selection's JSON (the run JSON's ``model_selection``). ``leads``: the
    joints' leads the model test may excuse a misfit by, within their bounds
    (station.analysis.joints.lead_inputs; ``m``'s deviations already corrected for
    the joints' tables, station.analysis.joint_fit).

    Standard errors: from the noise this measurement shows, with the correlation
    its shared Π0 stops give the deviations (orthocal.covariance.with_measured_noise:
    honest where ordinary least squares is ~10-20 % off), inflated by √F when the
    model leaves more than that noise (so a model the data reject does not look
    precise). Without a noise estimate (one cycle of one reading), the fit's own."""
    proc = config.procedure
    data = m.for_identify()
    model = with_form(model or proc.model, data)
    geometry = config.machine.geometry()
    try:
        noise = measurement_noise(config, m)
    except RunFailed:
        if model == "auto":
            raise
        noise = None
    selection = None
    # Misplaced stands are modelled so that they are not taken for tilted axes
    # (orthocal.stands); the linearised system (7) has no stand effect.
    stands = orthocal.Stands(tolerance=proc.stand_tolerance_mm,
                             mounts=m.mounts_for_identify() or None) \
        if proc.stand_tolerance_mm > 0 and proc.method == "nonlinear" else None
    try:
        if model != "auto":
            ident = orthocal.identify(data, geometry, model=model, method=proc.method,
                                      sigma=noise[0] if noise and stands else None,
                                      stands=stands if noise else None)
            test = lack_of_fit(ident, geometry, noise[0], noise[1]) if noise else None
        else:
            assert noise is not None  # auto: measurement_noise's failure raised above
            sigma, dof, source = noise
            # The model test excuses what the stated leg form and gauge errors can
            # make, within their bounds and with their shapes (orthocal.misfit): a
            # bowed leg does not buy tilts, and a gap is not taken for a bow.
            from station.analysis.run_budget import allowance

            allowed = allowance(config, leads)
            candidates = [with_form(c, data) for c in CANDIDATES]
            sel = orthocal.select_model(data, geometry, sigma, dof, candidates=candidates,
                                        method=proc.method, stands=stands,
                                        noise_source=source, allowance=allowed)
            ident, selection = sel.identification, sel.to_dict()
            selection["allowance"] = {
                **allowed.to_dict(),
                "note": ("a misfit is excused only by what the stated leg form (a bow per "
                         "gauge plane within the straightness), gauge errors (a scale "
                         "within the MPE), temperature and the joints' leads (within "
                         "their bounds, (J4)) can make, with the shape each makes; the "
                         "test keeps the measured noise's degrees of freedom")}
    except orthocal.IdentificationError as exc:
        raise RunFailed(f"identification failed: {exc}") from None
    if noise is not None and selection is not None:
        # the statement's inflation: the misfit beyond the noise alone
        test = lack_of_fit(ident, geometry, noise[0], noise[1])
    # A pass at the middles of a plan that reads a second gauge plane in another pass
    # (station.plan.steps.Plan.setups_of) does not claim the bows: there a uniform bow
    # is a tilt, and the pass that reads both planes measures them.
    if noise is not None and test is not None and _rejected(test) \
            and not (planned_second_plane(config) and not second_plane(data)):
        ident, test = measured_form(config, data, ident, noise, stands, test,
                                    tilts_possible=model == "auto", leads=leads)
    if noise is not None:
        inflate = 1.0
        if test is not None and _rejected(test):
            inflate = math.sqrt(test.F or 1.0)
        ident = with_measured_noise(ident, geometry, noise[0], inflate=inflate,
                                    noise_dof=noise[1])
    return ident, selection


def _rejected(test: ModelTest) -> bool:
    """Whether the plain lack-of-fit test rejects the model: a misfit beyond the noise."""
    return (test.F is not None and test.p_value is not None and test.p_value < LEVEL
            and test.F > 1.0)


def form_identifiable(model: str, keys: Iterable[Key], geometry: orthocal.Geometry) -> bool:
    """Whether ``model`` with one bow per gauge plane beside it is identifiable from the
    distinct deviations ``keys`` (docs/model.md, "Leg form in the loop"): yes for rho at
    the legs' middles, never where tilts are kept there (a uniform bow is a tilt)."""
    from orthocal import design

    distinct = list(dict.fromkeys(keys))
    q = design.quality(distinct, geometry, model + orthocal.FORM)
    return q.rank == len(q.names)


def measured_form(config: StationConfig, data, ident: orthocal.Identification,
                  noise: tuple[float, float, str], stands: orthocal.Stands | None,
                  test: ModelTest, tilts_possible: bool = True,
                  leads: Mapping[str, tuple[float, str]] | None = None
                  ) -> tuple[orthocal.Identification, ModelTest]:
    """Where ``ident``'s model leaves a misfit beyond the noise that the stated leg
    form excuses (the test with [uncertainty]'s allowance passes) and the bows can be
    told apart from the model's parameters on these stops, the bows fitted beside it:
    the identification and its plain lack-of-fit test (``test``: ``ident``'s). A bow is a
    systematic error of the same shape in every round, so counted as a scatter it
    inflates every standard error by √F, which no cycle shrinks, and leaves Δρ off by
    0.43·h (rho, docs/model.md); fitted, Δρ is free of it and its error is the noise's.

    Unless the axes' tilts explain the same misfit as well (the model with tilts
    passes against the noise alone), where they are possible (``tilts_possible``:
    model auto; a model the operator named without tilts says the axes are square):
    at the legs' middles a uniform bow is a tilt, and the data cannot say which the
    machine has. Then the tilts' fit is returned (the
    rigid geometry, whose budget carries the stated straightness through its
    sensitivity), marked with how far the bows' explanation puts each parameter
    (``ambiguity_mm``): no verdict may claim more than that allows (docs/model.md,
    "Tilts or bows"). Otherwise ``ident`` and ``test`` unchanged."""
    from station.analysis.run_budget import allowance

    geometry = config.machine.geometry()
    model = ident.model
    if model.endswith(orthocal.FORM) or not form_identifiable(model, data, geometry):
        return ident, test
    excused = lack_of_fit(ident, geometry, noise[0], noise[1],
                          allowance=allowance(config, leads))
    if excused.p_value is None or excused.p_value < LEVEL:
        return ident, test  # more than the stated form can make: not the form
    fitted = _fit(config, data, model + orthocal.FORM, noise, stands)
    if fitted is None:
        return ident, test
    tilted = _fit(config, data, with_tilts(model), noise, stands) if tilts_possible else None
    if tilted is not None:
        tilt_test = lack_of_fit(tilted, geometry, noise[0], noise[1])
        if not _rejected(tilt_test):
            if bows_stated(fitted, allowance(config).straightness):
                return ambiguous(tilted, fitted), tilt_test
            return tilted, tilt_test  # bows beyond the stated form: the axes lean
    return fitted, lack_of_fit(fitted, geometry, noise[0], noise[1])


def bows_stated(bowed: orthocal.Identification,
                straightness: Mapping[tuple[str, str], float]) -> bool:
    """Whether the bows of ``bowed`` (a fit with the legs' bows) lie within the stated
    straightness of their gauge planes (the sagitta bound, mm; a plane not named is
    straight), beyond it by no more than their noise (k standard errors at the model
    test's LEVEL, two-sided): only then do the bows explain what the tilts do (docs/
    model.md, "Tilts or bows"). Bows 2–3 µm on legs stated straight to 0.5 µm are
    no explanation of the data, and a tilt they would mimic is the axes'."""
    from scipy.special import ndtri  # the normal quantile

    k = float(ndtri(1.0 - LEVEL / 2))
    for name in BOW_NAMES:
        if name not in bowed.parameters:
            continue
        se = bowed.std_errors.get(name)
        if se is None or not math.isfinite(se):
            return True  # no noise to judge it by: the data cannot rule the bows out
        bound = float(straightness.get((name[-2], name[-1]), 0.0))
        if abs(bowed.parameters[name]) > bound + k * se:
            return False
    return True


def with_tilts(model: str) -> str:
    """``model`` with the axes' tilts ("rho+gap" → "rho+tilt+gap"); itself if it has
    them."""
    parts = model.split("+")
    if "tilt" in parts:
        return model
    return "+".join([parts[0], "tilt", *parts[1:]])


def ambiguous(tilted: orthocal.Identification,
              bowed: orthocal.Identification) -> orthocal.Identification:
    """``tilted`` where ``bowed`` explains the same data as well (the legs' bows for
    the axes' tilts), with the Δρ whose worst error over the two explanations is least,
    their midpoint: what the round states and the loop writes (docs/model.md, "Tilts or
    bows"). Marked with how far the explanations lie from the values stated, per
    parameter both hold (``ambiguity_mm``: half their distance for Δρ, all of it for
    the others, which keep the tilts' fit): what the data cannot decide, which every
    interval adds to its half-width."""
    from dataclasses import replace

    from orthocal.loop import WRITABLE

    shared = [n for n in tilted.names if n in bowed.parameters]
    params = dict(tilted.parameters)
    apart = {}
    for n in shared:
        t, b = tilted.parameters[n], bowed.parameters[n]
        if n in WRITABLE:
            params[n], apart[n] = 0.5 * (t + b), 0.5 * abs(t - b)
        else:
            apart[n] = abs(t - b)
    return replace(tilted, parameters=params, ambiguous_with=bowed.model, ambiguity_mm=apart)


def _fit(config: StationConfig, data, model: str, noise: tuple[float, float, str],
         stands: orthocal.Stands | None) -> orthocal.Identification | None:
    """``model`` fitted to ``data`` as the round's own fit was; None if it cannot be."""
    try:
        return orthocal.identify(data, config.machine.geometry(), model=model,
                                 method=config.procedure.method,
                                 sigma=noise[0] if stands else None, stands=stands)
    except orthocal.IdentificationError:
        return None
