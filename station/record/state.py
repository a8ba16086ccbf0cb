"""What a run's journal says, folded once: :class:`RunState`.

Every reader of the journal reads this: a resumed run (the steps it does not take
again, station.engine.replay; the setup a power cut interrupted, with its readings,
station.engine.recovery), the offsets a station holds (resume, rollback,
``--offsets-from``) and the result's counts (station.engine.procedure). The state is
built by one function, :meth:`RunState.apply`, applied to the typed records
(station.record.journal) in journal order, with no I/O: reopening a run folds what is
on disk, and a :class:`~station.record.journal_file.Journal` folds each record it saves
into the same state, so nothing reads the file a second time.

A ``setup-redo`` record voids the earlier cycle, setup_done and repeat records of its
(phase, setup): that setup is measured again from its first cycle
(station.engine.recovery).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

from orthocal import AXES
from station.record.journal import (
    Cycle,
    Event,
    Finished,
    Header,
    Identification,
    JointFace,
    JointMounted,
    JointTested,
    JointUnmounted,
    JournalRecord,
    Reading,
    Repeat,
    Resumed,
    RollbackDone,
    SetupDone,
    SetupRecord,
    SetupRedo,
    StoppedRecord,
    VerificationRecord,
    WritebackDone,
    WritebackFailed,
    WritebackInterrupted,
    WritebackRecord,
)
from station.record.journal_events import (
    EventBody,
    GuardRecovery,
    GuardRefused,
    GuardStop,
    MountKept,
    Retake,
    Retry,
)
from station.record.result_sections import Recovery

Fit = Identification | VerificationRecord


@dataclass
class LiveSetup:
    """The setup mounted last and not ended: its gauges are still on the machine, so it
    is the one a reference check after homing can check."""

    phase: str
    setup: int
    indicators: dict[str, str]  # name → direction, as last mounted
    # Every reading at its stops, from each of its mountings (a resume remounts it),
    # (stop, indicator) → values: the Π0 readings and their scatter the check needs.
    readings: dict[tuple[str, str], list[float]] = field(default_factory=dict)

    @property
    def prefix(self) -> str:
        return f"{self.phase}:{self.setup}:"  # of its stop ids (station.plan.steps.stop_id)


@dataclass
class OnMachine:
    """The gauges last put on (a ``setup`` record, or a ``mount-kept`` event: gauges
    left on, station.engine.kept): the offsets they were put on under (None: the
    run's own, no write-back before) and each plunger's travel there from where it
    was mounted (a kept mounting's; empty for a fresh one)."""

    phase: str
    setup: int
    indicators: dict[str, str]
    offsets: list[float] | None
    shift: dict[str, float] = field(default_factory=dict)


@dataclass
class GuardTally:
    """What the plunger guard did in every session (the result's ``plunger_guard``)."""

    stops: int = 0  # times it stopped the axes
    recovered: list[Recovery] = field(default_factory=list)  # each way back
    retakes: int = 0  # cycles taken again after a knocked stand
    refused: int = 0  # moves refused before they started


@dataclass
class RunState:
    """The journal's records folded in order (module docstring)."""

    header: Header | None = None
    finished: Finished | None = None
    resumes: int = 0  # ``resumed`` records: the sessions after the first
    # The steps done, by their identity (station.engine.replay reads them).
    cycles: dict[tuple[str, int, int], Cycle] = field(default_factory=dict)
    setups_done: dict[tuple[str, int], SetupDone] = field(default_factory=dict)
    repeats: dict[tuple[str, int, int], Repeat] = field(default_factory=dict)
    fits: dict[int, Fit] = field(default_factory=dict)  # round (0: the measurement's)
    writebacks: dict[int, dict[str, WritebackRecord]] = field(default_factory=dict)  # round, stage
    live: LiveSetup | None = None
    # What the journal's own write-backs and rollbacks leave the offsets at (x, y, z),
    # None while it has none.
    offsets_held: list[float] | None = None
    # Each rollback the operator made, in journal order: a rollback is an event of the
    # run, never an overwrite of the one before.
    rollbacks: list[RollbackDone] = field(default_factory=list)
    guard: GuardTally = field(default_factory=GuardTally)
    retries: int = 0  # driver retries
    mountings: int = 0  # ``setup`` records: what the operator mounted, and for how long
    operator_s: float = 0.0
    # (phase, setup) that went on with the gauges left on from the pass before
    # (``mount-kept`` events, station.engine.kept): no mounting of their own.
    kept: set[tuple[str, int]] = field(default_factory=set)
    on: OnMachine | None = None  # None: none, or a fault's session may have moved them
    # The joints the station's own test is done with, by axis (station.engine.joint_station),
    # and how many of the mountings were its own.
    joint_tests: dict[str, JointTested] = field(default_factory=dict)
    joint_mountings: int = 0

    @classmethod
    def of(cls, records: Iterable[JournalRecord]) -> RunState:
        state = cls()
        for record in records:
            state.apply(record)
        return state

    @property
    def started(self) -> float | None:
        """When the run's header was written (Unix time, s)."""
        return None if self.header is None else self.header.t

    def held_offsets(self, start: Sequence[float] | None) -> list[float] | None:
        """The offsets a station holding them holds now: the journal's own, else
        ``start`` (what the run began with; None: zeros, none of its own)."""
        if self.offsets_held is not None:
            return list(self.offsets_held)
        return None if start is None else [float(v) for v in start]

    def apply(self, rec: JournalRecord) -> None:
        """Fold one more record in (outliers, homing, reference checks and the
        records of a fault are read by nothing that resumes or sums a run)."""
        match rec:
            case Header() | Finished():
                self._ends(rec)
            case Resumed():
                self.resumes += 1
            case SetupRecord() | StoppedRecord():
                self._mounted(rec)
            case Reading():
                if self.live is not None and rec.stop.startswith(self.live.prefix):
                    self.live.readings[(rec.stop, rec.indicator)] = list(rec.values)
            case Cycle():
                self.cycles[(rec.phase, rec.setup, rec.cycle)] = rec
            case SetupDone():
                self._ended(rec)
            case Repeat() if rec.repeat is not None:
                self.repeats[(rec.phase, rec.setup, rec.repeat)] = rec
            case Identification() | VerificationRecord():
                self._fit(rec)
            case WritebackRecord():
                self._writeback(rec)
            case RollbackDone():
                self.offsets_held = [float(rec.restored[a]) for a in AXES]
                self.rollbacks.append(rec)
            case Event():
                self._event(rec.event)
            case SetupRedo():
                self._void(rec.phase, rec.setup)
            case JointMounted() | JointFace() | JointUnmounted() | JointTested():
                self._joint_test(rec)

    def _joint_test(self, rec: JointMounted | JointFace | JointUnmounted | JointTested
                    ) -> None:
        """The station's own test of a joint: its record once done; the operator's part,
        its time, and a mounting of its own with no leg gauge left on."""
        if isinstance(rec, JointTested):
            self.joint_tests[rec.joint] = rec
            return
        self.operator_s += float(rec.operator_s or 0.0)
        if isinstance(rec, JointMounted):
            self.mountings += 1
            self.joint_mountings += 1
            self.on, self.live = None, None

    def _ends(self, rec: Header | Finished) -> None:
        if isinstance(rec, Header):
            self.header = rec
        else:
            self.finished = rec

    def _mounted(self, rec: SetupRecord | StoppedRecord) -> None:
        if isinstance(rec, StoppedRecord):  # a fault's or Ctrl-C's: what was on is mounted again
            self.on = None
            return
        self.mountings += 1
        self.operator_s += float(rec.operator_s or 0.0)
        self.on = OnMachine(rec.phase, rec.setup, dict(rec.indicators),
                            None if self.offsets_held is None else list(self.offsets_held))
        if self.live is not None and (self.live.phase, self.live.setup) == (rec.phase,
                                                                            rec.setup):
            self.live.indicators = dict(rec.indicators)  # remounted: its readings stand
        else:
            self.live = LiveSetup(rec.phase, rec.setup, dict(rec.indicators))

    def _ended(self, rec: SetupDone) -> None:
        self.setups_done[(rec.phase, rec.setup)] = rec
        if self.live is not None and (self.live.phase, self.live.setup) == (rec.phase,
                                                                            rec.setup):
            self.live = None

    def _fit(self, rec: Fit) -> None:
        # a verification's round n; the measurement's identification is round 0
        n = rec.round if isinstance(rec, VerificationRecord) else 0
        self.fits[1 if n is None else n] = rec

    def _writeback(self, rec: WritebackRecord) -> None:
        # records from before the closed loop carry no round: round 1
        self.writebacks.setdefault(1 if rec.round is None else rec.round, {})[rec.stage] = rec
        # the stages after which the station holds the offsets: those written, or the
        # backup written back
        match rec:
            case WritebackDone():
                self.offsets_held = [float(rec.written[a]) for a in AXES]
            case WritebackInterrupted() | WritebackFailed(stage="failed-restored"):
                self.offsets_held = [float(rec.before[a]) for a in AXES]

    def _event(self, event: EventBody) -> None:
        match event:
            case Retry():
                self.retries += 1
            case GuardStop():
                self.guard.stops += 1
            case Retake():
                self.guard.retakes += 1
            case GuardRefused():
                self.guard.refused += 1
            case MountKept(kept=True):
                # the gauges left on are this setup's: a reference check after homing
                # checks them as it would a mounting's
                indicators = dict(event.indicators)
                self.kept.add((event.phase, event.setup))
                self.live = LiveSetup(event.phase, event.setup, indicators)
                self.on = OnMachine(event.phase, event.setup, indicators, event.offsets,
                                    dict(event.travel_mm or {}))
            case GuardRecovery(result="recovered", waypoints=int() as waypoints,
                               speed_mm_s=float() as speed):
                # (the mover journals both with every way back that ended "recovered")
                recovery = Recovery(where=event.where, move=event.move,
                                    indicator=event.indicator, waypoints=waypoints,
                                    speed_mm_s=speed)
                # only where the way back found a gauge's zero moved (a step): set, so
                # that result.json holds it; absent otherwise
                if event.zero_shift_mm is not None:
                    recovery.zero_shift_mm = dict(event.zero_shift_mm)
                self.guard.recovered.append(recovery)

    def _void(self, phase: str, setup: int) -> None:
        """A setup-redo: the setup's steps so far are void (its readings are kept, as
        the stops measured again replace theirs)."""
        self.setups_done.pop((phase, setup), None)
        self.cycles = {k: v for k, v in self.cycles.items() if k[:2] != (phase, setup)}
        self.repeats = {k: v for k, v in self.repeats.items() if k[:2] != (phase, setup)}
