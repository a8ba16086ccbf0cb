"""The floor of a calibration run and where its time goes, read from what the run
left (journal, plan, result) and what the virtual drive recorded: the physics
every run must pay (moves, settle, line time), the drive's idle time between its
moves, the first cycle's extra cost, and the gauges moved past a stroke end. The
station is run by bench/cycle.py; this only reads."""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drivers.indicator_protocols import make_protocol
from drivers.profiles import move_time
from drivers.sim.drive_motion import DriveMotion
from orthocal import AXES
from station.record.journal_file import read_journal


@dataclass
class Timing:
    speed_mm_s: float = 100.0
    accel_mm_s2: float = 1000.0
    baud: int = 9600
    settle_s: float = 0.05
    readings: int = 5
    protocol: str = "mitutoyo"
    # How the virtual controller moves its axes (a DriveMotion or its name), and the
    # acceleration the drive really has (None: the one the config gives the station).
    motion: str | DriveMotion = "coordinated"
    drive_accel: float | None = None
    guard: bool = True  # procedure.plunger_guard
    approach: str | None = None  # procedure.approach (None: the station's default)


def line_time_per_reading(protocol_name: str, baud: int) -> float:
    """Seconds one request + reply occupies the line (the simulator's emulation)."""
    proto = make_protocol(protocol_name)
    assert proto.reply_format is not None
    reply = proto.reply_format.format(value=0.0).encode() + proto.terminator
    return (len(proto.request) + len(reply)) * proto.bits_per_char / baud


def physical_floor(run_dir: Path, start_m: np.ndarray, timing: Timing
                   ) -> tuple[float, float, float, int]:
    """(moves, settle, line) seconds and the number of stops of the run in run_dir."""
    records = read_journal(run_dir / "journal.jsonl")
    plan = json.loads((run_dir / "plan.json").read_text())
    result = json.loads((run_dir / "result.json").read_text())
    before = np.array([result["offsets_before"][a] for a in AXES])
    written = result.get("offsets_written")
    after = before if not written else np.array([written[a] for a in AXES])
    # Closed loop: each phase runs on the offsets the write-back before it left, and
    # a verification measured again (v+1, v2+1) on its round's.
    offsets_of = {"m": before}
    current = before
    for it in result.get("iterations") or []:
        for phase in it.get("passes") or [it["phase"]]:
            offsets_of[phase] = current
        if it.get("offsets_written"):
            current = np.array([it["offsets_written"][a] for a in AXES])
    # Stops in the order they were read, with the most readings any gauge took there.
    stops: dict[str, int] = {}
    for r in records:
        if r["type"] == "reading":
            stops[r["stop"]] = max(stops.get(r["stop"], 0), len(r["values"]))
    position = start_m.copy()
    moves = 0.0
    for stop in stops:
        phase, setup, _cycle, sign = stop.split(":")
        # The reversal stop is Π0 reached from the other side: its trip there and the
        # approach's overruns are what lost motion costs, not in the floor.
        posture = "0" if sign == "r" else sign
        rho = np.array(plan["setups"][int(setup)]["postures"][posture], dtype=float)
        # machine scale: the offsets the phase ran on
        target = rho + offsets_of.get(phase, before if phase == "m" else after)
        distance = float(np.max(np.abs(target - position)))
        if distance > 1e-3:  # the station skips moves within a µm, as the drive would
            moves += move_time(distance, timing.speed_mm_s, timing.accel_mm_s2)
        position = target
    per_reading = line_time_per_reading(timing.protocol, timing.baud)
    settle = timing.settle_s * len(stops)
    line = per_reading * sum(stops.values())
    return moves, settle, line, len(stops)


def first_cycle_extra_s(records: list[dict[str, Any]]) -> tuple[float, int]:
    """From the journal: each stop's time (its reading record minus the previous
    stop's), first cycle against the mean of the same stop in later cycles."""
    ends: dict[str, float] = {}
    for r in records:
        if r["type"] == "reading":
            ends[r["stop"]] = r["t"]  # the last gauge's record closes the stop
    order = sorted(ends, key=ends.get)  # type: ignore[arg-type]
    took = {s: ends[s] - ends[p] for p, s in itertools.pairwise(order)}
    extra = []
    for stop, t in took.items():
        phase, setup, cycle, sign = stop.split(":")
        if cycle != "1":
            continue
        later = [took[k] for k in took if k.split(":")[:2] == [phase, setup]
                 and k.split(":")[3] == sign and k.split(":")[2] not in ("0", "1")]
        if later:
            extra.append(t - float(np.mean(later)))
    return (float(np.mean(extra)) if extra else 0.0), len(extra)


def idle_between_moves(began: list[float], durations: list[float],
                       targets: list[np.ndarray], postures: list[np.ndarray]
                       ) -> tuple[list[float], list[float]]:
    """The drive's idle time from the end of each move to the start of the next
    (machine clock), split by what the move went to: a stop of the plan (settle
    and readings follow) or a waypoint (the next sub-move could start at once)."""
    after_stop, after_waypoint = [], []
    for k in range(len(began) - 1):
        idle = began[k + 1] - (began[k] + durations[k])
        at_stop = any(np.max(np.abs(targets[k] - p)) <= 1e-3 for p in postures)
        (after_stop if at_stop else after_waypoint).append(idle)
    return after_stop, after_waypoint


def leg_under_test(target: np.ndarray) -> str | None:
    """The leg whose test posture (or waypoint on its axis) a joint target is: the
    joint that differs from the two others, which are equal (None: Π0)."""
    for i, axis in enumerate(AXES):
        j, k = (n for n in range(3) if n != i)
        if abs(target[j] - target[k]) < 1e-6 and abs(target[i] - target[j]) > 1e-6:
            return axis
    return None


def own_setup_events(events: list[Any], targets: list[np.ndarray]) -> tuple[int, int]:
    """(events on gauges of the leg under test, events on other legs' gauges): the
    leg under test at a move is that of the last move to a test posture or waypoint."""
    legs: list[str | None] = []
    current: str | None = None
    for target in targets:
        current = leg_under_test(target) or current
        legs.append(current)
    own = sum(1 for e in events if e.move is not None and 0 < e.move <= len(legs)
              and legs[e.move - 1] == e.leg)
    return own, len(events) - own
