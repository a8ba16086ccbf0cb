"""Which model the station identifies: a named one, or ``auto`` resolved by
:func:`orthocal.select_model` against the noise this very measurement shows
(design.md, "Models")."""

from __future__ import annotations

import math
from typing import Any

import orthocal
from orthocal.selection import noise_from_cycles, noise_from_readings
from station.config import StationConfig
from station.errors import RunFailed
from station.sequencer import Measurement


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


def identify_measurement(config: StationConfig, m: Measurement,
                         model: str | None = None) -> tuple[Any, dict[str, Any] | None]:
    """The identification of ``m`` with ``model`` (default: the config's) and, for
    auto, the selection's JSON (the run JSON's ``model_selection``)."""
    proc = config.procedure
    model = model or proc.model
    geometry = config.machine.geometry()
    try:
        if model != "auto":
            return orthocal.identify(m.for_identify(), geometry, model=model,
                                     method=proc.method), None
        sigma, dof, source = measurement_noise(config, m)
        sel = orthocal.select_model(m.for_identify(), geometry, sigma, dof,
                                    method=proc.method, noise_source=source)
    except orthocal.IdentificationError as exc:
        raise RunFailed(f"identification failed: {exc}") from None
    return sel.identification, sel.to_dict()
