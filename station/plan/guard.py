"""The plunger guard: what no plan can know.

The plan check keeps every plunger inside its stroke for the nominal machine.
The real machine adds the signal itself (the travel its offsets cause: up to
millimetres before calibration), and the gauge may sit with less preload or a
shorter stroke than configured. So during the moves of a mounting's first
cycle the mounted gauges are read while the axes move, and the axes stopped
(COMMAND 2) before a plunger comes within ``plunger_margin_mm`` of either end
of its stroke; later cycles of that mounting are predicted from what the
first one showed and refused before moving if they would come that close.

Travel is counted from the mounting point (the reading at the mounting's
first Π0), + pushed in; the stroke spans −preload .. stroke − preload.

Prediction while moving. Plunger travel = nominal travel + signal (measured −
nominal; a smooth function of the joint positions). The guard models no drive:
the nominal travel still ahead is bounded over every position the axes may
pass through from where they are (station.plan.motion: the box from here to the
sub-move's target for independent axes, then the later sub-moves' boxes), the
same bound the plan check used. At each poll the positions are read just
before and just after the gauges; the signal is measured where the nominal
travel is flat over the box of that window, and elsewhere (on a fast swing the
gauge's sampling instant would matter) only kept within what the reading
allows over that box, so that a knocked stand still shows at once. Ahead, the
signal is carried along the move's progress at the slope seen so far (median of
the samples' slopes, once 15 % of the move is done); the axes are stopped when
nominal bound + signal, or the measured travel itself, comes within the margin.

A stop is a second line, not the end: the trip
(:class:`station.engine.guard_monitor.PlungerGuardTrip`) carries what the sequencer
needs to re-plan from where the machine stands
(:meth:`~station.engine.guard_monitor.GuardMonitor.signal_envelope`): more waypoints,
a lower speed, the cycle's readings taken again. Later cycles route their moves with
the signal the first cycle measured at each stop
(:meth:`~station.engine.guard_monitor.GuardMonitor.route_signal`).

Here the prediction, pure: what the guard tracks per gauge and per move, the
signal's slope, the travel still ahead, what later cycles will do. The monitor
that reads the gauges and stops the axes is the engine's (station.engine.guard_monitor).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from station.plan.steps import REVERSAL

# The signal at a move's target is extrapolated from the part done once this
# fraction of the move is behind: a reading's noise (µm) and the sampling skew
# (tens of µm) grow by 1/progress.
MIN_PROGRESS = 0.15


@dataclass
class GuardedGauge:
    name: str
    direction: str
    low: float  # −preload
    high: float  # stroke − preload
    baseline: float  # the reading at the mounting point
    signal: float = 0.0
    seen: tuple[float, float] = (0.0, 0.0)
    start_signal: float = 0.0  # at the stop the current move started from
    end_signal: float = 0.0  # predicted at the move's target by the last poll
    prior_slope: float = 0.0  # the signal's change over the move, as it was routed
    leg_signal: float = 0.0  # where the sub-move in progress began
    rest_nominal: float = 0.0  # nominal travel where the last at_rest was taken
    samples: list[tuple[float, float]] = field(default_factory=list)  # (progress, Δsignal)


@dataclass
class MoveRecord:
    label: str
    travel: dict[str, tuple[float, float]] = field(default_factory=dict)
    nominal: dict[str, tuple[float, float]] = field(default_factory=dict)
    polls: int = 0
    # stopped by the guard, or re-planned after a stop (from where a plunger stood
    # inside the margin, or the way back): a path later cycles do not take
    off_route: bool = False


def signal_slope(g: GuardedGauge) -> float:
    """d(signal)/d(progress) from the samples once enough of the move is done
    (a reading's noise and the sampling skew grow by 1/progress); the median
    of the samples' slopes, so one knocked reading does not swing it. Before
    that, the slope the move was routed with (0 where nothing is known)."""
    slopes = [d / u for u, d in g.samples if u >= MIN_PROGRESS]
    return float(np.median(slopes)) if slopes else g.prior_slope


def travel_ahead(travel: float, signal: float, slope: float, u: float,
                 ahead: Sequence[tuple[tuple[float, float], tuple[float, float]]]
                 ) -> tuple[float, float]:
    """A gauge's plunger travel from now to the move's end (lo, hi): the measured
    ``travel``, and over each stretch still ahead (its nominal bound, its span of
    progress) the nominal bound plus the signal carried from ``signal`` at progress
    ``u`` at ``slope``."""
    lo, hi = travel, travel
    for (n_lo, n_hi), (v0, v1) in ahead:
        s0, s1 = (signal + slope * (v - u) for v in (v0, v1))
        lo = min(lo, n_lo + min(s0, s1))
        hi = max(hi, n_hi + max(s0, s1))
    return lo, hi


def later_travel(moves: Sequence[MoveRecord], names: Sequence[str],
                 predicted: Mapping[tuple[str, str], tuple[float, float]]
                 ) -> dict[tuple[str, str], tuple[float, float]]:
    """``predicted`` widened by what the first cycle's ``moves`` did: (move label,
    gauge) -> (min, max) travel a later cycle's move will see."""
    predicted = dict(predicted)
    # What a later cycle's move will do, as this cycle's polls saw it: not from a
    # move the guard stopped or one re-planned after a stop (a late poll may have
    # seen the plunger inside the margin as it stopped; later cycles take another
    # path, and check_cycle's route check holds the margin on it).
    for rec in moves:
        if rec.off_route:
            continue
        base = rec.label.split(" (waypoint")[0]  # the move's label: its target
        for name in names:
            n_lo, n_hi = rec.nominal[name]
            p_lo, p_hi = rec.travel.get(name, (n_lo, n_hi))
            old = predicted.get((base, name), (np.inf, -np.inf))
            predicted[(base, name)] = (min(old[0], p_lo), max(old[1], p_hi))
    return predicted


def stop_of(sign: str | None) -> str:
    """The stop whose signal a posture's is: the reversal stop is Π0 (the same joints,
    but for their play)."""
    return "0" if sign == REVERSAL else (sign or "")
