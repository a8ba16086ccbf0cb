"""The plunger guard: gauges watched while the axes move during a
mounting's first cycle, the axes stopped before a plunger reaches an end of its
stroke, later cycles refused before moving when predicted too close; and the
simulated gauge's finite stroke it is tested with."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import FAST, simulated

from drivers.sim.pty_gauges import SimIndicator
from station import report
from station.commands import run as cmd_run
from station.config import parse_config
from station.engine.guard_monitor import GuardMonitor, PlungerGuardStop, PlungerGuardTrip
from station.errors import RunFailed
from station.plan.checker import MotionChecker
from station.plan.steps import build_plan
from station.record.journal_file import read_journal


def test_simulated_gauge_clamps_at_the_ends_of_its_stroke() -> None:
    position = [0.0]
    with SimIndicator("mitutoyo", lambda: position[0], stroke_mm=1.0, preload_mm=0.3) as sim:
        assert (sim.stroke_mm, sim.preload_mm) == (1.0, 0.3)
        for value, expected in ((0.2, 0.2), (-0.5, -0.3), (0.9, 0.7), (0.0, 0.0)):
            position[0] = value
            assert sim._value_mm() == pytest.approx(expected)
        assert sim.clamped == 2
    with SimIndicator("mitutoyo", lambda: 0.0, stroke_mm=12.5) as sim:
        assert sim.preload_mm == 6.25  # mounted pushed in by half by default
    with pytest.raises(ValueError):
        SimIndicator("mitutoyo", lambda: 0.0, preload_mm=0.3)  # a preload needs a stroke


# The guard reads the gauges while the axes move: its runs at real time (conftest).
@pytest.mark.real_time
def test_guard_stops_the_axes_before_a_short_preload_lifts_off(tmp_path: Path) -> None:
    # Gauge A is mounted with only 0.3 mm of preload on a machine with large offsets:
    # the signal on the way to Π_x^+ (-0.66 mm) would lift the leg off its plunger.
    # The plan cannot know it (nominally the travel stays within -0.06 mm after its
    # waypoints); the guard sees it coming and stops the axes, naming the gauge.
    stations: list[Any] = []

    def short_preload(station: Any) -> None:
        station.strokes["A"] = (12.5, 0.3)
        station.indicators["A"].preload_mm = 0.3
        stations.append((station, station.indicators["A"]))

    with pytest.raises(RunFailed) as info:
        # at a real machine's speed (the tests' default virtual machine runs 10 times
        # faster, leaving the guard one or two polls per sub-move)
        cmd_run.run(simulated(tmp_path / "runs", seed=3, true_drho=(-2.0, -2.0, -2.0),
                              speed=100.0, hook=short_preload))
    message = str(info.value)
    (run_dir,) = list((tmp_path / "runs").glob("run-*"))
    assert "\n" not in message
    assert "plunger guard: indicator A (y) on measurement setup 1 (leg x), move to Π_x^+" \
        in message
    assert "the end where the leg leaves it" in message and "more preload" in message
    assert f"orthocal resume {run_dir}" in message
    records = read_journal(run_dir / "journal.jsonl")
    trips = [r["event"] for r in records if r["type"] == "event"
             and r["event"]["event"] == "plunger-guard"]
    # The first stop may be followed by one re-plan from where the machine stands
    # (more waypoints, slower), which the same lift-off stops again: which of the two
    # depends on how many polls fit into a sub-move at real time. Never a third.
    assert 1 <= len(trips) <= 2 and {t["indicator"] for t in trips} == {"A"}, trips
    assert records[-1]["type"] == "fault" and "plunger guard" in records[-1]["error"]
    # stopped before the end: the plunger is still on the leg, and never read at its end
    ((station, sim),) = stations
    travel = sim._source() - sim._zero
    assert -0.3 < travel < -0.05 and sim.clamped == 0, message
    assert not station.machine.status().moving
    assert json.loads((run_dir / "result.json").read_text())["status"] == "failed"


@pytest.mark.real_time
def test_guard_leaves_a_normal_run_alone(tmp_path: Path, capsys) -> None:
    # one measurement and its write-back: every mounting's first cycle watched at real
    # time (a verification would watch the same moves again)
    code = cmd_run.run(simulated(tmp_path / "runs", seed=3, true_drho=(1.5, -1.8, 1.2),
                                 procedure={**FAST, "verify": False}))
    result = json.loads(capsys.readouterr().out)
    assert result["status"] == "ok"
    # completed: 0, or 3 where its closed loop did not converge (it says why)
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    records = read_journal(Path(result["run_dir"]) / "journal.jsonl")
    events = [r["event"] for r in records if r["type"] == "event"]
    assert not any(e["event"] == "plunger-guard" for e in events)
    learned = [e for e in events if e["event"] == "plunger-guard-learned"]
    # each mounting's first cycle: 3 setups of the one measurement
    assert len(result["iterations"]) == 1 and len(learned) == 3
    assert all(e["polls"] > 0 for e in learned)
    for e in learned:
        for lo, hi in e["predicted_mm"].values():
            assert -6.25 + 0.2 < lo <= hi < 6.25 - 0.2


def _guard(preload: float, journal: list[dict[str, Any]]) -> tuple[GuardMonitor, Any]:
    data = {"indicators": [{"name": "A", "port": "/dev/a", "preload_mm": preload},
                           {"name": "B", "port": "/dev/b"}],
            "setups": [{"leg": "x", "indicators": {"A": "y", "B": "z"}}],
            "controller": {"motion": "coordinated"}}
    cfg = parse_config(copy.deepcopy(data))
    checker = MotionChecker(cfg, ([0, 0, 0], [1000, 1000, 1000]))
    sp = build_plan(cfg).setups[0]
    stops: list[str] = []
    guard = GuardMonitor(cfg, checker, lambda: np.zeros(3),
                         lambda names: {n: [0.0] for n in names},
                         lambda: stops.append("stop"), journal.append)
    guard.mount(sp, "m", dict(sp.indicators), {"A": 1.0, "B": 2.0})
    return guard, sp


def _first_cycle(guard: GuardMonitor, stop_means: dict[str, dict[str, float]],
                 margin: float | None = None) -> None:
    """Leg x's first cycle, Π0 → Π_x^+ → Π_x^− → Π0, watched (never polled: each
    move's travel is its nominal bound), ended with ``stop_means``; ``margin``: the
    moves begun as re-plans after a stop, with that margin."""
    g = build_plan(parse_config({"indicators": [{"name": "A", "port": "/dev/a"}],
                                 "setups": [{"leg": "x", "indicators": {"A": "y"}}]})
                   ).setups[0].postures
    path = [g["0"], g["+"], g["-"], g["0"]]
    for a, b, label in zip(path, path[1:], ["Π_x^+", "Π_x^-", "Π0"], strict=False):
        guard.begin_move(a, [b], margin=margin)
        assert guard.watch(a, b, label) is not None
    guard.learn(stop_means)


def test_a_first_cycle_no_poll_saw_is_journaled_all_the_same(tmp_path: Path) -> None:
    # Moves shorter than a poll (a fast drive, a loaded machine): the guard never
    # measured a slack while the axes moved. What it learned at the stops is still
    # a record of the run, saved like any other (it once carried an infinite slack,
    # which the journal refused and a forgiving append dropped without a word).
    from station.record.journal_file import Journal, read_journal

    with Journal(tmp_path / "journal.jsonl") as journal:
        guard, _ = _guard(6.25, journal)  # type: ignore[arg-type]
        _first_cycle(guard, {"+": {"A": 0.9, "B": 2.1}, "-": {"A": 0.35, "B": 2.2},
                             "0": {"A": 1.0, "B": 2.0}})
    (record,) = read_journal(tmp_path / "journal.jsonl")
    assert record["event"]["event"] == "plunger-guard-learned"
    assert record["event"]["polls"] == 0 and record["event"]["min_slack_mm"] is None


def test_later_cycles_are_refused_before_moving_when_predicted_too_close() -> None:
    journal: list[dict[str, Any]] = []
    guard, _ = _guard(0.8, journal)
    # cycle 1 ended with A 0.65 mm lifted at Π_x^−: within 0.2 mm of its 0.8 mm preload
    # once the move's own nominal swing is added; B far from its ends
    _first_cycle(guard, {"+": {"A": 1.0 - 0.1, "B": 2.1}, "-": {"A": 1.0 - 0.65, "B": 2.2},
                         "0": {"A": 1.0, "B": 2.0}})
    assert not guard.watching
    assert journal[-1]["event"]["event"] == "plunger-guard-learned"
    with pytest.raises(PlungerGuardStop) as info:
        guard.check_cycle(2)
    msg = str(info.value)
    assert "indicator A (y) on measurement setup 1 (leg x)" in msg and "cycle 2" in msg
    # cycle 1 moved the axes: the stop says so, and why (the stops' signal)
    assert "cycle 2 has not moved" in msg and "nothing has moved" not in msg
    assert "more preload" in msg and "Likely cause" in msg
    assert journal[-1]["event"]["event"] == "plunger-guard-refused"
    # the same cycle with a comfortable preload goes ahead
    guard2, _ = _guard(6.25, [])
    _first_cycle(guard2, {"+": {"A": 0.9, "B": 2.1}, "-": {"A": 0.35, "B": 2.2},
                          "0": {"A": 1.0, "B": 2.0}})
    guard2.check_cycle(2)


def test_a_move_replanned_after_a_stop_is_no_prediction_of_later_cycles() -> None:
    # The same first cycle as above, but its moves re-planned after a stop (begun with
    # the re-plan's own margin): their travel is of a path later cycles do not take,
    # so the refusal "as the first cycle showed" does not come from them; the route
    # check with the signal measured at the stops still refuses what it must.
    guard, _ = _guard(0.8, [])
    _first_cycle(guard, {"+": {"A": 1.0 - 0.1, "B": 2.1}, "-": {"A": 1.0 - 0.65, "B": 2.2},
                         "0": {"A": 1.0, "B": 2.0}}, margin=0.1)
    assert guard.predicted == {}
    with pytest.raises(PlungerGuardStop) as info:
        guard.check_cycle(2)
    assert "as the first cycle showed" not in str(info.value)
    assert "with the travel the first cycle measured at the stops" in str(info.value)


def test_a_move_the_guard_stopped_is_no_prediction_of_later_cycles() -> None:
    # A late poll (a loaded machine) sees gauge A already inside the margin as the
    # guard stops the axes: that move's path is not the one later cycles take (they
    # are routed with the signal measured at the stops), so it refuses none of them;
    # the moves that ran to their end still predict.
    cfg = parse_config({"indicators": [{"name": "A", "port": "/dev/a"}],
                        "setups": [{"leg": "x", "indicators": {"A": "y"}}],
                        "controller": {"motion": "coordinated"}})
    checker = MotionChecker(cfg, ([0, 0, 0], [1000, 1000, 1000]))
    sp = build_plan(cfg).setups[0]
    a, b = np.asarray(sp.postures["0"]), np.asarray(sp.postures["+"])
    reading = [10.0 + 6.1]  # travel +6.1 mm of a +6.25 mm stop, margin 0.2
    guard = GuardMonitor(cfg, checker, lambda: a, lambda names: {"A": [reading[0]]},
                         lambda: None, lambda r: None)
    guard.mount(sp, "m", {"A": "y"}, {"A": 10.0})
    guard.begin_move(a, [b])
    poll = guard.watch(a, b, "Π_x^+")
    assert poll is not None
    with pytest.raises(PlungerGuardTrip):
        poll()
    guard.begin_move(b, [a])  # a move that runs to its end, near its mounting value
    reading[0] = 10.0
    guard.watch(b, a, "Π0")()
    guard.learn({"+": {"A": 10.0}, "0": {"A": 10.0}})
    assert ("Π_x^+", "A") not in guard.predicted and ("Π0", "A") in guard.predicted


def test_guard_poll_stops_on_a_drifting_signal_before_the_end() -> None:
    # Positions follow the planned straight path Π0 → Π_x^+ sample by sample; gauge A
    # (preload 2 mm) reads the nominal travel (down to -0.88 mm on the way) plus a
    # signal growing linearly along the move. +0.2 mm: never near an end. -1.5 mm:
    # -0.88 - 1.5 would pass the end at -2; the guard stops before the gauge gets
    # within its 0.2 mm margin.
    cfg = parse_config({"indicators": [{"name": "A", "port": "/dev/a", "preload_mm": 2.0}],
                        "setups": [{"leg": "x", "indicators": {"A": "y"}}],
                        "controller": {"motion": "coordinated"}})
    checker = MotionChecker(cfg, ([0, 0, 0], [1000, 1000, 1000]))
    sp = build_plan(cfg).setups[0]
    a, b = np.asarray(sp.postures["0"]), np.asarray(sp.postures["+"])
    path = a + (b - a) * np.linspace(0, 1, 41)[:, None]

    def run(signal_at_end: float) -> tuple[int, list[str], float]:
        k = [0]
        stops: list[str] = []
        last = [0.0]

        def positions() -> np.ndarray:
            return path[min(k[0], 40)]

        def read(names: list[str]) -> dict[str, list[float]]:
            here = path[min(k[0], 40)]
            nominal = float(checker.nominal_travel(sp, "A", "y", here[None])[0])
            last[0] = nominal + signal_at_end * min(k[0], 40) / 40
            k[0] += 1
            return {"A": [10.0 + last[0]]}

        guard = GuardMonitor(cfg, checker, positions, read,
                             lambda: stops.append("stop"), lambda r: None)
        guard.mount(sp, "m", {"A": "y"}, {"A": 10.0})
        guard.begin_move(a, [b])
        poll = guard.watch(a, b, "Π_x^+")
        assert poll is not None
        try:
            # (the poll reads no more once the axes stand at the target, as the drive
            # stops calling it once it reports in position)
            for _ in range(60):
                poll()
        except PlungerGuardStop:
            pass
        return k[0], stops, last[0]

    polls, stops, _ = run(0.2)
    # polled all the way (the 40th read already saw the axes at the target) and never
    # stopped them
    assert polls == 40 and stops == []
    polls, stops, travel = run(-1.5)
    assert stops == ["stop"] and polls < 40 and travel > -2.0 + 0.2


def test_a_step_is_told_from_a_signal_back_where_the_move_began() -> None:
    # Gauge A's stand slides 5 mm at a fifth of the move Π0 → Π_x^+. Carried along the
    # move's progress as a signal, that step predicts the plunger far past its stop at
    # the target, and the guard stops the axes. Back at rest at Π0 the gauge reads
    # 5 mm more than it did there: same joint positions, so a step. The rest of the move
    # is re-planned with the step held, not extrapolated (no path could satisfy that:
    # the run stopped on CI's slower machine); a drifting signal with no step keeps
    # what the trip predicted.
    cfg = parse_config({"indicators": [{"name": "A", "port": "/dev/a"}],
                        "setups": [{"leg": "x", "indicators": {"A": "y"}}],
                        "controller": {"motion": "coordinated"}})
    checker = MotionChecker(cfg, ([0, 0, 0], [1000, 1000, 1000]))
    sp = build_plan(cfg).setups[0]
    a, b = np.asarray(sp.postures["0"]), np.asarray(sp.postures["+"])
    path = a + (b - a) * np.linspace(0, 1, 41)[:, None]

    def nominal(p: np.ndarray) -> float:
        return float(checker.nominal_travel(sp, "A", "y", p[None])[0])

    def run(extra: Any) -> tuple[GuardMonitor, Any, Any, int]:
        k = [0]

        def read(names: list[str]) -> dict[str, list[float]]:
            here = path[min(k[0], 40)]
            value = 10.0 + nominal(here) + extra(min(k[0], 40) / 40)
            k[0] += 1
            return {"A": [value]}

        guard = GuardMonitor(cfg, checker, lambda: path[min(k[0], 40)], read,
                             lambda: None, lambda r: None)
        guard.mount(sp, "m", {"A": "y"}, {"A": 10.0})
        guard.at_rest(a, {"A": 10.0})  # Π0 read at rest: the move starts from a stop
        guard.begin_move(a, [b])
        poll = guard.watch(a, b, "Π_x^+")
        assert poll is not None
        with pytest.raises(PlungerGuardTrip):
            for _ in range(60):
                poll()
        ahead = guard.signal_envelope("+")
        routed = guard.routed()
        guard.expect_stop("+")
        stopped_at = k[0]
        # the way back to Π0, at rest there: the gauge reads what ``extra`` says at Π0
        guard.begin_move(path[stopped_at], [a], guard.retreat_signal())
        guard.at_rest(a, {"A": 10.0 + nominal(a) + extra(stopped_at / 40, back=True)})
        return guard, ahead, routed, stopped_at

    def step(u: float, back: bool = False) -> float:
        return 5.0 if back or u >= 0.2 else 0.0

    guard, ahead, routed, _ = run(step)
    assert ahead["A"][1] > 10.0  # the step, extrapolated: far past the stop (+6.25)
    signal, shifts = guard.after_retreat("+", routed, ahead)
    assert shifts == {"A": pytest.approx(5.0, abs=1e-9)}
    assert signal["A"] == (pytest.approx(5.0, abs=1e-9), pytest.approx(5.0, abs=1e-9))
    assert guard.stop_signal["+"]["A"] == pytest.approx(5.0, abs=1e-9)

    def drift(u: float, back: bool = False) -> float:
        return 0.0 if back else 12.0 * u  # a signal of the positions: none at Π0

    guard, ahead, routed, _ = run(drift)
    signal, shifts = guard.after_retreat("+", routed, ahead)
    assert shifts == {}
    assert signal["A"][1] == ahead["A"][1] and signal["A"][1] > 6.25
    # a sub-move that began at a waypoint (no reading at rest there) has nothing exact
    # to compare with: what the trip predicted stands
    guard.begin_move(a, [path[10], b])
    guard.watch(a, path[10], "Π_x^+ (waypoint 1/1)")
    assert guard.routed() is not None  # from the stop read at rest
    guard.watch(path[10], b, "Π_x^+")
    assert guard.routed() is None
    signal, shifts = guard.after_retreat("+", None, ahead)
    assert shifts == {} and signal["A"][1] == ahead["A"][1]
