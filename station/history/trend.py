"""A machine's parameters over its runs, and how fast they drift (docs/design.md,
"Machine history", ``orthocal history --plot``). Pure: from history entries to
numbers; the figure is :mod:`station.report.history_plot`'s.

The drift of a parameter is the weighted least-squares slope of its values against
the run's date, each value weighted by 1/σ². The joint errors are fitted on their
as-found values only: a run's as-left value of e = Δρ − o rests largely on the same
verification as its as-found (``remaining.total``), so fitting both would count one
measurement twice. Where the values scatter more than their standard errors say
(χ²/ν > 1: the machine does not drift in a straight line), the slope's standard
error is scaled by √(χ²/ν) and its 95 % factor taken from Student's t on ν. No
drift is stated from runs spanning less than MIN_SPAN_DAYS."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from orthocal import AXES, coverage_factor

#: A month of the drift: the mean Gregorian month, in days.
MONTH_DAYS = 30.436875

#: No drift is stated from runs that span less than this (days): a line through runs
#: minutes apart turns their noise into microns per month (two runs 35 s apart gave
#: 3.5e4 ± 1.4e5 µm/month), which says nothing of how the machine ages.
MIN_SPAN_DAYS = 7.0


#: What a point's 95 % half-width is, as the history's figure labels it: the run's
#: statement's expanded uncertainty (Type A and B); for an entry from before the
#: statement, its certificate's (the uncertainty budget's, Type A and B) or the
#: scatter's alone (k × its standard error).
BASES = ("statement", "certificate", "scatter")


@dataclass(frozen=True)
class Point:
    """One value of one parameter in one run (mm or mrad, as the entry states it)."""

    when: datetime  # the run's start (as found, measured) or end (as left)
    state: str  # "as found", "as left", or "measured" (tilts and gaps: no frame)
    value: float
    std_error: float | None  # the scatter's (Type A): what the drift weighs by
    dof: float | None
    #: a 95 % half-width the run itself states (BASES); None: k × std_error here
    interval_95: float | None = None
    basis: str = "scatter"

    @property
    def expanded_95(self) -> float | None:
        if self.interval_95 is not None:
            return self.interval_95
        return None if self.std_error is None else \
            coverage_factor(self.dof, 0.95) * self.std_error


def _basis(v: Mapping[str, Any], half: float | None) -> str:
    """BASES' word for an entry's value ``v`` whose half-width is ``half``."""
    if v.get("stated"):
        return "statement"
    return "scatter" if half is None else "certificate"


@dataclass(frozen=True)
class Drift:
    """A parameter's slope per month with its standard error and 95 % half-width."""

    per_month: float
    std_error: float
    expanded_95: float
    runs: int


def started_at(entry: Mapping[str, Any], key: str = "started") -> datetime | None:
    """The entry's start (or ``key``'s date) as an aware datetime; None if absent."""
    try:
        when = datetime.fromisoformat(str(entry.get(key)))
    except ValueError:
        return None  # a run with no date cannot be placed on the time axis
    # Runs state their zone (now_iso); one without, from an older or edited record,
    # is taken as UTC so that it can still be ordered against the others.
    return when if when.tzinfo is not None else when.replace(tzinfo=UTC)


def series(entries: Sequence[Mapping[str, Any]]) -> dict[str, list[Point]]:
    """Per parameter (``drho_x`` … for the joint errors, then the tilts and gaps
    any run identified), its points oldest first."""
    out: dict[str, list[Point]] = {f"drho_{a}": [] for a in AXES}
    for entry in entries:
        when = started_at(entry)
        if when is None:
            continue
        # As found is the machine at the run's start, as left at its end.
        left = started_at(entry, "finished") or when
        for state, key, at in (("as found", "as_found", when), ("as left", "as_left", left)):
            frame = entry.get(key) or {}
            for axis, v in (frame.get("joint_error_mm") or {}).items():
                half = v.get("expanded_95_mm")  # entries since it was kept
                dof = v["dof"] if "dof" in v else frame.get("dof")
                out[f"drho_{axis}"].append(Point(at, state, float(v["value_mm"]),
                                                 v.get("std_error_mm"), dof, half,
                                                 _basis(v, half)))
        for name, v in (entry.get("layout") or {}).items():
            half = v.get("expanded_95", v.get("interval_95"))
            out.setdefault(name, []).append(
                Point(when, "measured", float(v["value"]), v.get("std_error"), v.get("dof"),
                      half, "statement" if v.get("stated") else "scatter"))
    return {name: sorted(points, key=lambda p: p.when) for name, points in out.items()
            if points}


def _fitted(points: Sequence[Point]) -> list[Point]:
    """The points a drift is fitted to: as found (or measured), with a standard error.
    Weighted by the scatter alone (the statement's Type A part): the Type B part common
    to a machine's runs (the legs' form) moves no slope."""
    return [p for p in points if p.state != "as left" and p.std_error and p.std_error > 0]


def why_no_drift(points: Sequence[Point]) -> str | None:
    """Why no drift is stated for ``points`` (the words history and its figure
    print), or None where :func:`drift` states one."""
    fit = _fitted(points)
    if len(fit) < 2:
        return "fewer than two dated runs"
    span = max(p.when for p in fit) - min(p.when for p in fit)
    if span.total_seconds() < MIN_SPAN_DAYS * 86400.0:
        return f"runs span less than {MIN_SPAN_DAYS:g} days"
    return None


def drift(points: Sequence[Point]) -> Drift | None:
    """The weighted slope per month of the points fitted (as found, or measured),
    or None where :func:`why_no_drift` says why not (fewer than two runs with
    standard errors, or runs spanning less than MIN_SPAN_DAYS)."""
    if why_no_drift(points) is not None:
        return None
    fit = _fitted(points)
    t0 = fit[0].when
    x = [(p.when - t0).total_seconds() / 86400.0 / MONTH_DAYS for p in fit]
    # mypy does not narrow std_error through fit's filter (every one is > 0)
    w = [1.0 / p.std_error ** 2 for p in fit]  # type: ignore[operator]
    sw = sum(w)
    xm = sum(wi * xi for wi, xi in zip(w, x, strict=True)) / sw
    ym = sum(wi * p.value for wi, p in zip(w, fit, strict=True)) / sw
    sxx = sum(wi * (xi - xm) ** 2 for wi, xi in zip(w, x, strict=True))
    if sxx <= 0.0:
        return None  # cannot happen past why_no_drift; a zero divisor all the same
    slope = sum(wi * (xi - xm) * (p.value - ym)
                for wi, xi, p in zip(w, x, fit, strict=True)) / sxx
    se = math.sqrt(1.0 / sxx)
    nu = len(fit) - 2
    dof: float | None = None
    if nu > 0:
        chi2 = sum(wi * (p.value - ym - slope * (xi - xm)) ** 2
                   for wi, xi, p in zip(w, x, fit, strict=True))
        if chi2 / nu > 1.0:
            se *= math.sqrt(chi2 / nu)
            dof = float(nu)
    return Drift(slope, se, coverage_factor(dof, 0.95) * se, len(fit))
