"""What one round tells the next: the axes' layout, which no offset changes
(docs/model.md, "Axes that do not meet" and "Writing the offsets back").

After a write-back only the joint offsets have changed: the tilts and the gaps
between the axes are what the earlier rounds measured too. A verification that
identifies them again from its own twelve deviations alone pays for it in its Δρ
(noise gain 2.92 under ``rho+tilt+gap`` against 1.87 under ``rho``), and that is
the figure the closed loop judges "converged" by. Here the earlier rounds' pooled
layout ℓ_p (covariance Σ_p, independent data) joins the round's own fit θ̂ = (Δρ̂,
ℓ̂) (covariance C) as what it is, a measurement of the same ℓ:

    C' = (C⁻¹ + Pᵀ·Σ_p⁻¹·P)⁻¹,     θ' = C'·(C⁻¹·θ̂ + Pᵀ·Σ_p⁻¹·ℓ_p)

(P picks ℓ out of θ): generalised least squares of the two, exact to first order
in the parameters' change. Δρ gains through its correlation with ℓ in this
round's fit, never loses: C' ≤ C.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from orthocal.geometry import Geometry
from orthocal.identification import Identification
from orthocal.measurement import deviations


def carried(own: Identification, geometry: Geometry, names: Sequence[str],
            values: np.ndarray, covariance: np.ndarray) -> Identification:
    """``own`` (a round's fit) joined with an independent measurement of its
    parameters ``names`` (``values`` with ``covariance``: the earlier rounds'
    pooled layout), module docstring. The residuals are the data's at the joined
    parameters."""
    idx = [own.names.index(n) for n in names]
    C = np.asarray(own.covariance, dtype=float)
    theta = np.array([own.parameters[n] for n in own.names])
    prior_info = np.linalg.inv(np.asarray(covariance, dtype=float))
    info = np.linalg.inv(C)
    joined_info = info.copy()
    joined_info[np.ix_(idx, idx)] += prior_info
    rhs = info @ theta
    rhs[idx] += prior_info @ np.asarray(values, dtype=float)
    cov = np.linalg.inv(joined_info)
    cov = (cov + cov.T) / 2.0
    new = cov @ rhs
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    params = {n: float(v) for n, v in zip(own.names, new, strict=True)}
    joined = replace(own, parameters=params,
                     std_errors={n: float(s) for n, s in zip(own.names, std, strict=True)},
                     covariance=cov, correlation=cov / np.outer(std, std))
    if own.method != "nonlinear":
        return joined
    model_values = deviations(list(own.keys), geometry, joined.fit_vector, own.mount_offsets)
    residuals = np.asarray(own.values) - model_values
    predicted: dict = {}
    for key, value in zip(own.keys, model_values, strict=True):
        predicted.setdefault(key, float(value))
    return replace(joined, residuals=residuals, predicted=predicted,
                   residual_rms=float(np.sqrt(np.mean(residuals**2))))
