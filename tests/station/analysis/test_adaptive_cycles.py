"""The adaptive-cycles rule's standard error (station.engine.sequencer.cycle_std_error)."""

from __future__ import annotations

import math

import numpy as np

from station.analysis.statistics import cycle_std_error


def _setup_cycles(rng: np.random.Generator, c: int, s: float) -> list[dict[str, float]]:
    """Per-cycle deviations of one two-gauge setup as the sequencer forms them:
    independent noise s at every stop, consecutive cycles sharing their Π0."""
    out: list[dict[str, float]] = [{} for _ in range(c)]
    for axis in "yz":
        z = rng.normal(0.0, s, c + 1)
        plus, minus = rng.normal(0.0, s, c), rng.normal(0.0, s, c)
        for k in range(c):
            base = 0.5 * (z[k] + z[k + 1])
            out[k][f"+x{axis}"] = 0.1 + plus[k] - base
            out[k][f"-x{axis}"] = -0.2 + minus[k] - base
    return out


def test_needs_two_cycles_and_is_zero_without_scatter() -> None:
    assert cycle_std_error([{"+xy": 0.1, "-xy": 0.2}]) == math.inf
    assert cycle_std_error([{"+xy": 0.1, "-xy": 0.2}] * 3) < 1e-12


def test_pools_the_setups_deviations() -> None:
    # +xy scatters (var 2e-6 at two cycles), -xy does not: the pool is their mean.
    cycles = [{"+xy": 0.001, "-xy": 0.0}, {"+xy": -0.001, "-xy": 0.0}]
    factor = (2 + 2 * (1 / 6)) / (2 - 2 / 6)
    assert math.isclose(cycle_std_error(cycles), math.sqrt(1e-6 * factor / 2))


def test_matches_the_scatter_of_the_mean_with_shared_pi0() -> None:
    """Over many setups, the estimate squared averages to the true variance of a
    deviation's mean over the cycles (what a setup stopping at its target needs)."""
    rng = np.random.default_rng(7)
    s = 0.002
    for c in (2, 3, 5):
        estimates, means = [], []
        for _ in range(4000):
            cycles = _setup_cycles(rng, c, s)
            estimates.append(cycle_std_error(cycles) ** 2)
            means.append(np.mean([cy["+xy"] for cy in cycles]))
        true_var = float(np.var(means))
        assert abs(np.mean(estimates) / true_var - 1.0) < 0.08, c
