"""The Type B inputs of an identification as bounded columns (orthocal.uncertainty):
each physical input uniform in ±1, acting on the identified parameters through the
fit's sensitivity K (orthocal.budget.propagation; docs/model.md, "The statement's
uncertainty").

The same sources as the budget's (orthocal.budget: leg straightness, gauge MPE,
gauge resolution, plunger angle, temperature), with the same models, but kept as
what they are (bounded inputs with a shape) instead of a variance per parameter, so
that one input seen by two fits (the legs' bows by the last round's Δρ and by the
round that gave the axes' layout) stays one input, and a statement about several
parameters (squareness, the tool's field) carries their correlation:

- leg straightness: each gauge plane bowed within ±s, half of it a bow common to every
  plane (the legs of one machine are made alike, and a uniform bow is exactly a tilt
  signature at the legs' middles) and half its own (:data:`ALIKE`), so that no plane
  bows beyond its bound; labelled by plane, so the same input in every round;
- gauge MPE: each deviation off by ±e_k (e over the span of the deviation, in
  proportion below MPE_SPAN_MM), per round;
- gauge resolution: triangular ±r per deviation, two uniform inputs of ±r/2;
- plunger angle: a gauge's deviations scaled by ±(1 − cos θ), per gauge and round;
- temperature: each deviation off by ±α·ΔT·L/2, per round;
- a joint's lead: each joint's positioning error a lead within ±b µm/m from Π0 (an
  assumed joint's bound, or what a table's own uncertainty leaves of its lead),
  through what a lead does to the deviations, (J4): one input per joint, labelled by
  joint, so the same input in every round (docs/model.md, "The identification with
  joint tables").

Pure, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from orthocal.budget import (
    MPE_SPAN_MM,
    STEEL_ALPHA,
    Gauge,
    Propagation,
    form_vector,
    non_negative,
    per_name,
)
from orthocal.geometry import AXES
from orthocal.joint_error import lead_deviation_change
from orthocal.uncertainty import Uncertainty, combined, type_b

#: The budget's source names (orthocal.budget), so that a statement's basis and the
#: budget table say the same.
STRAIGHTNESS, TEMPERATURE, ANGLE = "leg straightness", "temperature", "plunger angle"


def _per_leg(straightness: float | Sequence[float] | Mapping[str, float]
             ) -> dict[str, float]:
    if isinstance(straightness, Mapping):
        return {a: non_negative(straightness[a], "leg straightness") for a in straightness}
    if isinstance(straightness, Sequence) and not isinstance(straightness, str):
        if len(straightness) != len(AXES):
            raise ValueError(f"leg straightness: one value or [x, y, z], got {straightness!r}")
        return {a: non_negative(v, "leg straightness")
                for a, v in zip(AXES, straightness, strict=True)}
    return dict.fromkeys(AXES, non_negative(float(straightness), "leg straightness"))


def _key_name(key: tuple[str, str, str]) -> str:
    sign, leg, direction = key
    return f"{sign}{leg}{direction}"


#: The share of each plane's stated bow common to every plane (the legs of one machine
#: are made alike): each plane bows by s·(ALIKE·u_0 + (1 − ALIKE)·u_p), u_0 common, u_p
#: its own, both uniform in ±1, so that no plane bows beyond its stated bound s and the
#: planes' bows correlate (0.5 at ALIKE = 1/2; orthocal.budget.form_columns' ``alike``).
ALIKE = 0.5


def straightness_columns(prop: Propagation,
                         straightness: float | Sequence[float] | Mapping[str, float]
                         ) -> Uncertainty:
    """The legs' form: a bow common to every plane and one of each plane's own (module
    docstring, :data:`ALIKE`), each column K·g_p·s times its share over the
    parameters."""
    s_of = _per_leg(straightness)
    g = form_vector(prop.keys, prop.geometry, prop.params, prop.mount_offsets)
    planes = prop.gauges
    whole = [prop.K @ (g * prop.mask(p) * s_of[p[0]]) for p in planes]
    per_plane = [(1.0 - ALIKE) * w for w in whole]
    shared = ALIKE * sum(whole, np.zeros(len(prop.names)))
    cols = np.column_stack([shared, *per_plane]) if planes else np.zeros((len(prop.names), 0))
    labels = ["straightness:shared", *(f"straightness:{''.join(p)}" for p in planes)]
    return type_b(prop.names, cols, labels, [STRAIGHTNESS] * len(labels))


def mpe_columns(prop: Propagation, mpe: float | Mapping[Gauge, float], tag: str,
                names: Mapping[Gauge, str], span_mm: float | None = MPE_SPAN_MM
                ) -> Uncertainty:
    """Each gauge's MPE: one input per deviation it measures, ±e over the span the
    deviation covers (in proportion below ``span_mm``). ``names``: the source's name
    per gauge (the budget names the indicator)."""
    values = per_name(mpe, prop.gauges, "gauge MPE")
    scale = np.ones(len(prop.keys)) if span_mm is None else \
        np.minimum(1.0, np.abs(prop.measured) / span_mm)
    cols, labels, sources = [], [], []
    for k, key in enumerate(prop.keys):
        gauge = (key[1], key[2])
        col = np.zeros(len(prop.keys))
        col[k] = values[gauge] * scale[k]
        cols.append(prop.K @ col)
        labels.append(f"mpe:{tag}:{_key_name(key)}")
        sources.append(names.get(gauge, f"gauge MPE {''.join(gauge)}"))
    return _stack(prop, cols, labels, sources)


def resolution_columns(prop: Propagation, resolution: float | Mapping[Gauge, float], tag: str,
                       names: Mapping[Gauge, str]) -> Uncertainty:
    """Each deviation is the difference of two readings quantised by ±r/2: two
    uniform inputs of ±r/2 (their sum triangular ±r)."""
    values = per_name(resolution, prop.gauges, "gauge resolution")
    cols, labels, sources = [], [], []
    for k, key in enumerate(prop.keys):
        gauge = (key[1], key[2])
        col = np.zeros(len(prop.keys))
        col[k] = values[gauge] / 2.0
        for end in ("a", "b"):
            cols.append(prop.K @ col)
            labels.append(f"resolution:{tag}:{_key_name(key)}:{end}")
            sources.append(names.get(gauge, f"gauge resolution {''.join(gauge)}"))
    return _stack(prop, cols, labels, sources)


def angle_columns(prop: Propagation, angle_deg: float, tag: str) -> Uncertainty:
    """A plunger θ off its direction reads cos θ of the travel: each gauge's
    deviations scaled by ±(1 − cos θ), one input per gauge."""
    c = 1.0 - math.cos(math.radians(non_negative(angle_deg, "plunger angle")))
    cols = [prop.K @ (c * prop.measured * prop.mask(g)) for g in prop.gauges]
    labels = [f"angle:{tag}:{''.join(g)}" for g in prop.gauges]
    return _stack(prop, cols, labels, [ANGLE] * len(cols))


def temperature_columns(prop: Propagation, temperature_change: float, tag: str,
                        alpha: float = STEEL_ALPHA) -> Uncertainty:
    """A leg grows by α·ΔT·L at an unknown time between the Π0 stops around a
    reading: each deviation off by ±α·ΔT·L/2, one input per deviation."""
    half = alpha * non_negative(temperature_change, "temperature change") \
        * prop.geometry.leg_length / 2.0
    cols = [prop.K[:, k] * half for k in range(len(prop.keys))]
    labels = [f"temperature:{tag}:{_key_name(key)}" for key in prop.keys]
    return _stack(prop, cols, labels, [TEMPERATURE] * len(cols))


def joint_lead_columns(prop: Propagation, bounds_um_per_m: Mapping[str, float],
                       names: Mapping[str, str] | None = None) -> Uncertainty:
    """Each joint's lead within ±b (µm/m, by axis; 0: left out): its deviations change
    by (J4) of a lead b on that joint alone (orthocal.lead_deviation_change), through
    the fit's sensitivity K. ``names``: the source's name per joint."""
    cols, labels, sources = [], [], []
    for i, axis in enumerate(AXES):
        b = non_negative(bounds_um_per_m.get(axis, 0.0), f"joint {axis}'s lead bound")
        if b == 0.0:
            continue
        lead = np.zeros(3)
        lead[i] = b
        cols.append(prop.K @ lead_deviation_change(prop.keys, prop.geometry, lead))
        labels.append(f"joint lead:{axis}")
        sources.append((names or {}).get(axis, f"joint {axis} lead"))
    return _stack(prop, cols, labels, sources)


def _stack(prop: Propagation, cols: Sequence[np.ndarray], labels: Sequence[str],
           sources: Sequence[str]) -> Uncertainty:
    matrix = np.column_stack(cols) if cols else np.zeros((len(prop.names), 0))
    return type_b(prop.names, matrix, labels, sources)


def budget_columns(prop: Propagation, tag: str, *,
                   straightness: float | Sequence[float] | Mapping[str, float] | None,
                   mpe: float | Mapping[Gauge, float] | None,
                   resolution: float | Mapping[Gauge, float] | None,
                   plunger_angle_deg: float | None, temperature_change: float | None,
                   mpe_names: Mapping[Gauge, str] | None = None,
                   resolution_names: Mapping[Gauge, str] | None = None,
                   alpha: float = STEEL_ALPHA,
                   joint_leads: Mapping[str, float] | None = None,
                   joint_names: Mapping[str, str] | None = None) -> Uncertainty:
    """Every Type B input given (None: left out) as columns over ``prop.names``;
    ``tag`` names the round, so that inputs of separate rounds stay separate and the
    legs' form and the joints' leads (labelled without it) stay one input each.
    ``joint_leads``: each joint's lead bound (µm/m, :func:`joint_lead_columns`)."""
    parts = []
    if straightness is not None:
        parts.append(straightness_columns(prop, straightness))
    if mpe is not None:
        parts.append(mpe_columns(prop, mpe, tag, mpe_names or {}))
    if resolution is not None:
        parts.append(resolution_columns(prop, resolution, tag, resolution_names or {}))
    if plunger_angle_deg is not None:
        parts.append(angle_columns(prop, plunger_angle_deg, tag))
    if temperature_change is not None:
        parts.append(temperature_columns(prop, temperature_change, tag, alpha))
    if joint_leads:
        parts.append(joint_lead_columns(prop, joint_leads, joint_names))
    return combined(parts, prop.names)
