"""Closed-loop calibration maths: what a correction leaves behind, and when a
further correction is worth a round (model.md, "Writing the offsets back" and
"Where the indicator plane is").

Only the joint offsets Δρ can be written to a controller. After o_i ← o_i − Δρ̂_i
the machine behaves as if its parameters were the identified ones with Δρ
zeroed: leg-length errors and axis tilts stay and still produce deviations.
A verification is judged against those predicted deviations, not against zero.
Works on parameter names, so it holds for any model (PARAM_NAMES).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from orthocal.geometry import AXES, Geometry, params_vector
from orthocal.measurement import Key, deviations

#: The parameters a controller can correct: its zero offsets (o_i ← o_i − Δρ_i).
WRITABLE: tuple[str, ...] = tuple(f"drho_{a}" for a in AXES)


def after_correction(parameters: Mapping[str, float]) -> dict[str, float]:
    """The machine's parameters once the identified Δρ are written back: the same
    parameters with every writable one zeroed."""
    return {n: (0.0 if n in WRITABLE else float(v)) for n, v in parameters.items()}


def predicted_after_correction(keys: Sequence[Key], geometry: Geometry,
                               parameters: Mapping[str, float]) -> np.ndarray:
    """Exact deviations (model (1), :func:`orthocal.deviations`) that a verification
    should show after writing the Δρ of ``parameters``: zero for a Δρ-only model,
    the signature of ΔL and tilts otherwise."""
    return deviations(keys, geometry, params_vector(after_correction(parameters)))


def significant_corrections(parameters: Mapping[str, float],
                            std_errors: Mapping[str, float | None],
                            converge_mm: float, k: float = 3.0,
                            previous_std_errors: Mapping[str, float | None] | None = None,
                            ) -> list[str]:
    """Names of the writable parameters whose value is worth writing again: beyond
    ``k`` standard errors (not noise) AND beyond ``converge_mm`` (not too small to
    matter). A missing or infinite standard error never makes a value significant.

    After a write-back the verification sees what the previous correction left,
    which is that correction's own error even on a machine the model fully explains:
    under "the previous round fixed it", a re-identified Δρ_i is distributed with
    variance se_i² + se_prev,i². ``previous_std_errors`` (the identification that
    was written) adds that term, so a correction counts only when it is more than
    the noise of both measurements: writing less would trade one noise for another.
    The previous term is at most se_i: the same experiment with the same gauges has
    the same noise, and a larger se_prev comes from misfit (misplaced stands), the
    very bias the loop is there to remove.
    """
    out = []
    for name in WRITABLE:
        if name not in parameters:
            continue
        value = abs(float(parameters[name]))
        se = _finite(std_errors.get(name))
        if se is None:
            continue
        if previous_std_errors is not None:
            prev = _finite(previous_std_errors.get(name))
            if prev is None:
                continue
            se = math.hypot(se, min(prev, se))
        if value > k * se and value > converge_mm:
            out.append(name)
    return out


def _finite(value: float | None) -> float | None:
    if value is None:
        return None
    f = float(value)
    return f if math.isfinite(f) else None
