"""Moving the axes to a step's target (the sequencer's moves): the route from
where they stand, one COMMAND 1 per sub-move watched by the plunger guard, and
the guard's second line. When the guard stops the axes mid-move, the mover waits
for rest, measures the gauges there, goes back to where the interrupted sub-move
began (a box inside the one just travelled, where the leg is parallel again),
and re-plans the rest of the move from there with what the gauges showed (more
waypoints, a lower speed), journaling it; only when no safe path is left does the
run stop, naming the gauge, the move and what to change.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from drivers.base import Arrivals, AxisReadout, GaugeReadings
from station.config import StationConfig
from station.engine.guard_monitor import GuardMonitor, PlungerGuardStop, PlungerGuardTrip
from station.errors import BadInput, RunFailed
from station.plan.checker import SIGNAL_PAD_MM, MotionChecker, PathRefused
from station.plan.steps import Move, Plan, SetupPlan

# The plunger guard's second line: after a trip the rest of the move is re-planned
# from where the axes stopped, at this fraction of the speed (again at each trip of
# the same mounting, down to MIN_SPEED_FRACTION), at most MAX_RECOVERIES times per
# mounting.
RECOVERY_SPEED_FACTOR = 0.5
MIN_SPEED_FRACTION = 0.1
MAX_RECOVERIES = 6
# Waypoints a re-plan may use: from a plunger stopped close to its end the first
# sub-moves must be short (their box small), growing as it gets away.
RECOVERY_WAYPOINTS = 40
# How long the axes may take to come to rest after the guard's stop (COMMAND 2).
STOP_TIMEOUT_S = 10.0


class MoverAxes(AxisReadout, Arrivals, Protocol):
    """What the mover asks of the axes: where they stand and whether they still move,
    and moves waited for (each watched by the guard)."""


class Mover:
    """One per sequencer. ``position``: where the axes are (None: moving or not
    read yet); ``at``: the posture they last arrived at ("0", "+", "-", "+30";
    None: unknown); ``setup``/``mounted``: the setup in progress and its gauges
    (set by the sequencer); ``recovered``: the journal records of recovered trips."""

    def __init__(self, *, config: StationConfig, plan: Plan, controller: MoverAxes,
                 indicators: GaugeReadings, checker: MotionChecker, guard: GuardMonitor,
                 journal: Callable[[dict[str, object]], None],
                 journal_safe: Callable[[dict[str, object]], None],
                 progress: Callable[..., None]) -> None:
        self.config, self.plan = config, plan
        self.controller, self.indicators = controller, indicators
        self.checker, self.guard = checker, guard
        self._journal, self._journal_safe, self.progress = journal, journal_safe, progress
        self.position: np.ndarray | None = None
        self.at: str | None = None
        # The approach the axes last arrived with (Move.approach relative to its
        # target; None: straight, or not known): a stop the axes stand at already is
        # only skipped when they arrived there from the side it asks for.
        self._arrived_from: tuple[float, ...] | None = None
        self.setup: SetupPlan | None = None
        self.mounted: dict[str, str] = {}
        self.touched = False
        self.moves = 0
        self.guard_recoveries = 0
        self.recovered: list[dict[str, object]] = []
        self._leg_start: np.ndarray | None = None  # where the sub-move in progress began
        self._speed_factor = 1.0
        self._recoveries = 0

    def mount(self, mounted: dict[str, str]) -> None:
        """A new mounting: its gauges, full speed, no recoveries yet."""
        self.mounted = dict(mounted)
        self._speed_factor, self._recoveries = 1.0, 0

    def move(self, step: Move) -> None:
        """To the step's target: the route from where the axes stand, each sub-move
        watched by the guard while it watches; after a trip, the guard's second
        line (``touched`` then says the cycle in progress had one)."""
        target = np.asarray(step.targets, dtype=float)
        sign = self._sign_of(step)
        # Always ask the drive: a write-back shifts the counted position of a carriage
        # that has not moved, and a resumed run starts wherever the machine stopped.
        self.position = np.asarray(self.controller.read_positions(), dtype=float)
        side = _side(step)
        if np.allclose(self.position, target, atol=1e-3) and side == self._arrived_from:
            self.at = sign
            return  # already there, from that side: consecutive setups share Π0
        # The plan was checked from nominal postures; the actual start may differ
        # (first move, resumed run, new offsets), so the move is checked again from
        # here and its waypoints (if any) derived from here; once the guard has
        # learned the mounting's signal, it is part of the check.
        signal = self._route_signal(sign)
        # Where the guard no longer watches, the route must keep its margin.
        strict = bool(self.mounted) and self.guard.enabled and not self.guard.watching
        try:
            legs = self.checker.route(self.position, target, step.label, self.setup,
                                      self.mounted, signal=signal, strict=strict,
                                      travel=False, approach=step.approach)
        except PathRefused as exc:
            if not (self.mounted and signal is not None):
                raise  # the plan's own check, from where the machine stands: bad input
            detail = str(exc).removeprefix("plan: ").removesuffix("; nothing has moved")
            raise PlungerGuardStop(
                f"plunger guard: with the travel measured under this mounting, {detail}; "
                f"this move has not started, {self.guard.axes_seen.text(self.position)}. "
                + self.guard.cause(exc.indicator or "", exc.pushed)) from None
        self.progress("move", label=step.label, targets=step.targets)
        self.at = None
        self._arrived_from = None
        self.guard.begin_move(self.position, legs, signal)
        touched = False
        trip: PlungerGuardTrip | None = None
        while True:
            try:
                if trip is not None:  # inside the try: a trip on the way back is caught
                    legs = self._recover(step, trip, sign)
                    trip = None
                self._sub_moves(step, legs)
                break
            except PlungerGuardTrip as exc:
                trip, touched = exc, True
        self.at = sign
        self._arrived_from = side
        if touched:
            self.touched = True

    def _route_signal(self, sign: str | None) -> dict[str, tuple[float, float]] | None:
        """The travel beyond the nominal model a move of this mounting is routed with
        (at its start, at its target): what the guard measured at both stops (None:
        a stop not read yet under this mounting)."""
        if not self.mounted:
            return None
        return self.guard.route_signal(self.at, sign)

    def _sign_of(self, step: Move) -> str | None:
        """The posture a move goes to, from the setup's postures (None: not one)."""
        if self.setup is None:
            return "0" if step.label == "Π0" else None
        for sign, targets in self.setup.postures.items():
            if tuple(targets) == tuple(step.targets):
                return sign
        return None

    def _sub_moves(self, step: Move, legs: Sequence[np.ndarray], watched: bool = False
                   ) -> None:
        """One COMMAND 1 per target of ``legs`` (``watched``: a way back after a
        trip, labelled so)."""
        speed = self.config.controller.speed_mm_s * self._speed_factor
        for number, leg in enumerate(legs, start=1):
            # Each waypoint is a move of its own (COMMAND 1, a deadline from its own
            # length); none is a reading stop, so the journal and resume ignore them.
            label = step.label if number == len(legs) and not watched else \
                f"{step.label} ({'way back' if watched else 'waypoint'} {number}/" \
                f"{len(legs) - (0 if watched else 1)})"
            start = self.position
            self._leg_start = start
            self.position = None  # unknown until the move has arrived
            watch = None if start is None else self.guard.watch(start, leg, label)
            if watch is None:
                actual = self.controller.move_and_wait(list(leg), speed_mm_s=speed, start=start)
            else:
                actual = self.controller.move_and_wait(list(leg), speed_mm_s=speed, start=start,
                                                       watch=watch)
            self.position = np.asarray(actual, dtype=float)
            self.moves += 1

    def _recover(self, step: Move, trip: PlungerGuardTrip, sign: str | None
                 ) -> list[np.ndarray]:
        """The guard stopped the axes mid-move: wait until they rest and measure the
        gauges there; back to where the interrupted sub-move began (its box lies
        inside the one just travelled, and there the leg is parallel again), measure
        again, and re-plan the rest of the move from there with what the gauges
        showed (more waypoints where needed), at a lower speed. Where the way back
        does not hold, the rest is re-planned from where the axes stand. Raises the
        trip (the run stops) when no safe path is left; returns the sub-moves on."""
        self._recoveries += 1
        here, means = self._at_rest_after_stop()
        record: dict[str, object] = {
            "event": "plunger-guard-recovery", "indicator": trip.indicator,
            "where": self.guard.where, "move": trip.label, "from": [float(v) for v in here],
            "readings_mm": means}
        if self._recoveries > MAX_RECOVERIES:
            record["result"] = f"stopped: {MAX_RECOVERIES} recoveries on this mounting"
            self._journal_safe({"type": "event", "event": record})
            raise PlungerGuardStop(
                f"{trip} (the guard stopped this mounting's axes {self._recoveries} times; "
                "check the stand)") from None
        self._speed_factor = max(MIN_SPEED_FRACTION,
                                 self._speed_factor * RECOVERY_SPEED_FACTOR)
        speed = self.config.controller.speed_mm_s * self._speed_factor
        target = np.asarray(step.targets, dtype=float)
        # what the trip predicted at the target, before the way back moves the guard on
        ahead = self.guard.signal_envelope(sign)
        routed = self.guard.routed()
        self.guard.expect_stop(sign)
        back = self._leg_start
        # at rest where the sub-move began: the trip came at once, or the way back held
        returned = back is not None and np.max(np.abs(back - here)) <= 1e-3
        if back is not None and not returned:
            try:
                retreat = self._replan(here, back, step.label, self.guard.retreat_signal())
            except BadInput:
                retreat = None  # no safe way back: on from here
            if retreat is not None:
                record["back_to"] = [float(v) for v in back]
                self._sub_moves(step, retreat, watched=True)  # a trip here: caught by _move
                here, means = self._at_rest_after_stop()
                returned = True
        if returned:
            # Where the sub-move began, a gauge that reads otherwise than it did there
            # had its zero moved; what the trip extrapolated from that step is dropped.
            signal, shifts = self.guard.after_retreat(sign, routed, ahead)
            if shifts:
                record["zero_shift_mm"] = shifts
        else:
            signal = {n: (now, ahead[n][1]) for n, (now, _) in
                      self.guard.signal_envelope(sign).items()}
        record["signal_mm"] = {n: list(v) for n, v in signal.items()}
        try:
            legs = self._replan(here, target, step.label, signal, step.approach)
        except BadInput as exc:
            record["result"] = f"no safe path: {exc}"
            self._journal_safe({"type": "event", "event": record})
            raise PlungerGuardStop(
                f"{trip}; no safe path from where the axes stopped: "
                f"{str(exc).removeprefix('plan: ')}") from None
        record.update(result="recovered", waypoints=len(legs) - 1, speed_mm_s=speed,
                      route=[[float(v) for v in leg] for leg in legs])
        self._journal({"type": "event", "event": record})
        self.recovered.append(record)
        self.guard_recoveries += 1
        self.progress("guard_recovered", label=step.label, indicator=trip.indicator)
        return legs

    def _at_rest_after_stop(self) -> tuple[np.ndarray, dict[str, float]]:
        """Positions once the axes rest, and the mounted gauges' mean readings there
        (what the guard's signal is then measured from)."""
        here = self._wait_stopped()
        self.position = here
        names = list(self.mounted)
        values = self.indicators.read(max(1, self.plan.readings), names)
        means = {n: float(np.mean(values[n])) for n in names}
        self.guard.at_rest(here, means)
        return here, means

    def _replan(self, here: np.ndarray, target: np.ndarray, label: str,
                signal: dict[str, tuple[float, float]],
                approach: tuple[float, float, float] | None = None) -> list[np.ndarray]:
        """A route from where a plunger may stand inside the margin: it may come no
        closer to its end than it is (less a reading's pad), never past it; the guard
        watches it with that margin; the move's approach kept (its last leg from one
        side). Raises BadInput when none holds."""
        margin = min(self.guard.margin, self.guard.slack_now() - SIGNAL_PAD_MM)
        if margin < 0:
            raise BadInput(f"plan: a plunger stands within {SIGNAL_PAD_MM:g} mm of the end "
                           "of its stroke")
        legs = self.checker.route(here, target, label, self.setup, self.mounted,
                                  signal=signal, strict=True, margin=margin,
                                  max_waypoints=RECOVERY_WAYPOINTS, travel=False,
                                  approach=approach)
        self.guard.begin_move(here, legs, signal, margin=margin)
        return legs

    def _wait_stopped(self) -> np.ndarray:
        """Positions once the drive reports no motion (finite wait: STOP_TIMEOUT_S)."""
        deadline = time.monotonic() + STOP_TIMEOUT_S
        while True:
            status = self.controller.read_status()
            if not status.moving:
                return np.asarray(self.controller.read_positions(), dtype=float)
            if time.monotonic() >= deadline:
                raise RunFailed(f"plunger guard: the axes still move {STOP_TIMEOUT_S:g} s "
                                "after the stop; check the drive")
            time.sleep(0.01)


def _side(step: Move) -> tuple[float, ...] | None:
    """The approach of ``step`` relative to its target (None: straight)."""
    if step.approach is None:
        return None
    return tuple(round(float(a) - float(t), 6)
                 for a, t in zip(step.approach, step.targets, strict=True))
