"""The path the controller may take: the motion model in the
register-map profile and the config, the simulator's independent axes, the plan
check over every position a move can pass through, and the fewest waypoints that
keep the plungers in their strokes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import FAST, resumed, simulated, station_config, station_data
from truth import assert_truth, drho

import orthocal
from drivers.map_files import builtin_maps, load_map
from drivers.profiles import move_time
from drivers.registers import GENERIC
from drivers.sim.machine import VirtualOrthoglide
from station import report
from station.commands import run as cmd_run
from station.config import StationConfig, parse_config
from station.errors import BadInput, RunFailed
from station.plan.check import check_plan
from station.plan.checker import MotionChecker
from station.plan.limits import motion_model
from station.plan.motion import reachable_points
from station.plan.steps import build_plan
from station.record.journal_file import read_journal

IAI_PCON = builtin_maps()["iai-pcon-direct"]

# The builders' station on a slow controller, two cycles of three readings.
CONTROLLER: dict[str, Any] = {"speed_mm_s": 100.0, "accel_mm_s2": 1000.0}
PROCEDURE: dict[str, Any] = {"cycles": 2, "readings": 3}
WIDE = ([0.0, 0.0, 0.0], [1000.0, 1000.0, 1000.0])


def config(**controller: Any) -> StationConfig:
    return station_config(controller={**CONTROLLER, **controller}, procedure=PROCEDURE)


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def travel_on_machine(cfg: StationConfig, legs_of_move: list[list[np.ndarray]],
                      setup: int = 0, dt: float = 0.0005) -> dict[str, tuple[float, float]]:
    """Run moves (each a list of sub-move targets, one COMMAND 1 each) on a virtual
    machine with independent axes and a stepped clock; every mounted plunger's
    travel (+ pushed in, from Π0) as (min, max) over every instant."""
    clock = Clock()
    c = cfg.controller
    machine = VirtualOrthoglide(motion="independent", speed_mm_s=c.speed_mm_s,
                                accel_mm_s2=c.accel_mm_s2, clock=clock)
    sp = cfg.setups[setup]
    zero = {n: machine.leg_reading(sp.leg, d.lstrip("-")) for n, d in sp.indicators.items()}
    seen = {n: (0.0, 0.0) for n in sp.indicators}
    for legs in legs_of_move:
        for target in legs:
            duration = machine.move_to(target)
            end = clock.t + duration
            while clock.t < end + dt:
                clock.t += dt
                for n, d in sp.indicators.items():
                    sign = -1.0 if d.startswith("-") else 1.0
                    t = sign * (machine.leg_reading(sp.leg, d.lstrip("-")) - zero[n])
                    seen[n] = (min(seen[n][0], t), max(seen[n][1], t))
    return seen


def planned_moves(plan_json: dict, setup: int) -> list[list[np.ndarray]]:
    """The moves of one setup's first cycle as the plan lists them: each move's
    waypoints ("via", absent when the move is a single COMMAND 1), its approach
    point (the last leg's start), then its target."""
    moves = []
    current = -1
    for step in plan_json["steps"]:
        if step["kind"] == "prompt":
            current = step["setup"]
        elif step["kind"] == "move" and current == setup:
            approach = [] if step.get("approach") is None else [np.asarray(step["approach"])]
            moves.append([np.asarray(w) for w in step.get("via", [])] + approach
                         + [np.asarray(step["targets"])])
        if step["kind"] == "checkpoint" and current == setup:
            break
    return moves


def test_independent_axes_keep_plungers_in_stroke() -> None:
    # The case the plan must survive: an independent controller, standard 12.5 mm gauges
    # preloaded by half. A single COMMAND 1 from Π_x^+ to Π_x^− swings the gauges of
    # leg x by ~8.8 mm (the short axes arrive long before x): past the 6.25 mm of
    # preload, the leg leaves the plunger. The plan must route the move so that,
    # on the simulated machine, every plunger stays within its stroke at every instant.
    cfg = config(motion="independent")
    g = cfg.machine.geometry()
    single = travel_on_machine(cfg, [[orthocal.posture("+", "x", g)],
                                     [orthocal.posture("-", "x", g)]])
    assert min(lo for lo, _ in single.values()) < -8.5  # the figure, reproduced
    plan = check_plan(build_plan(cfg), cfg, WIDE, start=orthocal.posture("0", None, g))
    moves = planned_moves(plan.to_json(), 0)
    # one waypoint on Π_x^+ → Π_x^− and one on Π_x^− → Π0: safe for any axis timing;
    # each move's last leg from its approach point; then the reversal stop's move
    assert [len(m) for m in moves] == [2, 3, 3, 2]
    for name, (lo, hi) in travel_on_machine(cfg, moves).items():
        ind = cfg.indicator(name)
        assert -ind.preload < lo and hi < ind.stroke_mm - ind.preload, (name, lo, hi)
    text = plan.format()
    assert "controller path: independent axes" in text
    assert "move Π_x^-" in text and "via 1 waypoint(s)" in text


def test_plan_travel_bounds_the_travel_on_the_simulated_machine() -> None:
    # The plan no longer models the simulator's trapezoids: it bounds the travel over
    # the whole box of each move, so what the virtual gauges go through lies inside
    # its bound; and the bound is sharp: a brute-force search over a fine grid of
    # each box (every point of which some timing of the axes passes through: an axis
    # may pause while another moves) comes within 0.01 mm of it.
    cfg = config(motion="independent")
    g = cfg.machine.geometry()
    plan = check_plan(build_plan(cfg), cfg, WIDE, start=orthocal.posture("0", None, g))
    moves = planned_moves(plan.to_json(), 0)
    seen = travel_on_machine(cfg, moves)
    sp = build_plan(cfg).setups[0]
    checker = MotionChecker(cfg, WIDE)
    here = orthocal.posture("0", None, g)
    brute: dict[str, list[float]] = {n: [] for n in sp.indicators}
    for legs in moves:
        for leg in legs:
            points = reachable_points(here, leg, "independent", n=41)
            for n, d in sp.indicators.items():
                travel = checker.nominal_travel(sp, n, d, points)
                brute[n] += [float(travel.min()), float(travel.max())]
            here = leg
    for name, (lo, hi) in seen.items():
        p_lo, p_hi = plan.travel[f"{name} on leg x (setup 1)"]
        assert p_lo - 1e-6 <= lo and hi <= p_hi + 1e-6, (name, (lo, hi), (p_lo, p_hi))
        assert p_lo - 1e-6 <= min(brute[name]) <= p_lo + 0.01
        assert p_hi - 0.01 <= max(brute[name]) <= p_hi + 1e-6


def _trapezoid(distance: float, v: float, a: float, t: float) -> float:
    """Distance a rest-to-rest trapezoid has covered at t (the test's own reference)."""
    total = move_time(distance, v, a)
    t_acc = min(v / a, total / 2.0)
    v_peak = a * t_acc
    if t <= 0:
        return 0.0
    if t >= total:
        return distance
    if t < t_acc:
        return 0.5 * a * t * t
    if t > total - t_acc:
        return distance - 0.5 * a * (total - t) ** 2
    return 0.5 * a * t_acc**2 + v_peak * (t - t_acc)


def test_independent_simulated_axes_run_their_own_trapezoids() -> None:
    clock = Clock()
    machine = VirtualOrthoglide(motion="independent", speed_mm_s=100.0, accel_mm_s2=1000.0,
                                clock=clock)
    a = machine.actual()
    delta = np.array([60.0, -5.9, -0.4])
    b = a + delta
    duration = machine.move_to(b)
    assert duration == pytest.approx(move_time(60.0, 100.0, 1000.0))
    for t in np.linspace(0.0, duration, 101):
        clock.t = t
        expected = a + np.sign(delta) * [_trapezoid(abs(d), 100.0, 1000.0, t) for d in delta]
        np.testing.assert_allclose(machine.actual(), expected, atol=1e-9)
    # a coordinated machine stays on the straight line and arrives at the same time
    clock2 = Clock()
    coord = VirtualOrthoglide(speed_mm_s=100.0, accel_mm_s2=1000.0, clock=clock2)
    assert coord.move_to(b) == pytest.approx(duration)
    clock2.t = duration / 3
    u = (coord.actual() - a) / (b - a)
    assert np.ptp(u) < 1e-12


def test_independent_stop_brakes_each_axis() -> None:
    clock = Clock()
    machine = VirtualOrthoglide(motion="independent", speed_mm_s=100.0, accel_mm_s2=1000.0,
                                clock=clock)
    a = machine.actual()
    machine.move_to(a + np.array([50.0, 2.0, 0.0]))
    clock.t = 0.2  # y has arrived (2 mm in 0.09 s); x cruises at 100 mm/s
    here = machine.actual()
    machine.stop()
    clock.t = 1.0
    rest = machine.actual()
    assert rest[1] == pytest.approx(a[1] + 2.0)
    assert rest[0] - here[0] == pytest.approx(100.0**2 / (2 * 1000.0))  # v²/2a
    assert not machine.status().moving


def test_motion_comes_from_the_profile_unless_the_config_says() -> None:
    assert GENERIC.motion == "independent"  # COMMAND 1 promises no interpolation
    assert IAI_PCON.motion == "independent"
    assert load_map("orthocal-generic", {"SPEED": {"address": 41}}).motion == "independent"
    assert motion_model(config()) == "independent"
    assert motion_model(config(motion="coordinated")) == "coordinated"
    assert motion_model(config(profile="iai-pcon-direct")) == "independent"
    with pytest.raises(BadInput, match=r"controller\.profile"):
        motion_model(config(profile="nonesuch"))
    data = station_data(controller=CONTROLLER, procedure=PROCEDURE)
    data["controller"]["motion"] = "interpolated"
    with pytest.raises(BadInput, match=r"controller\.motion"):
        parse_config(data)


def test_coordinated_plan_needs_no_waypoints_for_standard_gauges() -> None:
    cfg = config(motion="coordinated")
    g = cfg.machine.geometry()
    plan = check_plan(build_plan(cfg), cfg, WIDE, start=orthocal.posture("0", None, g))
    assert plan.routes == {}
    assert "waypoint(s):" not in plan.format()


def test_short_gauge_gets_as_many_waypoints_as_it_needs() -> None:
    # A 3 mm gauge preloaded by 1.5: even the straight line from Π_x^+ to Π_x^−
    # swings leg x by 4.9 mm. Waypoints with the end point on the x axis: one halfway
    # leaves a 1.48 mm swing (inside the stroke, but within the guard's 0.2 mm margin
    # of its end); one placed where the two halves swing alike leaves 1.17 mm: the
    # plan takes that one (and one on Π_x^− → Π0, whose 1.49 mm swing is as close).
    data = station_data(controller=CONTROLLER, procedure=PROCEDURE)
    data["controller"]["motion"] = "coordinated"
    for ind in data["indicators"]:
        ind.update(stroke_mm=3.0, preload_mm=1.5)
    cfg = parse_config(data)
    g = cfg.machine.geometry()
    plan = check_plan(build_plan(cfg), cfg, WIDE, start=orthocal.posture("0", None, g))
    moves = planned_moves(plan.to_json(), 0)
    assert [len(m) for m in moves] == [2, 3, 3, 2]  # with the approach points, as above
    lo, hi = plan.travel["A on leg x (setup 1)"]
    assert -1.5 + 0.2 < lo < -0.8 and hi < 1.5 - 0.2  # 0.88 on Π0 → Π_x^+
    assert "via 1 waypoint(s)" in plan.format()
    # the waypoints put the end point on the x axis: leg x parallel, gauges at zero
    for w in moves[1][:-2]:  # (the last two: the approach point and the target)
        p = orthocal.forward(w, g)
        assert abs(p[1]) < 1e-9 and abs(p[2]) < 1e-9
    checker = MotionChecker(cfg, WIDE)
    sp = build_plan(cfg).setups[0]
    legs = checker.route(orthocal.posture("+", "x", g), orthocal.posture("-", "x", g),
                         "Π_x^-", sp, dict(sp.indicators))
    assert len(legs) == 2


# --- the sequencer runs the waypoints -----------------------------------------------------



def test_independent_machine_run_with_waypoints_is_interrupted_and_resumed(
        tmp_path: Path, capsys) -> None:
    true_drho = (0.7, -1.1, 0.5)
    stations: list[Any] = []

    def keep(station: Any) -> None:
        assert station.machine.motion == "independent"  # --motion, kept for resume
        stations.append((station, dict(station.indicators)))

    def alarm(station: Any) -> None:
        keep(station)
        # the fifth move is the first part of Π_x^+ → Π_x^− (a waypoint move): before
        # it, Π0 and Π_x^+, each from its approach point
        station.controller.faults.alarm_after_moves = 4

    with pytest.raises(RunFailed) as info:
        cmd_run.run(simulated(tmp_path / "runs", true_drho=true_drho, motion="independent",
                              hook=alarm))
    (run_dir,) = list((tmp_path / "runs").glob("run-*"))
    assert "alarm 17" in str(info.value) and f"orthocal resume {run_dir}" in str(info.value)
    plan_text = (run_dir / "plan.txt").read_text()
    assert "controller path: independent axes" in plan_text and "waypoint(s)" in plan_text
    assert not any(r["type"] == "cycle" for r in read_journal(run_dir / "journal.jsonl"))
    capsys.readouterr()
    code = cmd_run.resume(resumed(run_dir, hook=keep))
    result = json.loads(capsys.readouterr().out)
    assert result["status"] == "ok"
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    # the truth within the run's own statement (2 µm gauges, two cycles, stands
    # modelled: a standard error of ~6 µm; a fixed 10 µm failed one draw in a few)
    assert_truth(result, drho(true_drho))
    # no gauge ever read at an end of its stroke: not at the stops, not in the guard's polls
    assert len(stations) == 2
    assert all(sim.clamped == 0 for _, sims in stations for sim in sims.values())
    # a waypoint move is no reading stop: every stop was read once per phase and cycle,
    # but the two read before the alarm, whose cycle was redone after remounting
    records = read_journal(run_dir / "journal.jsonl")
    stops = [r["stop"] for r in records if r["type"] == "reading" and r["indicator"] == "A"]
    # (every phase the closed loop measured: a second write-back adds one)
    phases = len(result["iterations"])
    # (four stops per cycle: the test postures, Π0, and Π0 from the other side)
    assert len(set(stops)) == phases * 3 * (1 + 4 * FAST["cycles"])
    assert sorted(s for s in set(stops) if stops.count(s) > 1) == ["m:0:0:0", "m:0:1:+"]
    # moves: 3 per cycle + 1 waypoint on each Π_i^+ → Π_i^−
    assert result["timing"]["moves"] >= phases * 3 * 4 * FAST["cycles"] - 4
