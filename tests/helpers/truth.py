"""Checking a simulated run against its hidden truth (imported by the tests)."""

from __future__ import annotations

from orthocal import coverage_factor

# Tests that compare a simulated run with its hidden truth use the station's own
# statement, so they test its honesty rather than a bound picked to pass: the truth
# is ``remaining.total`` (the correction applied plus what the last verification
# found left, not written) within k of its standard errors, k from Student's t on the dof behind
# them. At coverage 1 − 1e-4 per value an honest station fails such a check about
# once in 3000 runs of three axes. The check is coarse by design (standard errors a
# quarter of the true ones fail it in most runs, half only in one run of 15): the
# fine measure of honesty is bench/station_accuracy.py over many seeds. It is
# one-sided by nature: one run cannot show its standard errors too large. That side
# is tested over seeded runs of the pure maths, where the spread of the estimates
# must match the stated errors from both sides (tests/orthocal/test_stands.py, the station's
# default statement; tests/orthocal/test_selection.py, the measured noise without stands).
TRUTH_COVERAGE = 1.0 - 1e-4


def truth_miss(result: dict, truth: dict[str, float],
               coverage: float = TRUTH_COVERAGE) -> dict[str, str]:
    """Which of ``truth`` (parameter name → value) lie outside the run's statement,
    each with the numbers (empty: all inside). Raises if the run states no
    standard error or dof for a name: a missing figure is a failure too."""
    rem = result.get("remaining") or {}
    misses = {}
    for name, value in truth.items():
        if name in (rem.get("total") or {}):
            centre = rem["total"][name]
            se, dof = rem["std_errors"][name], rem["std_errors_dof"]
        else:
            centre = result["identified"][name]
            se, dof = result["std_errors"][name], result["std_errors_dof"]
        assert se is not None and dof is not None, f"{name}: no standard error or dof"
        k = coverage_factor(dof, coverage)
        if abs(centre - value) > k * se:
            misses[name] = (f"{centre:+.5f} vs truth {value:+.5f}: {abs(centre - value) / se:.2f}"
                            f" SE > k = {k:.2f} ({dof:g} dof)")
    return misses


def assert_truth(result: dict, truth: dict[str, float]) -> None:
    """The truth lies within the run's own statement (:func:`truth_miss`)."""
    misses = truth_miss(result, truth)
    assert not misses, misses


def drho(values: tuple[float, float, float]) -> dict[str, float]:
    return {f"drho_{a}": v for a, v in zip("xyz", values, strict=True)}
