"""The gauges of a round's last setup, left on for the first setup of the next
(docs/design.md, "Closed loop"): one mounting fewer per round, where the plan check
says the plungers keep their strokes after the write-back's shift.

A write-back changes the controller's offsets by Δo and leaves the carriages where
they are: the same commanded stops then put each joint Δo further along
(drivers.sim.machine: q = ρ + (o − o_initial) + Δρ). A gauge left on reads every
stop of the next round from a Π0 that is no longer its mounting point: at the new
Π0 its plunger already stands at the travel t₀ the nominal model gives for Π0 + Δo
(+ pushed in), so it has that much less stroke one way and more the other: for
that mounting it sits as if mounted with preload p + t₀. The setup's every move is
checked with that preload (and SIGNAL_PAD_MM more margin for the model's first
order in Δo) before anything moves; where one does not hold, the setup is mounted
again with a prompt saying why.

The order of the setups in a pass is a function of the pass before alone (its last
setup first, then the plan's order), so a resumed run replays every pass in the
order it was measured. A resumed run whose kill fell between two setups finds the
gauges the journal last put on still on, as the run left alone would have (one that
stopped on a fault or Ctrl-C mounts afresh).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol, TypedDict

import numpy as np

from drivers.base import AxisReadout, ZeroOffsets
from orthocal import AXES
from station.config import StationConfig
from station.errors import BadInput
from station.plan.checker import SIGNAL_PAD_MM, MotionChecker
from station.plan.mounting import MountingSheet, sheet_of
from station.plan.steps import Move, Plan, Prompt, SetupPlan
from station.record.journal import WritebackBackup, WritebackDone, WritebackIntent
from station.record.journal_file import Journal


class PromptWords(TypedDict):
    """What the mount prompt says beside the mounting (Operator.mount's keywords)."""

    sheet: MountingSheet
    picture: str
    count: Mapping[str, int] | None
    remount: str | None

class KeptAxes(AxisReadout, ZeroOffsets, Protocol):
    """What the keeper asks of the axes: where they stand and their offsets."""


@dataclass
class Mounting:
    """A setup's gauges as they stand on the machine: the controller's offsets when
    their Π0 was last their reference, and each plunger's travel at that Π0 from
    where it was mounted (mm, + pushed in; 0 for a fresh mounting)."""

    setup: int
    indicators: dict[str, str]
    offsets: np.ndarray
    shift: dict[str, float] = field(default_factory=dict)


def order(setups: Sequence[SetupPlan], first: int | None) -> list[SetupPlan]:
    """``setups`` with the one of index ``first`` (the pass before's last) first."""
    head = [sp for sp in setups if sp.index == first]
    return head + [sp for sp in setups if sp.index != first]


def kept_travel(checker: MotionChecker, sp: SetupPlan, mounting: Mounting,
                offsets_now: Sequence[float] | np.ndarray,
                start: Sequence[float] | np.ndarray | None) -> dict[str, float] | str:
    """Each gauge's travel at ``sp``'s Π0 now, from where it was mounted, when every
    move of a cycle of ``sp`` holds with the mounting kept (module docstring); else
    why not, in the plan check's words. ``start``: where the axes stand (None: Π0)."""
    shift = np.asarray(offsets_now, dtype=float) - mounting.offsets
    zero = np.asarray(sp.postures["0"], dtype=float)
    t0 = {n: mounting.shift.get(n, 0.0) + float(np.ravel(checker.nominal_travel(
        sp, n, d, (zero + shift)[None, :]))[0]) for n, d in mounting.indicators.items()}
    before = checker.preload_shift
    checker.preload_shift = t0
    margin = checker.margin + SIGNAL_PAD_MM
    position = zero - shift if start is None else np.asarray(start, dtype=float)
    try:
        for step in [sp.move("0"), *sp.cycle_steps("m", 1, 0.0, 1),
                     *sp.cycle_steps("m", 2, 0.0, 1)[:1]]:
            if isinstance(step, Move):
                checker.route(position, step.targets, step.label, sp, mounting.indicators,
                              margin=margin, travel=False, approach=step.approach)
                position = np.asarray(step.targets, dtype=float)
    except BadInput as exc:
        return str(exc).removeprefix("plan: ").removesuffix("; nothing has moved")
    finally:
        checker.preload_shift = before
    return t0


def keys_of(sp: SetupPlan) -> list[str]:
    """The deviation keys ``sp``'s gauges read ("+xy", "+@0.75xy"…)."""
    return [f"{sp.key_posture(p)}{sp.leg}{d.lstrip('-')}" for d in sp.indicators.values()
            for p in sp.order]


class Keeper:
    """The sequencer's part in keeping gauges on (module docstring): which mounting is
    on the machine, whether the next pass's first setup keeps it, and what a mount
    prompt says beyond the mounting."""

    def __init__(self, config: StationConfig, plan: Plan, checker: MotionChecker,
                 controller: KeptAxes, journal: Journal,
                 progress: Callable[..., None]) -> None:
        self.config, self.plan, self.checker = config, plan, checker
        self.controller, self.journal, self.progress = controller, journal, progress
        self.mounting: Mounting | None = None  # the live setup's gauges
        self.still: Mounting | None = None  # left on after their setup ended
        self.last: int | None = None  # the last setup measured: the next pass's first
        self.remount: str | None = None  # why gauges left on are mounted again
        # The mountings the run expects (closed_loop.mountings_expected; the command
        # sets them): the first prompt says them.
        self.expected: dict[str, int] | None = None

    def mounted(self, setup: int, indicators: dict[str, str]) -> None:
        """The operator mounted ``setup``'s gauges: their Π0 is the mounting point."""
        self.remount = None
        self.checker.preload_shift = {}
        self.mounting = Mounting(setup, dict(indicators), self._offsets())

    def ended(self, phase: str, setup: int, live: bool) -> None:
        """A setup ended; its gauges stay on: this session's, or (replayed from the
        journal) the ones the journal says were put on for it last."""
        self.still = self.mounting if live else self._from_journal(phase, setup)
        self.mounting, self.last = None, setup

    def _from_journal(self, phase: str, setup: int) -> Mounting | None:
        """The gauges the journal last put on, where they are ``setup``'s of
        ``phase``: a resumed run whose kill fell between two setups goes on as the
        run left alone would have (the simulator keeps its gauges across it too)."""
        state = self.journal.state
        on = state.on
        if on is None or (on.phase, on.setup) != (phase, setup):
            return None
        offsets = on.offsets
        if offsets is None:  # put on before any write-back: the run's own offsets
            first = next(iter(state.writebacks.get(1, {}).values()), None)
            if isinstance(first, (WritebackBackup, WritebackIntent, WritebackDone)):
                offsets = [first.before[a] for a in AXES]
        return Mounting(setup, dict(on.indicators),
                        self._offsets() if offsets is None else np.asarray(offsets, float),
                        dict(on.shift))

    def keep(self, phase: str, sp: SetupPlan) -> bool:
        """Whether ``sp`` starts with the gauges still on; journaled either way, and
        the checker given the kept preload when it does."""
        still, self.still = self.still, None
        if still is None or still.setup != sp.index or still.indicators != sp.indicators:
            return False
        offsets = self._offsets()
        found = kept_travel(self.checker, sp, still, offsets,
                            self.controller.read_positions())
        record = {"event": "mount-kept", "phase": phase, "setup": sp.index,
                  "indicators": dict(sp.indicators)}
        if isinstance(found, str):
            self.remount = found
            self.journal.append({"type": "event", "event": {**record, "kept": False,
                                                            "why": found}})
            return False
        self.checker.preload_shift = found
        self.mounting = Mounting(sp.index, dict(sp.indicators), offsets, found)
        self.journal.append({"type": "event", "event": {
            **record, "kept": True, "travel_mm": found,
            "offsets": [float(v) for v in offsets]}})
        self.progress("mount_kept", phase=phase, setup=sp.index, travel=found)
        return True

    def prompt_words(self, phase: str, step: Prompt) -> PromptWords:
        """The mount prompt's words beyond the mounting (Operator.mount): the
        mounting's sheet (each plunger's preload window from the plan check's travel,
        station.plan.mounting) and its picture in the run directory, the mountings to
        expect at the run's first, why gauges left on are mounted again."""
        sheet = sheet_of(self.config, self.plan, self.plan.setups[step.setup])
        state = self.journal.state  # the joints' own test's mountings come first
        first = phase == "m" and state.mountings == state.joint_mountings
        return PromptWords(sheet=sheet, picture=str(self.journal.path.parent / sheet.file_name),
                           count=self.expected if first else None, remount=self.remount)

    def _offsets(self) -> np.ndarray:
        return np.asarray(self.controller.read_offsets(), dtype=float)
