"""The plan: listed step by step, and refused before any motion when a target
leaves the soft limits or a plunger would leave its stroke, with the refusal
naming the indicator, the setup and the posture."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest
from builders import journal_header, station_config, station_data

import orthocal
from drivers.sim.controller import SimController
from station.commands.cli import main
from station.config import StationConfig, load_config, parse_config
from station.errors import BadInput
from station.plan.check import check_plan
from station.plan.steps import Move, Prompt, Read, build_plan

PROCEDURE = {"cycles": 2, "readings": 3}  # the builders' station, two cycles of three
WIDE = ([0.0, 0.0, 0.0], [1000.0, 1000.0, 1000.0])


def config(**sections) -> StationConfig:
    return station_config(procedure=PROCEDURE, **sections)


def test_listing_has_every_stop_and_prompt() -> None:
    cfg = config()
    plan = check_plan(build_plan(cfg), cfg, WIDE)
    steps = list(plan.steps())
    prompts = [s for s in steps if isinstance(s, Prompt)]
    reads = [s for s in steps if isinstance(s, Read)]
    assert [p.leg for p in prompts] == ["x", "y", "z"]
    # per setup: the opening Π0 and four stops per cycle (consecutive cycles share Π0;
    # the fourth is Π0 from the other side, the joints' reversal)
    assert len(reads) == 3 * (1 + 4 * 2)
    assert sum(1 for r in reads if r.sign == "r") == 3 * 2
    assert all(r.n == 3 and r.indicators == ("A", "B") for r in reads)
    assert len({r.stop for r in reads}) == len(reads)
    text = plan.format()
    assert "Π_y^+" in text and "mount A (x), B (-z)" in text and "plan checked" in text


def test_moves_are_the_test_postures_and_prompts_come_at_pi0() -> None:
    cfg = config()
    plan = build_plan(cfg)
    g = cfg.machine.geometry()
    steps = list(plan.steps())
    for before, step in itertools.pairwise(steps):
        if isinstance(step, Prompt):
            assert isinstance(before, Move) and before.label == "Π0"
    moves = {m.label: m.targets for m in steps if isinstance(m, Move)}
    np.testing.assert_allclose(moves["Π_x^-"], orthocal.posture("-", "x", g))
    np.testing.assert_allclose(moves["Π_z^+"], orthocal.posture("+", "z", g))
    # Π+ goes straight to Π−: no axis travels back through Π0 in between; each cycle
    # ends with Π0 from the other side (the reversal stop)
    labels = [m.label for m in steps if isinstance(m, Move)]
    assert labels[:6] == ["Π0", "Π_x^+", "Π_x^-", "Π0", "Π0 (other side)", "Π_x^+"]


def test_soft_limit_refusal_names_posture_and_axis() -> None:
    cfg = config()
    hi = orthocal.posture("+", "y", cfg.machine.geometry())[1] - 1.0
    with pytest.raises(BadInput) as info:
        check_plan(build_plan(cfg), cfg, ([0, 0, 0], [1000, hi, 1000]))
    msg = str(info.value)
    assert "Π_y^+" in msg and "ρ_y" in msg and "soft limits" in msg and "setup 2" in msg


def test_config_narrows_the_controller_limits() -> None:
    data = station_data(procedure=PROCEDURE)
    data["controller"] = {"soft_max": [400.0, 400.0, 360.0]}
    cfg = parse_config(data)
    with pytest.raises(BadInput, match=r"Π_z\^\+.*ρ_z"):
        check_plan(build_plan(cfg), cfg, WIDE)


def test_first_move_from_the_actual_position_is_checked() -> None:
    cfg = config()
    with pytest.raises(BadInput, match=r"move to Π0.*outside the soft limits"):
        check_plan(build_plan(cfg), cfg, ([250, 250, 250], [400, 400, 400]),
                   start=[100.0, 310.25, 310.25])


def test_stroke_refusal_names_indicator_setup_and_posture() -> None:
    # Going from Π_x^+ to Π_x^− swings leg x sideways on the way (it is parallel to
    # its axis only where the end point is on the x axis): a gauge already at its
    # stop (preload = stroke) cannot follow, whatever waypoints the plan puts in.
    data = station_data(procedure=PROCEDURE)
    data["indicators"][1].update(stroke_mm=8.0, preload_mm=8.0)
    data["setups"][0]["indicators"]["B"] = "-z"  # reversed: the swing pushes it in
    cfg = parse_config(data)
    with pytest.raises(BadInput) as info:
        check_plan(build_plan(cfg), cfg, WIDE)
    msg = str(info.value)
    assert "indicator B" in msg and "setup 1" in msg and "Π_x^+" in msg
    assert "stroke" in msg


def test_lift_off_refusal_depends_on_mount_sign() -> None:
    # Same leg motion, seen from the other side: no preload lifts off instead.
    data = station_data(procedure=PROCEDURE)
    data["controller"] = {"motion": "coordinated"}  # a path that swings one way only
    # No preload at all, the stops as planned and no reversal stop: the approach's
    # overrun beyond a stop would lift such a gauge by itself.
    data["procedure"] = {**PROCEDURE, "approach": "as-planned", "measure_reversal": False}
    data["indicators"][0].update(stroke_mm=12.5, preload_mm=0.0)
    cfg = parse_config(data)
    with pytest.raises(BadInput) as info:
        check_plan(build_plan(cfg), cfg, WIDE)
    assert "lift off indicator A" in str(info.value)
    # Reversed, the same gauge is pushed in by the same motion: within its stroke.
    for setup in data["setups"]:
        for name, d in setup["indicators"].items():
            if name == "A":
                setup["indicators"][name] = "-" + d
    cfg = parse_config(data)
    plan = check_plan(build_plan(cfg), cfg, WIDE)
    lo, hi = plan.travel["A on leg x (setup 1)"]
    assert lo >= -1e-9 and hi > 4.0


def test_travel_of_a_mounted_indicator_matches_the_model() -> None:
    # the straight path between the stops, as planned (an approach's last leg would
    # add its overrun's share to the extremes)
    cfg = station_config(controller={"motion": "coordinated"},
                         procedure={**PROCEDURE, "approach": "as-planned",
                                    "measure_reversal": False})
    plan = check_plan(build_plan(cfg), cfg, WIDE)
    lo, hi = plan.travel["A on leg x (setup 1)"]
    g = cfg.machine.geometry()
    # the leg's worst excursion along y on the straight joint path Π_x^+ → Π_x^−
    a, b = orthocal.posture("+", "x", g), orthocal.posture("-", "x", g)
    path = a + (b - a) * np.linspace(0, 1, 400)[:, None]
    r = orthocal.leg_reading(path, "x", "y", g) - orthocal.leg_reading(
        orthocal.posture("0", None, g), "x", "y", g)
    assert lo == pytest.approx(r.min(), abs=0.01)
    assert hi == pytest.approx(max(r.max(), 0.0), abs=0.01)


def test_plan_json_lists_steps() -> None:
    cfg = config()
    data = check_plan(build_plan(cfg), cfg, WIDE).to_json()
    kinds = {s["kind"] for s in data["steps"]}
    assert kinds == {"move", "prompt", "settle", "read", "checkpoint"}
    assert data["soft_limits"]["upper"] == WIDE[1]


def test_an_identical_check_is_remembered_and_gives_what_the_check_gives() -> None:
    """A check with a fresh checker is kept (station.plan.check): the same plan checked
    again with another fresh checker gets the plan and the checker's state the check
    itself gives, and goes on from copies of them; a checker that has worked already,
    or a plan refused, is checked afresh."""
    from station.plan import check
    from station.plan.checker import MotionChecker

    cfg = config()
    start = [310.25, 310.25, 310.25]
    check._kept.clear()
    first_checker = MotionChecker(cfg, WIDE)
    first = check_plan(build_plan(cfg), cfg, WIDE, start=start, checker=first_checker)
    assert len(check._kept) == 1
    again_checker = MotionChecker(cfg, WIDE)
    again = check_plan(build_plan(cfg), cfg, WIDE, start=start, checker=again_checker)
    assert len(check._kept) == 1  # recalled, not checked again
    assert again.to_json() == first.to_json() and again.routes == first.routes
    assert again.format() == first.format() and again.start == first.start
    travel, routes, bounds = again_checker.state()
    assert travel == first_checker.travel and bounds.keys() == first_checker.state()[2].keys()
    assert routes.keys() == first_checker.state()[1].keys()
    # the run goes on with its own copies: what it adds is not what was kept
    again_checker.route(start, [300.0, 310.25, 310.25], "elsewhere")
    assert len(again_checker.state()[1]) > len(next(iter(check._kept.values())).checker[1])
    # where the devices are reached is not what the check reads: recalled; a gauge's
    # stroke is: checked afresh
    data = station_data(procedure=PROCEDURE)
    data["controller"] = {"port": 5021, "timeout_s": 0.5}
    data["indicators"][0]["port"] = "/dev/pts/9"
    moved = parse_config(data)
    check_plan(build_plan(moved), moved, WIDE, start=start, checker=MotionChecker(moved, WIDE))
    assert len(check._kept) == 1
    data["indicators"][0]["stroke_mm"] = 25.0
    longer = parse_config(data)
    check_plan(build_plan(longer), longer, WIDE, start=start,
               checker=MotionChecker(longer, WIDE))
    assert len(check._kept) == 2
    check._kept.clear()
    # a checker that has worked already: its check is not kept
    check_plan(build_plan(cfg), cfg, WIDE, start=start, checker=again_checker)
    assert not check._kept
    # a refused plan: refused each time, never kept
    narrow = ([0.0, 0.0, 0.0], [300.0, 1000.0, 1000.0])
    for _ in range(2):
        with pytest.raises(BadInput):
            check_plan(build_plan(cfg), cfg, narrow)
    assert not check._kept


def _missing_port_config(tmp_path: Path, controller_port: int) -> tuple[Path, Path]:
    """A config whose gauge D is on a port that is not there (an adapter unplugged)."""
    missing = tmp_path / "ttyUSB99"
    path = tmp_path / "station.toml"
    path.write_text(f"[controller]\nport = {controller_port}\ntimeout_s = 0.5\n"
                    '[[indicators]]\nname = "C"\nport = "/dev/null"\n'
                    f'[[indicators]]\nname = "D"\nport = "{missing}"\nreopen_s = 0.5\n'
                    '[[setups]]\nleg = "y"\nindicators = { C = "x", D = "-z" }\n')
    return path, missing


def test_a_gauge_port_that_does_not_exist_is_refused_before_anything_moves(
        tmp_path: Path, capsys) -> None:
    with SimController() as sim:
        path, missing = _missing_port_config(tmp_path, sim.port)
        for extra in (["--plan"], ["--yes"]):
            code = main(["run", "--config", str(path), *extra, "--out", str(tmp_path / "r")])
            err = capsys.readouterr().err
            assert code == 2, (extra, err)
            assert err.splitlines() == [f"orthocal: error: indicator D: port {missing} does "
                                        "not exist (plug its adapter in, or correct "
                                        "[[indicators]] port)"]
        assert sim.stats.writes == 0 and sim.stats.commands == {}  # nothing moved
    assert not (tmp_path / "r").exists()


def test_resume_refuses_a_gauge_port_that_does_not_exist(tmp_path: Path, capsys) -> None:
    # An interrupted run on real devices (no simulation in its header) whose gauge's
    # adapter is not plugged in again: refused at once, before homing or any check.
    with SimController() as sim:
        path, missing = _missing_port_config(tmp_path, sim.port)
        run_dir = tmp_path / "run-1"
        run_dir.mkdir()
        (run_dir / "config.toml").write_text(path.read_text())
        (run_dir / "journal.jsonl").write_text(json.dumps(
            {"t": 0.0, **journal_header(config=load_config(path).model_dump())}) + "\n")
        assert main(["resume", str(run_dir), "--yes"]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"orthocal: error: indicator D: port {missing} does not exist")
        assert sim.stats.writes == 0 and sim.stats.commands == {}
