"""What an identification's residual may be, given the noise and the budget's sources
(docs/design.md, "Uncertainty budget"): E[rᵀr] part by part beside the observed rᵀr,
so that a residual far above them says the model lacks something (the model test's
allowance reads the same sources). Pure functions, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from orthocal.budget import Source
from orthocal.geometry import Geometry
from orthocal.identification import Identification
from orthocal.noise import row_correlation
from orthocal.numbers import finite
from orthocal.sensitivities import check_geometry, estimate_gain, fit_design, rows_of


@dataclass(frozen=True)
class ExpectedLackOfFit:
    """The residual sum of squares (mm², over the fit's rows) the fit leaves and
    what noise and the budget's sources let it be (:func:`expected_lack_of_fit`)."""

    observed: float
    noise: float
    sources: dict[str, float]
    stands: float

    @property
    def expected(self) -> float:
        """E[rᵀr] from noise, the stands' prior and every source."""
        return self.noise + self.stands + sum(self.sources.values())

    @property
    def ratio(self) -> float:
        """observed / expected: ≫ 1 when noise and the stated errors cannot explain
        the residual (a model error), ≈ 1 or less when they can."""
        return self.observed / self.expected if self.expected > 0 else math.inf

    def to_dict(self) -> dict[str, Any]:
        return {"observed_rss_mm2": finite(self.observed), "noise_rss_mm2": finite(self.noise),
                "stands_rss_mm2": finite(self.stands), "expected_rss_mm2": finite(self.expected),
                "sources_rss_mm2": {n: finite(v) for n, v in self.sources.items()},
                "ratio": finite(self.ratio)}


def expected_lack_of_fit(ident: Identification, sources: Sequence[Source], sigma: float,
                         geometry: Geometry | None = None,
                         shared_zero: bool = True) -> ExpectedLackOfFit:
    """E[rᵀr] = trace((I − H)·Σ·(I − H)ᵀ) of the fit's residual r (rows
    ``ident.keys``), H = J·K its hat matrix (:func:`sensitivity`; (I − H) is the
    projector of ordinary least squares, where this is trace((I − H)Σ_B) +
    dof·σ²), Σ the rows' covariance: noise σ² (one per-cycle deviation;
    ``shared_zero``: the station's shared Π0 stops correlate the rows,
    orthocal.noise.row_correlation), each source's Σ_s expanded to the rows
    (systematic: the same in every cycle) and, with stands modelled, their prior
    J_M·σ_M²·J_Mᵀ. Each part stated apart, beside the observed rᵀr."""
    geometry = geometry or Geometry()
    check_geometry(ident, geometry)
    keys = list(ident.keys)
    J_t, J_m, lam, curvature = fit_design(ident, geometry)
    gain = estimate_gain(J_t, J_m, lam, curvature)
    A = J_t if J_m is None else np.hstack([J_t, J_m])
    R = np.eye(len(keys)) - A @ gain  # r = R·(error of the data)

    def part(cov: np.ndarray) -> float:
        return float(np.einsum("rk,kl,rl->", R, cov, R))

    distinct = list(dict.fromkeys(keys))
    P = rows_of(keys, distinct)
    by_source: dict[str, float] = {}
    for s in sources:
        if s.covariance is None:
            raise ValueError(f"source {s.name!r} states no deviation covariance")
        if list(s.keys) != distinct:
            raise ValueError(f"source {s.name!r} was built for other deviations")
        by_source[s.name] = part(P @ s.covariance @ P.T)
    stands = 0.0
    if J_m is not None and ident.stand_model is not None:
        stands = part(ident.stand_model.prior_sd**2 * (J_m @ J_m.T))
    r = np.asarray(ident.residuals)
    return ExpectedLackOfFit(observed=float(r @ r),
                             noise=part(sigma**2 * row_correlation(keys, shared_zero)),
                             sources=by_source, stands=stands)
