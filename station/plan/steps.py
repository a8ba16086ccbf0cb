"""The procedure as a list of small typed steps (bluesky-style plan), checked
before anything moves.

A setup is: move to Π0, prompt the operator to mount the setup's indicators
(at Π0, the middle of the leg), read Π0, then cycles Π_i^+ → Π_i^− → Π0, each
stop settled and read. Consecutive cycles share their Π0 stop, and Π_i^+ goes
straight to Π_i^−, so no axis travels further than the postures require. With
``[procedure] strokes`` a cycle visits Π_i(s) for every stroke, in the order of
:func:`orthocal.postures.stop_order` (out along +, back through to −, home).

Lost motion (``[procedure] approach``): every move to a stop ends with a short leg
that every joint runs in the chosen direction, from ``approach_overrun_mm``
beyond the target (``Move.approach``, the point it starts from); and every
cycle ends with one more stop, Π0 approached from the other side (posture
``"r"``), whose readings against the cycle's closing Π0 give the joints'
reversal (orthocal.lost_motion), and enter no deviation.

Stop ids are ``"{phase}:{setup}:{cycle}:{posture}"`` (phase ``m`` measurement,
``v`` verification; cycle 0 holds only the first Π0). The sequencer generates
the same steps with the same functions, so the listing and the check cover
exactly what runs, repeats and verification included (they revisit the same
postures).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from typing import Protocol

import orthocal
from drivers.base import Vec3
from orthocal import AXES, postures
from orthocal.postures import MIDDLE
from station.config import StationConfig
from station.plan import motion

PHASES = {"m": "measurement", "v": "verification"}


#: The posture of a cycle's last stop: Π0 approached from the other side, for the
#: joints' reversal.
REVERSAL = "r"


def posture_label(sign: str, leg: str | None) -> str:
    if sign == "0":
        return "Π0"
    if sign == REVERSAL:
        return "Π0 (other side)"
    return f"Π_{leg}^{sign}" if sign in ("+", "-") else f"Π_{leg}({sign})"


def cycle_postures(config: StationConfig,
                   strokes: Sequence[float] | None = None) -> tuple[str, ...]:
    """The test postures of one cycle, in the order visited: ('+', '-') unless
    ``[procedure] strokes`` (or ``strokes``, for a design study) names others
    (orthocal.postures: '+30', '-50', ...)."""
    m = config.machine
    strokes = strokes or config.procedure.strokes or [m.rho_max, m.rho_min]
    geometry = m.geometry()
    return tuple(postures.posture_name(s, geometry) for s in postures.stop_order(strokes))


def stop_id(phase: str, setup: int, cycle: int, sign: str) -> str:
    return f"{phase}:{setup}:{cycle}:{sign}"


@dataclass(frozen=True)
class Prompt:
    setup: int
    leg: str
    indicators: tuple[tuple[str, str], ...]  # (name, direction) as mounted
    kind: str = "prompt"
    at: float = postures.MIDDLE  # the gauges' place along the leg (SetupConfig.at)


@dataclass(frozen=True)
class Move:
    targets: tuple[float, float, float]
    label: str
    kind: str = "move"
    # Where the move's last short leg starts (every joint then runs toward its target
    # from one side: [procedure] approach); None: as planned, straight to the target.
    approach: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Settle:
    seconds: float
    kind: str = "settle"


@dataclass(frozen=True)
class Read:
    stop: str
    setup: int
    cycle: int
    sign: str  # "0", "+", "-" or a stroke such as "+30"
    indicators: tuple[str, ...]
    n: int
    kind: str = "read"


@dataclass(frozen=True)
class Checkpoint:
    setup: int
    cycle: int
    label: str = "cycle complete"
    kind: str = "checkpoint"


Step = Prompt | Move | Settle | Read | Checkpoint


class Listed(Protocol):
    """A part of the plan beside its setups, with its own steps: the station's own test
    of the joints (station.plan.joint_test_plan.StationTest)."""

    def to_json(self) -> dict[str, object]: ...

    def lines(self) -> list[str]: ...


@dataclass
class SetupPlan:
    index: int
    leg: str
    indicators: dict[str, str]  # name -> "y" or "-y"
    postures: dict[str, tuple[float, float, float]]  # "0", "+", "-", "+30" -> joint targets
    order: tuple[str, ...] = ("+", "-")  # the test postures of a cycle, in order
    # The signed overrun each stop is approached from (mm: −o from below, +o from
    # above; None: as planned), and the reversal stop's ("r": from the other side).
    overrun: float | None = None
    reversal_overrun: float | None = None
    # Where along the leg the gauges touch it (fraction from the carriage's joint).
    # (MIDDLE by name: the field ``postures`` above hides the module in this body.)
    at: float = MIDDLE

    def key_posture(self, sign: str) -> str:
        """The deviation key's posture of test posture ``sign`` read by this setup's
        gauges: "+" at the middle, "+@0.25" in a second plane."""
        return postures.with_plane(sign, self.at)

    def move(self, sign: str) -> Move:
        """The move to posture ``sign`` ("r": Π0 from the side opposite the stops')."""
        targets = self.postures["0" if sign == REVERSAL else sign]
        over = self.reversal_overrun if sign == REVERSAL else self.overrun
        approach = None if over is None else joint_triple(float(v) + over for v in targets)
        return Move(targets, posture_label(sign, self.leg), approach=approach)

    @property
    def signs(self) -> tuple[str, ...]:
        """The stops of a cycle, in order: its test postures, Π0, the reversal stop."""
        return (*self.order, "0", *((REVERSAL,) if self.reversal_overrun is not None else ()))

    def start_steps(self, phase: str, cycle: int, settle_s: float, n: int) -> list[Step]:
        """Mount at Π0 and take the Π0 reading that opens cycle ``cycle + 1`` (0 in a
        fresh run; later when a resumed run remounts mid-setup)."""
        names = tuple(self.indicators)
        return [
            self.move("0"),
            Prompt(self.index, self.leg, tuple(self.indicators.items()), at=self.at),
            Settle(settle_s),
            Read(stop_id(phase, self.index, cycle, "0"), self.index, cycle, "0", names, n),
        ]

    def cycle_steps(self, phase: str, cycle: int, settle_s: float, n: int) -> list[Step]:
        names = tuple(self.indicators)
        steps: list[Step] = []
        for sign in self.signs:
            steps += [
                self.move(sign),
                Settle(settle_s),
                Read(stop_id(phase, self.index, cycle, sign), self.index, cycle, sign, names, n),
            ]
        steps.append(Checkpoint(self.index, cycle))
        return steps


@dataclass
class Plan:
    setups: list[SetupPlan]
    cycles: int
    readings: int
    settle_s: float
    limits: tuple[list[float], list[float]] | None = None
    limits_source: str = ""
    # Per indicator and setup: (min, max) plunger travel found by the check, mm.
    travel: dict[str, tuple[float, float]] = field(default_factory=dict)
    # The controller's path model and the waypoints the check put on moves whose
    # single COMMAND 1 would take a plunger out of its stroke (see route_key).
    motion: str | None = None
    routes: dict[tuple, list[tuple[float, float, float]]] = field(default_factory=dict)
    start: tuple[float, ...] | None = None
    # The run's pass (0-based) that reads a second gauge plane (setups_of): the second,
    # the first taken with the offsets small; the first where nothing is verified.
    two_plane_pass: int = 1
    # The station's own test of the joints, before the first measurement: planned and
    # checked with the plan (station.plan.joint_test_plan), None without one.
    station_test: Listed | None = None

    def setups_of(self, index: int) -> list[SetupPlan]:
        """The setups the run's pass ``index`` (0-based, every pass of every measurement
        counted in order, further passes too) measures, in the order it measures them
        where no gauges are still on (station.engine.kept puts the pass before's last
        first). A plan with a second gauge plane beside the legs' middles reads that
        plane once, in the run's second pass (:attr:`two_plane_pass`: the verification
        of the first write-back, or the first measurement's further pass where it wrote
        nothing; the first pass where nothing is verified), its setups first so that
        the pass ends at a leg's middle, whose gauges the next pass keeps; every other
        pass reads the middles alone. The first pass is measured with the offsets still
        large, where the stands set by eye blur the bows; the legs' form does not change
        when offsets are written, so the later passes carry the bows the second
        measured (docs/design.md, "A second gauge plane, read once"; docs/model.md,
        "The second gauge plane"). A function of the index and the plan
        alone: a resumed run measures every pass as it was."""
        middles = [sp for sp in self.setups if sp.at == MIDDLE]
        if not middles or len(middles) == len(self.setups):
            return list(self.setups)
        if index == self.two_plane_pass:
            return [sp for sp in self.setups if sp.at != MIDDLE] + middles
        return middles

    def passes(self) -> dict[str, list[int]] | None:
        """Which setups (1-based, in order) the run's first pass, its second and every
        later one measure, where a second gauge plane makes them differ
        (:meth:`setups_of`); else None."""
        first, second, later = (self.setups_of(i) for i in (0, 1, 2))
        if len(first) == len(second):
            return None
        return {"first": [sp.index + 1 for sp in first],
                "second": [sp.index + 1 for sp in second],
                "later": [sp.index + 1 for sp in later]}

    def deviation_keys(self, index: int | None = None
                       ) -> tuple[list[tuple[str, str, str]], list[list[int]]]:
        """The deviation keys the run's pass ``index`` (:meth:`setups_of`; None: every
        setup of the plan) measures and, per mounted indicator, its rows in the order a
        cycle visits the stops (for orthocal.design.run_std_errors)."""
        keys: list[tuple[str, str, str]] = []
        indicators: list[list[int]] = []
        for sp in self._pass(index):
            for direction in sp.indicators.values():
                rows = []
                for posture in sp.order:
                    rows.append(len(keys))
                    keys.append((sp.key_posture(posture), sp.leg, direction.lstrip("-")))
                indicators.append(rows)
        return keys, indicators

    def waypoints_of(self) -> Iterator[tuple[Step, list[tuple[float, float, float]]]]:
        """Each step of the measurement phase with the waypoints of its move (its
        approach point, where it has one, is the move's own: Move.approach)."""
        position = self.start
        for step in self.steps("m"):
            via: list[tuple[float, float, float]] = []
            if isinstance(step, Move):
                if position is not None:
                    via = self.routes.get(route_key(position, step.targets), [])
                position = step.targets
            yield step, via

    def steps(self, phase: str = "m", index: int | None = None) -> Iterator[Step]:
        """Every step of one pass of ``phase`` at the configured number of cycles: the
        setups of the run's pass ``index`` (:meth:`setups_of`), None: every setup of
        the plan in its order (the listing, the plan check's order)."""
        for sp in self._pass(index):
            yield from sp.start_steps(phase, 0, self.settle_s, self.readings)
            for cycle in range(1, self.cycles + 1):
                yield from sp.cycle_steps(phase, cycle, self.settle_s, self.readings)

    def _passes_line(self, passes: dict[str, list[int]]) -> str:
        both = "(the second gauge plane first, ending at a leg's middle)"
        if self.two_plane_pass == 0:
            return (f"passes: the first measures setups {_numbers(passes['first'])} {both}; "
                    f"every later one setups {_numbers(passes['later'])} (the legs' "
                    "middles), carrying the bows the first measured")
        return (f"passes: the first measures setups {_numbers(passes['first'])} (the legs' "
                "middles); the second (the first verification, or the first measurement's "
                f"further pass) setups {_numbers(passes['second'])} {both}; every later one "
                f"setups {_numbers(passes['later'])}, carrying the bows the second measured")

    def _pass(self, index: int | None) -> list[SetupPlan]:
        return list(self.setups) if index is None else self.setups_of(index)

    def to_json(self) -> dict:
        # Only a plan with [procedure] strokes says so: the default's JSON stays as it was.
        strokes = {} if self.setups[0].order == ("+", "-") else {
            "test_postures": list(self.setups[0].order)}
        passes = self.passes()
        return {
            **strokes,
            **({} if passes is None else {"passes": passes}),
            **({} if self.station_test is None else
               {"station_test": self.station_test.to_json()}),
            "cycles": self.cycles,
            "readings": self.readings,
            "settle_s": self.settle_s,
            "soft_limits": None if self.limits is None else
            {"lower": self.limits[0], "upper": self.limits[1], "source": self.limits_source},
            "setups": [
                {"index": sp.index, "leg": sp.leg, "indicators": sp.indicators,
                 "postures": {k: list(v) for k, v in sp.postures.items()}}
                for sp in self.setups
            ],
            "travel_mm": {k: list(v) for k, v in self.travel.items()},
            "motion": self.motion,
            "steps": [asdict(s) | ({"via": [list(w) for w in via]} if via else {})
                      for s, via in self.waypoints_of()],
        }

    def format(self) -> str:
        order = self.setups[0].order
        cycle = "Π0 → Π+ → Π− → Π0" if order == ("+", "-") else \
            " → ".join(["Π0", *(posture_label(s, "i") for s in order), "Π0"])
        lines = [
            f"plan: {len(self.setups)} setup(s) × up to {self.cycles} cycle(s) "
            f"({cycle}) × {self.readings} reading(s) per stop, "
            f"settle {self.settle_s:g} s"
        ]
        if self.limits is not None:
            lo, hi = self.limits
            source = f" ({self.limits_source})" if self.limits_source else ""
            lines.append(f"soft limits{source} (mm): " + ", ".join(
                f"ρ_{a} ∈ [{lo[i]:.3f}, {hi[i]:.3f}]" for i, a in enumerate(AXES)))
        if self.motion is not None:
            lines.append(f"controller path: {self.motion} axes: {motion.GUARANTEE[self.motion]}"
                         "; a move that could take a plunger out of its stroke goes via "
                         "waypoints, one COMMAND 1 each")
        if (passes := self.passes()) is not None:
            lines.append(self._passes_line(passes))
        sp0 = self.setups[0]
        if sp0.overrun is not None or sp0.reversal_overrun is not None:
            lines.append(approach_words(sp0.overrun, sp0.reversal_overrun))
        if self.station_test is not None:
            lines += self.station_test.lines()
        number = 0
        for step, via in self.waypoints_of():
            number += 1
            if isinstance(step, Move):
                text = f"move {step.label:<7} ρ = (" + ", ".join(
                    f"{t:.3f}" for t in step.targets) + ")"
                if via:
                    text += f" via {len(via)} waypoint(s): " + "; ".join(
                        "(" + ", ".join(f"{t:.3f}" for t in w) + ")" for w in via)
                if step.approach is not None:
                    side = "below" if step.approach[0] < step.targets[0] else "above"
                    text += f", from {side}"
            elif isinstance(step, Prompt):
                lines.append(f"setup {step.setup + 1}: leg {step.leg}")
                text = ("prompt: mount " + ", ".join(f"{n} ({d})" for n, d in step.indicators)
                        + (f" at the middle of leg {step.leg}" if step.at == MIDDLE else
                           f" at {step.at:g} of leg {step.leg}") + " at Π0; remove the others")
            elif isinstance(step, Settle):
                text = f"settle {step.seconds:g} s"
            elif isinstance(step, Read):
                text = f"read {step.stop:<10} {', '.join(step.indicators)} × {step.n}"
            else:
                text = f"checkpoint: setup {step.setup + 1} cycle {step.cycle} complete"
            lines.append(f"  {number:4d}  {text}")
        if self.travel:
            lines.append("plunger travel, bound over every position the moves can pass "
                         "through (nominal model):")
            for key, (lo_t, hi_t) in self.travel.items():
                lines.append(f"  {key}: {lo_t:+.3f} .. {hi_t:+.3f} mm")
        lines.append("plan checked: every target inside the soft limits and the workspace, "
                     "every plunger within its stroke")
        return "\n".join(lines)


def approach_words(overrun: float | None, reversal: float | None) -> str:
    """The listing's line on how the stops are approached."""
    if overrun is None:
        head = "approach: as planned (the joints reach the stops from either side)"
    else:
        head = (f"approach: every stop from {'below' if overrun < 0 else 'above'}, every "
                f"joint's last leg from {abs(overrun):.3f} mm beyond (lost motion shifts "
                "every stop alike)")
    if reversal is None:
        return head
    return (head + f"; each cycle ends with Π0 from {'above' if reversal > 0 else 'below'}"
            " as well: the joints' reversal, in no deviation")


def joint_triple(values: Iterable[float]) -> tuple[float, float, float]:
    """Three joint values (x, y, z) as a tuple of floats."""
    x, y, z = (float(v) for v in values)
    return x, y, z


def route_key(start: Vec3, target: Vec3) -> tuple:
    """Routes are keyed by their ends (to the µm): a move with gauges mounted
    joins two postures of one leg, so it belongs to one setup."""
    return (*(round(float(v), 3) for v in start), *(round(float(v), 3) for v in target))


def build_plan(config: StationConfig, strokes: Sequence[float] | None = None) -> Plan:
    """The plan of ``config``; ``strokes`` replaces ``[procedure] strokes`` (design
    studies try strokes the config does not hold, even beyond rho_min/rho_max)."""
    geometry = config.machine.geometry()
    proc = config.procedure
    order = cycle_postures(config, strokes)
    setups = []
    for idx, setup in enumerate(config.setups):
        targets = {
            s: joint_triple(orthocal.posture(s, setup.leg, geometry))
            for s in ("0", *order)
        }
        setups.append(SetupPlan(idx, setup.leg, dict(setup.indicators), targets,
                                order, *approach_overruns(config), at=setup.at))
    # with nothing verified the first pass may be the run's only one
    return Plan(setups, proc.cycles, proc.readings, proc.settle_s,
                two_plane_pass=1 if proc.verify else 0)


def approach_overruns(config: StationConfig) -> tuple[float | None, float | None]:
    """(the signed overrun the stops are approached from, the reversal stop's): from
    below −o, then the reversal from above +o; from above the other way round; as
    planned no approach leg, and the reversal from above (in the paper's order every
    joint reaches the cycle's closing Π0 from below); no reversal stop without
    ``measure_reversal``."""
    proc = config.procedure
    o = proc.approach_overrun_mm
    stops, other = (o, -o) if proc.approach == "above" else \
        ((-o if proc.approach == "below" else None), o)
    return stops, (other if proc.measure_reversal else None)


def _numbers(setups: list[int]) -> str:
    return ", ".join(str(n) for n in setups)
