"""``orthocal design`` and orthocal.design: the experiment's quality before it runs."""

from __future__ import annotations

import json

import numpy as np
import pytest
from builders import station_config, station_data

import orthocal
from orthocal import design
from station.commands.cli import main
from station.commands.design_command import design_summary, plan_keys, run_time
from station.commands.simulate.launch import station_config as sim_station_config
from station.config import parse_config
from station.plan.check import check_plan
from station.plan.steps import build_plan

G = orthocal.Geometry()
LEGS = {a: [d for d in "xyz" if d != a] for a in "xyz"}


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("model", ["rho", "L", "full", "rho+tilt"])
@pytest.mark.parametrize("strokes", [[60, -100], [60, 30, -50, -100]])
def test_noise_gains_are_the_statistical_floor(model, strokes) -> None:
    keys = design.keys_for(strokes, LEGS, G)
    q = design.quality(keys, G, model)
    floor = orthocal.statistical_floor(keys, G, model, 1.0)
    np.testing.assert_allclose(list(q.noise_gain.values()), floor, rtol=1e-12)
    assert q.rank == len(q.names) and q.identifiable
    J = orthocal.jacobian(keys, G, model)
    assert q.condition_number == pytest.approx(np.linalg.cond(J), rel=1e-9)


def test_paper_figures() -> None:
    """docs/model.md: condition 61.87 for the full model, noise gain 1.87 for Δρ alone."""
    keys = design.keys_for([60, -100], LEGS, G)
    assert design.quality(keys, G, "full").condition_number == pytest.approx(61.87, abs=0.01)
    assert design.quality(keys, G, "rho").noise_gain["drho_x"] == pytest.approx(1.867, abs=1e-3)


def test_full_tilt_from_two_postures_is_explained_in_words() -> None:
    q = design.quality(design.keys_for([60, -100], LEGS, G), G, "full+tilt")
    assert q.rank == 8 and not q.identifiable and len(q.invisible) == 1
    (combo,) = q.invisible
    # ΔL and the tilts trade against each other (docs/model.md, "Extended model")
    assert {"dL_x", "dL_y", "dL_z", "tilt_yx", "tilt_zx", "tilt_zy"} <= set(combo)
    J = orthocal.jacobian(design.keys_for([60, -100], LEGS, G), G, "full+tilt")
    v = np.array([combo.get(n, 0.0) for n in q.names])
    assert np.abs(J @ v).max() < 0.05 * np.abs(J).max()  # it really changes (almost) nothing
    words = " ".join(design.describe(q))
    assert "rank 8 < 9" in words and "cannot be told apart" in words and "dL_x" in words


def test_run_covariance_matches_a_simulated_run() -> None:
    """Monte Carlo of what the station does: noisy readings at Π0 / stops / Π0 ...,
    deviations against the two Π0 means around each stop, OLS over all cycles."""
    strokes, cycles, readings = [60, 30, -50, -100], 3, 2
    keys = design.keys_for(strokes, LEGS, G)
    J = orthocal.jacobian(keys, G, "rho")
    n = len(strokes)
    indicators = [[k * 6 + m for k in range(n)] for m in range(6)]
    predicted = design.run_std_errors(J, indicators, cycles, readings)
    rng = np.random.default_rng(5)
    draws = 4000
    X = np.vstack([J[rows] for _ in range(cycles) for rows in indicators])
    pinv = np.linalg.pinv(X)
    estimates = []
    for _ in range(draws):
        per_ind = []
        for _m in indicators:
            zero = rng.normal(0, 1, (cycles + 1, readings)).mean(axis=1)
            stops = rng.normal(0, 1, (cycles, n, readings)).mean(axis=2)
            per_ind.append(stops - 0.5 * (zero[:-1] + zero[1:])[:, None])  # [cycle, stop]
        y = [per_ind[m][c] for c in range(cycles) for m in range(len(indicators))]
        estimates.append(pinv @ np.concatenate(y))
    empirical = np.std(estimates, axis=0, ddof=1)
    np.testing.assert_allclose(empirical, predicted, rtol=0.04)
    # and the shared Π0 matters: independent deviations would claim a different figure
    naive = np.sqrt(np.diag(np.linalg.inv(X.T @ X)) * 1.5 / readings)
    assert np.all(np.abs(naive / predicted - 1) > 0.06)


def test_search_stays_within_limits_and_improves_its_objective() -> None:
    def objective(strokes) -> float:
        keys = design.keys_for(strokes, LEGS, G)
        J = orthocal.jacobian(keys, G, "rho")
        ind = [[k * 6 + m for k in range(len(strokes))] for m in range(6)]
        return -np.linalg.slogdet(design.run_covariance(J, ind, 3, 5))[1]

    refused = {-60.0, -59.0, 45.0}
    found = design.search_strokes([30, -40], LEGS, G, "rho", (-70.0, 50.0),
                                  feasible=lambda s: s not in refused, cycles=3)
    assert all(-70 <= s <= 50 and s != 0 and s not in refused for s in found.strokes)
    assert len(set(found.strokes)) == len(found.strokes) == 2
    assert objective(found.strokes) > objective([30, -40]) + 0.1
    # the optimum of this model is at the ends of the allowed range
    assert found.strokes == (50.0, -70.0)


def test_search_respects_a_set_check_and_adds_stops_only_when_it_must() -> None:
    calls = []

    def no_big_pair(strokes) -> bool:
        calls.append(strokes)
        return not (max(strokes) > 50 and min(strokes) < -90)

    found = design.search_strokes([60, -100], LEGS, G, "rho", (-100.0, 60.0),
                                  feasible_set=no_big_pair, cycles=3)
    assert no_big_pair(found.strokes) and calls
    tilt = design.search_strokes([60, -100], LEGS, G, "full+tilt", (-100.0, 60.0), cycles=3)
    assert len(tilt.strokes) == 3 and tilt.quality.identifiable


PROCEDURE = {"cycles": 2, "readings": 3, "settle_s": 0.1}  # on the builders' station


def test_summary_numbers_are_orthocal_s_and_the_plan_s() -> None:
    cfg = station_config(procedure=PROCEDURE)
    doc = design_summary(cfg, "rho", search=False)  # the configured plan's numbers
    plan = build_plan(cfg)
    keys, _ = plan_keys(plan)
    floor = orthocal.statistical_floor(keys, G, "rho", 1.0)
    assert list(doc["noise_gain"].values()) == pytest.approx(list(floor), rel=1e-12)
    t = doc["run_time"]
    # opening Π0 + 4 stops per cycle (Π+, Π−, Π0 and Π0 from the other side)
    stops = sum(1 + 4 * 2 for _ in plan.setups)
    assert t["stops"] == stops and t["settle_s"] == pytest.approx(0.1 * stops)
    assert t["total_s"] == pytest.approx(2 * (t["moves_s"] + t["settle_s"] + t["readings_s"]))
    # every stop is reached by two moves (to its approach point, then its last leg),
    # but the first, whose start nobody knows; and each waypoint the plan check put on
    # a move (independent axes, the profile's default: any timing) is a move of its own
    # (no controller asked: only the config limits the plan, as in design_summary)
    checked = check_plan(build_plan(cfg), cfg, ([-1e6] * 3, [1e6] * 3))
    waypoints = sum(len(via) for _, via in checked.waypoints_of())
    assert waypoints > 0
    assert t["moves"] == 2 * stops - 1 + waypoints


def test_search_never_leaves_the_config_soft_limits() -> None:
    data = station_data(procedure=PROCEDURE)
    L = 310.25
    data["machine"] = {"rho_min": -80.0, "rho_max": 40.0}
    data["controller"] = {"soft_min": [L - 90] * 3, "soft_max": [L + 50] * 3}
    cfg = parse_config(data)
    doc = design_summary(cfg, "rho")
    s = doc["search"]
    assert s["bounds_mm"] == [-90.0, 50.0] and "soft_min" in s["bounds_from"]
    assert all(-90 <= v <= 50 for v in s["strokes_mm"])
    assert s["strokes_mm"] != doc["strokes_mm"]  # the wider stops are worth proposing
    assert "rho_min = -90" in s["config"] or "rho_max = 50" in s["config"]
    assert s["d_criterion_log_det"] >= doc["d_criterion_log_det"]
    # the proposal passes the same plan check as a run (wide controller, config limits)
    check_plan(build_plan(cfg, s["strokes_mm"]), cfg, ([-1e6] * 3, [1e6] * 3))


def test_more_strokes_cost_time() -> None:
    cfg = station_config(procedure=PROCEDURE)
    two = run_time(build_plan(cfg), cfg)
    four = run_time(build_plan(cfg, [60, 30, -50, -100]), cfg)
    assert four["stops"] > two["stops"] and four["total_s"] > two["total_s"]


def test_cli_design_text_and_json(capsys) -> None:
    code, out, err = run_cli(capsys, "design", "--model", "full+tilt")
    assert code == 0, err
    assert "rank 8 of 9" in out and "cannot be told apart" in out and "D-optimal" in out
    code, out, _ = run_cli(capsys, "design", "--model", "full+tilt", "--strokes",
                           "60,30,-50,-100", "--json")
    assert code == 0
    doc = json.loads(out)
    assert doc["rank"] == 9 and doc["test_postures"] == ["+30", "+", "-50", "-"]
    assert doc["search"]["rank"] == 9


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--strokes", "0,30"], "procedure.strokes: must be finite and nonzero"),
        (["--strokes", "30,abc"], "--strokes: expected numbers"),
        (["--strokes", "30,90"], "procedure.strokes: 90 is outside"),
        (["--model", "nope"], "--model: must be one of"),
        (["--rho-min", "5"], "machine.rho_min"),
        (["--config", "/nonexistent/station.toml"], "/nonexistent/station.toml"),
    ],
)
def test_cli_design_bad_input_exits_2_with_one_line(capsys, argv, expected) -> None:
    code, out, err = run_cli(capsys, "design", *argv)
    assert code == 2 and out == ""
    assert expected in err and err.count("\n") == 1 and "Traceback" not in err


def test_cli_design_auto_shows_the_largest_model_the_postures_identify(capsys) -> None:
    code, out, _ = run_cli(capsys, "design", "--model", "auto", "--json")
    assert code == 0 and json.loads(out)["model"] == "rho+tilt+gap"
    code, out, _ = run_cli(capsys, "design", "--model", "auto", "--strokes", "60,30,-50,-100",
                           "--json")
    assert code == 0 and json.loads(out)["model"] == "full+tilt+gap"


def test_run_plan_includes_the_design_summary(tmp_path, capsys) -> None:
    """``orthocal run --plan`` asks the controller for its soft limits: the search
    stays inside them and inside the plungers' travel (the whole plan check)."""
    from station.commands.simulate.station_setups import SimulatedStation, gauges_for
    from station.config import load_config
    from station.config.toml import toml_text

    with SimulatedStation(gauges=gauges_for(6, mounted=True), seed=2) as station:
        path = tmp_path / "station.toml"
        path.write_text(toml_text(sim_station_config(station, {}), "test"))
        code, out, err = run_cli(capsys, "run", "--config", str(path), "--plan", "--out",
                                 str(tmp_path))
        assert code == 0, err
        assert "plan checked" in out and "design: model rho" in out and "D-optimal" in out
        code, out, err = run_cli(capsys, "run", "--config", str(path), "--plan", "--json",
                                 "--out", str(tmp_path))
        assert code == 0, err
        doc = json.loads(out)
    s = doc["design"]["search"]
    assert "controller" in s["bounds_from"]
    # the default model is auto: shown for rho+tilt+gap, the largest two stops identify
    assert doc["design"]["model"] == "rho+tilt+gap" and "auto" in doc["design"]
    keys = design.keys_for([60, -100], LEGS, G)
    floor = orthocal.statistical_floor(keys, G, "rho+tilt+gap", 1.0)
    assert list(doc["design"]["noise_gain"].values()) == pytest.approx(list(floor), rel=1e-9)
    cfg = load_config(path)
    lo, hi = doc["soft_limits"]["lower"], doc["soft_limits"]["upper"]
    check_plan(build_plan(cfg, s["strokes_mm"]), cfg, (lo, hi))
    assert s["d_criterion_log_det"] >= doc["design"]["d_criterion_log_det"]
    assert not list(tmp_path.glob("run-*"))


def test_a_verification_s_error_splits_into_noise_and_stands() -> None:
    """What sizes a verification's cycles (station.engine.sizing, decided): the
    gauges' part falls with the cycles, the stands' part does not, and on a machine
    whose legs do not slope (offsets written, axes that meet) there is none."""
    g = orthocal.Geometry()
    keys = design.keys_for((g.rho_max, g.rho_min), {"x": "yz", "y": "xz", "z": "xy"}, g)
    sd = 5.0 / np.sqrt(3.0)
    machine = np.zeros(12)  # the held-out machine of bench/gaps_vs_truth.py
    machine[6:] = (0.2, 0.1, -0.15, 0.15, -0.10, 0.12)  # tilts mrad, gaps mm
    few = design.drho_error_parts(keys, g, "rho+tilt+gap", machine, 0.55e-3 / np.sqrt(3), sd)
    many = design.drho_error_parts(keys, g, "rho+tilt+gap", machine, 0.55e-3 / np.sqrt(27), sd)
    assert np.allclose(many[0], few[0] / 3.0, rtol=1e-9)
    assert np.all(many[1] > 0.75 * few[1]) and many[1][1] > 0.5e-3
    # the noise part is the design's noise gain times the deviation's error (the
    # gain at the nominal machine, linear; here exact at the held-out one: 2e-5 apart)
    q = design.quality(keys, g, "rho+tilt+gap")
    assert few[0][0] == pytest.approx(q.noise_gain["drho_x"] * 0.55e-3 / np.sqrt(3), rel=1e-3)
    square = design.drho_error_parts(keys, g, "rho", np.zeros(12), 0.3e-3, sd)
    assert np.all(square[1] < 1e-9)
