"""The run's uncertainty budget (docs/design.md, "Uncertainty budget"): the
config's Type B inputs, each absent one at a default named here, propagated by
orthocal.budget through the last round's identification to the run's statement,
combined with its Type A part (the scatter), and the noise the model test is to
allow for them."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Literal

import numpy as np

import orthocal
from orthocal import budget as gum
from orthocal.budget_columns import budget_columns, joint_lead_columns
from orthocal.uncertainty import Uncertainty
from station.config import StationConfig
from station.record.result import Remaining
from station.record.result_base import NotStated, Params
from station.record.result_sections import (
    BudgetInputs,
    BudgetSource,
    Instrument,
    StatedInput,
    UncertaintyBudget,
)

Statement = Literal["remaining.total", "identified"]

# Defaults where the config says nothing, each named in the budget as assumed.
# A ground steel leg straight to 10 µm over its length: good practice, not a given.
DEFAULT_LEG_STRAIGHTNESS_MM = 0.010
# Typical MPE of a 12.5 mm digital indicator with 1 µm steps (Mitutoyo ID-C, Sylvac
# S_Dial, Mahr MarCator data sheets: 3 µm); a gauge of unknown make: 5 µm.
DEFAULT_MPE_MM = {"mitutoyo": 0.003, "sylvac": 0.003, "mahr": 0.003, "generic": 0.005}
# A temperature change during a run of some minutes in a workshop, and a plunger set
# by eye against the leg's normal.
DEFAULT_TEMPERATURE_CHANGE_C = 0.5
DEFAULT_PLUNGER_ANGLE_DEG = 2.0


def inputs(config: StationConfig) -> BudgetInputs:
    """Every Type B input with its value and whether the config gave it (else the
    default above): what the budget assumed, in its own words."""
    u = config.uncertainty
    gauges = {ind.name: ind for ind in config.indicators}

    def entry(value: float | list[float] | None, default: float, why: str) -> StatedInput:
        if value is not None:
            return StatedInput(value=value, given=True)
        return StatedInput(value=default, given=False, assumed=why)

    return BudgetInputs(
        leg_straightness_mm=entry(
            u.leg_straightness_mm, DEFAULT_LEG_STRAIGHTNESS_MM,
            "good practice for a ground leg over its length, not measured "
            "([uncertainty] leg_straightness_mm)"),
        temperature_change_c=entry(
            u.temperature_change_c, DEFAULT_TEMPERATURE_CHANGE_C,
            "a workshop over a run of minutes ([uncertainty] temperature_change_c)"),
        plunger_angle_deg=entry(
            u.plunger_angle_deg, DEFAULT_PLUNGER_ANGLE_DEG,
            "plungers set by eye ([uncertainty] plunger_angle_deg)"),
        mpe_mm={name: entry(g.mpe_mm, DEFAULT_MPE_MM[g.protocol],
                            f"typical of a {g.protocol} digital indicator "
                            "([[indicators]] mpe_mm)")
                for name, g in gauges.items()},
        resolution_mm={name: StatedInput(value=g.resolution_mm, given=True)
                       for name, g in gauges.items()},
    )


def _number(stated: StatedInput) -> float:
    """An input stated as one number (all but the legs' straightness, which may be one
    per leg)."""
    assert not isinstance(stated.value, list), stated
    return float(stated.value)


def _gauge_names(config: StationConfig) -> dict[tuple[str, str], str]:
    """(leg, direction) → the indicator mounted there (its setup's)."""
    return {(sp.leg, d.lstrip("-")): name for sp in config.setups
            for name, d in sp.indicators.items()}


def _at_its_parameters(ident: orthocal.Identification, geometry: orthocal.Geometry
                       ) -> orthocal.Identification:
    """``ident`` with its residuals those of its own parameters: a fit moved to the
    middle of the joints' lost-motion bands (orthocal.lost_motion.band_middle) keeps
    the residuals of the band's edge, µm away, where its sensitivity is the same."""
    if ident.method != "nonlinear":
        return ident
    model = orthocal.deviations(list(ident.keys), geometry, ident.fit_vector, ident.mount_offsets)
    return replace(ident, residuals=np.asarray(ident.values) - model)


def _round_inputs(config: StationConfig, ident: orthocal.Identification) -> tuple[
        orthocal.Identification, BudgetInputs, dict[tuple[str, str], str],
        Callable[[dict[str, StatedInput]], dict[tuple[str, str], float]], bool]:
    """What a round's budget starts from: ``ident`` at its parameters, the config's
    inputs (:func:`inputs`), the gauge planes it read by indicator name, a stated
    input per plane, and whether the fit holds the legs' bows. Where it does (measured
    in a second gauge plane, or carried from the round that measured them:
    orthocal.carry.joined_fit) they are parameters, their uncertainty in its
    covariance: not unknown bows of ±s again."""
    ident = _at_its_parameters(ident, config.machine.geometry())
    given = inputs(config)
    planes = {plane: name for plane, name in _gauge_names(config).items()
              if any((k[1], k[2]) == plane for k in ident.keys)}

    def per_plane(table: dict[str, StatedInput]) -> dict[tuple[str, str], float]:
        return {plane: _number(table[name]) for plane, name in planes.items()}

    form_fitted = any(n in ident.names for n in orthocal.BOW_NAMES)
    return ident, given, planes, per_plane, form_fitted


def largest_first(source: BudgetSource) -> tuple[int, str]:
    """The order of a budget's sources: largest contribution first; ties (to a
    nanometre: within another CPU's last bits) by name."""
    return (-round(1e6 * max(v or 0.0 for v in source.contributions_mm.values())),
            source.source)


def stated_inputs(config: StationConfig) -> tuple[BudgetInputs, list[str], list[Instrument]]:
    """The budget's inputs (:func:`inputs`), those assumed in words, and the gauges as
    instruments: named by what identifies an instrument (its serial), not by its port."""
    given = inputs(config)
    alone = {"leg_straightness_mm": given.leg_straightness_mm,
             "temperature_change_c": given.temperature_change_c,
             "plunger_angle_deg": given.plunger_angle_deg}
    assumed = [f"{k}: {v.value} ({v.assumed})" for k, v in alone.items() if not v.given]
    assumed += [f"mpe_mm of {n}: {v.value} ({v.assumed})"
                for n, v in given.mpe_mm.items() if not v.given]
    instruments = [Instrument(name=g.name, protocol=g.protocol, serial=g.serial,
                              resolution_mm=g.resolution_mm,
                              mpe_mm=_number(given.mpe_mm[g.name])) for g in config.indicators]
    return given, assumed, instruments


def sources(config: StationConfig, ident: orthocal.Identification) -> list[gum.Source]:
    """The Type B sources of ``ident`` (a round's identification), named by the
    indicators (not by their gauge planes) where they are a gauge's."""
    ident, given, planes, per_plane, form_fitted = _round_inputs(config, ident)
    out = gum.budget_sources(
        ident, config.machine.geometry(),
        straightness=None if form_fitted else given.leg_straightness_mm.value,
        mpe=per_plane(given.mpe_mm), resolution=per_plane(given.resolution_mm),
        plunger_angle_deg=_number(given.plunger_angle_deg),
        temperature_change=_number(given.temperature_change_c))
    renamed = []
    for s in out:
        plane = s.name[-2:]
        if s.name.startswith("gauge ") and (plane[0], plane[1]) in planes:
            name = planes[(plane[0], plane[1])]
            s = replace(s, name=f"{s.name[:-3]} {name} (leg {plane[0]}, along {plane[1]})")
        renamed.append(s)
    return renamed


def round_columns(config: StationConfig, ident: orthocal.Identification, tag: str,
                  leads: Mapping[str, tuple[float, str]] | None = None) -> Uncertainty:
    """The Type B inputs of a round's identification as bounded columns over its
    parameters (orthocal.budget_columns: the legs' form labelled by gauge plane, the
    same input in every round; the rest per round, ``tag``), the config's inputs or
    their defaults (:func:`inputs`). Where the fit holds the legs' bows (a second
    gauge plane, or carried), they are parameters: no straightness column. ``leads``:
    each joint's lead bound and its name (station.analysis.joints.lead_inputs), one
    input per joint through (J4) (orthocal.budget_columns.joint_lead_columns)."""
    ident, given, planes, per_plane, form_fitted = _round_inputs(config, ident)
    straight = given.leg_straightness_mm.value
    return budget_columns(
        gum.propagation(ident, config.machine.geometry()), tag,
        straightness=None if form_fitted else straight,
        # The gauges' resolution is no systematic input here: the noise the scatter
        # measures is floored at the quantisation (station.analysis.model_choice) and
        # dithers it (GUM F.2.2.1), so the Type A part holds it.
        mpe=per_plane(given.mpe_mm), resolution=None,
        plunger_angle_deg=_number(given.plunger_angle_deg),
        temperature_change=_number(given.temperature_change_c),
        mpe_names={p: f"gauge MPE {n} (leg {p[0]}, along {p[1]})" for p, n in planes.items()},
        joint_leads={a: b for a, (b, _) in (leads or {}).items()},
        joint_names={a: name for a, (_, name) in (leads or {}).items()})


def lead_columns(config: StationConfig, ident: orthocal.Identification,
                 leads: Mapping[str, tuple[float, str]]) -> Uncertainty:
    """The joints' leads alone (``leads``: station.analysis.joints.lead_inputs) as
    bounded columns over ``ident``'s parameters, through its sensitivity (J4)
    (orthocal.budget_columns.joint_lead_columns): one input per joint, labelled by
    joint, the same in every round."""
    geometry = config.machine.geometry()
    prop = gum.propagation(_at_its_parameters(ident, geometry), geometry)
    return joint_lead_columns(prop, {a: b for a, (b, _) in leads.items()},
                              {a: name for a, (_, name) in leads.items()})


def fields(config: StationConfig, ident: orthocal.Identification,
           type_a_se: Mapping[str, float | None], type_a_dof: float | None, statement: Statement
           ) -> UncertaintyBudget | NotStated | None:
    """The run JSON's ``uncertainty_budget`` for the Δρ of ``statement`` (where the
    run states them: "remaining.total" or "identified"), from the identification
    of the round that measured them; None where the model has no Δρ."""
    se = {n: v for n, v in type_a_se.items() if n.startswith("drho_") and v is not None}
    names = list(se)
    if not names:
        return None
    try:
        srcs = sources(config, ident)
    except ValueError as exc:
        return NotStated(error=f"not stated: {exc}")
    # the budget states the Δρ; the tilts and ΔL of the model are propagated too
    trimmed = [replace(s, contributions={n: s.contributions[n] for n in names})
               for s in srcs]
    # orthocal's figures (JSON-ready, its pure maths) taken into the record's models here
    doc = gum.combine({n: float(v) for n, v in se.items()}, type_a_dof, trimmed)
    found = [BudgetSource.model_validate(s) for s in doc["sources"]]
    found = [found[0], *sorted(found[1:], key=largest_first)]
    given, assumed, instruments = stated_inputs(config)
    return UncertaintyBudget(
        statement=statement, sources=found, combined_mm=_params(doc["combined_mm"]),
        effective_dof=_params(doc["effective_dof"]),
        coverage_factor=_params(doc["coverage_factor"]),
        expanded_95_mm=_params(doc["expanded_95_mm"]), inputs=given, assumed=assumed,
        instruments=instruments,
        method=("GUM (JCGM 100:2008): each input through the sensitivity of the "
                "round's identification (stands and model included), combined in "
                "quadrature with the scatter, Welch-Satterthwaite dof, Student's "
                "k for 95 %; the legs' form as independent bows of each gauge "
                "plane (rectangular, ±straightness), the gauge MPE over the travel "
                "a deviation spans (0.2 mm, in proportion below)"
                + ("; the legs' bows are the fit's own parameters (a second gauge "
                   "plane, or carried from the round that measured it): their "
                   "uncertainty is in the scatter's part, not the straightness's"
                   if any(n in ident.names for n in orthocal.BOW_NAMES) else "")))


def _params(values: Mapping[str, float | None]) -> Params:
    """A per-parameter map of orthocal's (infinite and NaN already null), as the
    record's."""
    return {n: None if v is None else float(v) for n, v in values.items()}


def form_of_layout(config: StationConfig, ident: orthocal.Identification, names: Sequence[str]
                   ) -> tuple[np.ndarray, str] | None:
    """What the legs' form ([uncertainty] leg_straightness_mm, stated or assumed) may
    leave in the layout ``names`` as ``ident`` (the fit that gave them) identifies
    them, as a covariance over ``names`` and the words the accuracy block says it
    with; None where the fit took the bows itself (a second gauge plane) or holds
    none of ``names``."""
    held = [n for n in names if n in ident.names]
    if not held or any(n in ident.names for n in orthocal.BOW_NAMES):
        return None
    geometry = config.machine.geometry()
    given = inputs(config).leg_straightness_mm
    prop = gum.propagation(_at_its_parameters(ident, geometry), geometry)
    cov = gum.form_covariance(prop, given.value)
    idx = [list(ident.names).index(n) for n in held]
    said = "stated" if given.given else "assumed, not stated in [uncertainty]"
    return cov[np.ix_(idx, idx)], (
        f"the 95 % intervals of the after-figures carry the legs' form (straightness "
        f"{given.value} mm, {said}) as errors of the tilts and gaps: with one gauge "
        "plane per leg a uniform bow of the legs reads exactly as tilts")


def allowance(config: StationConfig, leads: Mapping[str, tuple[float, str]] | None = None
              ) -> orthocal.Allowance:
    """What the model test may excuse a misfit by (orthocal.misfit): the stated (or
    assumed) straightness as each gauge plane's bow, each gauge's MPE as a scale
    error over its travel, the plunger angle, the temperature change and each joint's
    lead (``leads``, station.analysis.joints.lead_inputs); the same inputs as the
    budget's, so the model test and the statement agree on them."""
    given = inputs(config)
    value = given.leg_straightness_mm.value
    per_leg = dict(zip(orthocal.AXES, value if isinstance(value, list) and len(value) == 3
                       else [value[0] if isinstance(value, list) else value] * 3,
                       strict=True))
    planes = _gauge_names(config)
    return orthocal.Allowance(
        straightness={plane: float(per_leg[plane[0]]) for plane in planes},
        mpe={plane: _number(given.mpe_mm[name]) for plane, name in planes.items()},
        plunger_angle_deg=_number(given.plunger_angle_deg),
        temperature_change=_number(given.temperature_change_c),
        joint_lead_um_per_m={a: b for a, (b, _) in (leads or {}).items()})


def of_run(config: StationConfig, idents: list[orthocal.Identification],
           remaining: Remaining | None) -> UncertaintyBudget | NotStated | None:
    """``uncertainty_budget`` of the run's statement: the last verification's
    (``remaining.total``: its Type A part the remaining's standard errors, from the
    run's ``remaining``) when the loop measured after its last write-back, else the
    last identification's."""
    if not idents:
        return None
    if remaining is not None:
        return fields(config, idents[-1], remaining.std_errors, remaining.std_errors_dof,
                      "remaining.total")
    return fields(config, idents[-1], dict(idents[-1].std_errors),
                  idents[-1].std_error_dof, "identified")

