"""The simulator has the errors the budget counts: bowed legs
(``--leg-bow``) and gauges with a scale error (``--gauge-scale``).

A bow of sagitta h shows as 4h·t(1 − t) where the gauge's base-fixed plane
touches the leg, t the fraction along it from the carriage (drivers.sim.bowed_legs);
the expected values here are computed from orthocal.forward and the posture
alone, the readings over the gauges' pseudo-terminals. Every move uses a
stepped clock: nothing depends on the host's speed.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import FAST, no_figures_file, parsed_simulate, resumed, simulated

import orthocal
from drivers.indicators import SerialIndicator
from drivers.sim.bowed_legs import contact_fraction
from drivers.sim.machine import VirtualOrthoglide
from drivers.sim.pty_gauges import SimIndicator
from drivers.sim.specs import GaugeSpec, MachineTruth
from drivers.sim.station import VirtualStation
from station import report
from station.commands import cli
from station.commands.options import SimOptions
from station.commands.simulate.launch import sim_params, start_station
from station.commands.simulate.station_setups import SimulatedStation
from station.errors import BadInput
from station.record.journal_file import read_journal

G = orthocal.Geometry()
M = G.mount_plane
PI0 = orthocal.posture("0", None, G)
DRHO = np.array([0.9, -1.2, 0.6])  # hidden offsets: the gauges travel a few 0.1 mm
BOW = 0.05  # a sagitta large enough to see on a 1 µm gauge (7.5 µm at Π_x^+)
DIGIT = 0.001  # the gauges' quantisation (mm)


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def fraction(rho: np.ndarray, leg: str, drho: np.ndarray = DRHO) -> float:
    """t = (q_i − M)/(q_i − p_i) on an untilted machine, from orthocal alone."""
    i = "xyz".index(leg)
    p = orthocal.forward(rho, G, drho)
    q = rho[i] + drho[i]
    return float((q - M) / (q - p[i]))


def parabola(t: float, h: float = BOW) -> float:
    return 4.0 * h * t * (1.0 - t)


@contextmanager
def station(leg_bow: Any = (0.0, 0.0, 0.0), strokes: Any = None, gauge_scale: Any = 0.0
            ) -> Iterator[tuple[SimulatedStation, Clock, dict[str, SerialIndicator]]]:
    """A virtual station on a stepped clock, A and B on leg x along y and z, each
    read by the real driver over its pseudo-terminal."""
    clock = Clock()
    gauges_spec = GaugeSpec(noise_mm=0.0, line_time=False, strokes=strokes or {},
                            scale=gauge_scale)
    with ExitStack() as stack:
        st = stack.enter_context(SimulatedStation(MachineTruth(drho=DRHO, leg_bow=leg_bow),
                                                  gauges=gauges_spec, clock=clock))
        st.mount("A", "x", "y")
        st.mount("B", "x", "z")
        gauges = {n: stack.enter_context(SerialIndicator(n, st.indicators[n].port, "mitutoyo",
                                                         timeout_s=2.0))
                  for n in "AB"}
        yield st, clock, gauges


def go(st: VirtualStation, clock: Clock, rho: np.ndarray) -> None:
    clock.t += st.machine.move_to(rho) + 0.01


def readings_along(path: list[np.ndarray], **kw: Any) -> np.ndarray:
    """The readings of A and B at each posture of ``path`` (rows), over the ptys."""
    with station(**kw) as (st, clock, gauges):
        out = []
        for rho in path:
            go(st, clock, rho)
            out.append([gauges[n].read() for n in "AB"])
        return np.array(out)


# --- the bow ---------------------------------------------------------------------------


def test_a_bowed_leg_shows_the_parabola_where_the_gauge_plane_touches_it() -> None:
    plus, minus = (orthocal.posture(s, "x", G) for s in "+-")
    path = [plus, PI0, minus, PI0]
    straight = readings_along(path)
    bowed = readings_along(path, leg_bow=(BOW, BOW, BOW))
    t0 = fraction(PI0, "x")
    for row, rho in enumerate(path):
        expected = parabola(fraction(rho, "x")) - parabola(t0)
        # both gauge planes of the leg see the same h; each reading is within half a
        # digit of its exact value, so their difference within one
        for col in range(2):
            assert bowed[row, col] - straight[row, col] == pytest.approx(expected, abs=DIGIT)
    # visible, not lost in the digits: 7.5 µm less at Π_x^+, 21 µm at Π_x^-, none at Π0
    assert bowed[0, 0] - straight[0, 0] < -0.006
    assert bowed[2, 0] - straight[2, 0] < -0.019
    assert np.all(bowed[[1, 3]] == 0.0) and np.all(straight[[1, 3]] == 0.0)


def test_the_bow_is_exact_with_misplaced_stands_tilts_and_reversed_gauges() -> None:
    # Unquantised: the machine's own readings, bowed minus straight, are the parabola
    # at the t where the plane meets the leg's axis A → P (A = q_i·u_i when tilted).
    tilt = np.array([0.4, -0.3, 0.25])
    bow = np.array([0.03, -0.02, 0.05])
    kw: dict[str, Any] = {"true_drho": DRHO, "true_dl": (0.02, -0.01, 0.03), "true_tilt": tilt}
    clock = Clock()
    straight = VirtualOrthoglide(G, clock=clock, **kw)
    bowed = VirtualOrthoglide(G, clock=clock, leg_bow=bow, **kw)
    assert bowed.leg_bow.tolist() == bow.tolist()
    u = orthocal.axis_directions(tilt)
    for sign, leg in (("+", "x"), ("-", "y"), ("+", "z"), ("0", None)):
        rho = orthocal.posture(sign, leg, G)
        for m in (straight, bowed):
            clock.t += m.move_to(rho) + 0.01
        p = orthocal.forward(rho, G, DRHO, kw["true_dl"], tilt)
        for i, gauge_leg in enumerate("xyz"):
            a = (rho[i] + DRHO[i]) * u[i]
            for plane in (M, M + 6.0):
                t = (plane - a[i]) / (p[i] - a[i])
                # the point of the axis at t is in the gauge's plane
                assert (a + t * (p - a))[i] == pytest.approx(plane, abs=1e-9)
                assert contact_fraction(rho, gauge_leg, G, DRHO, np.array(kw["true_dl"]),
                                        tilt, plane) == pytest.approx(t, abs=1e-12)
                for direction in "xyz".replace(gauge_leg, ""):
                    diff = bowed.leg_reading(gauge_leg, direction, plane) \
                        - straight.leg_reading(gauge_leg, direction, plane)
                    assert diff == pytest.approx(parabola(t, bow[i]), abs=1e-12)
    # a gauge mounted reversed reads the coordinate negated, the bow with it
    with station(leg_bow=(BOW, 0.0, 0.0)) as (st, clock, gauges):
        st.mount("B", "x", "-z")
        go(st, clock, orthocal.posture("-", "x", G))
        expected = parabola(fraction(orthocal.posture("-", "x", G), "x")) \
            - parabola(fraction(PI0, "x"))
        straight_b = -float(orthocal.leg_reading(orthocal.posture("-", "x", G), "x", "z", G,
                                                 DRHO)) \
            + float(orthocal.leg_reading(PI0, "x", "z", G, DRHO))
        assert gauges["B"].read() == pytest.approx(straight_b - expected, abs=DIGIT / 2 + 1e-9)


def test_the_stroke_watch_sees_the_bow_too() -> None:
    # A plunger just short enough of its stop for the straight leg at Π_x^-: the
    # bowed leg drives it past, and the count from the trajectory sees that.
    minus = orthocal.posture("-", "x", G)
    straight_travel = float(orthocal.leg_reading(minus, "x", "y", G, DRHO)
                            - orthocal.leg_reading(PI0, "x", "y", G, DRHO))
    # t leaves ½ at Π_x^-, so a negative bow pushes the plunger further in there
    bow = -0.5
    rise = parabola(fraction(minus, "x"), bow) - parabola(fraction(PI0, "x"), bow)
    assert straight_travel > 0 and rise > 0.1
    high = straight_travel + rise / 2  # the stop lies between the two travels
    strokes = {"A": (12.5, 12.5 - high), "B": (12.5, 6.25)}
    counts = []
    for leg_bow in ((0.0, 0.0, 0.0), (bow, bow, bow)):
        with station(leg_bow=leg_bow, strokes=strokes) as (st, clock, _):
            go(st, clock, minus)
            counts.append([(e.gauge, e.end) for e in st.out_of_stroke])
    assert counts == [[], [("A", "high")]]


# --- the gauge scale -------------------------------------------------------------------


def test_a_scale_error_multiplies_the_plungers_travel() -> None:
    where = {"mm": 10.0}
    with SimIndicator("mitutoyo", lambda: where["mm"], scale_error=0.002, stroke_mm=12.5) \
            as sim, SerialIndicator("A", sim.port, "mitutoyo", timeout_s=2.0) as ind:
        for travel in (5.0, -3.0, 0.0, 1.2345):
            where["mm"] = 10.0 + travel
            assert ind.read() == pytest.approx(1.002 * travel, abs=DIGIT / 2 + 1e-9)
        # the stop is the plunger's, in true mm; the display scales what it shows there
        where["mm"] = 10.0 + 8.0
        assert ind.read() == pytest.approx(1.002 * 6.25, abs=DIGIT / 2 + 1e-9)
        assert sim.clamped == 1
        sim.unmount()  # on the bench: its constant reading, no travel to scale
        assert ind.read() == 0.0
    for bad in (1.0, -1.5, float("nan")):
        with pytest.raises(ValueError, match="scale_error"):
            SimIndicator("mitutoyo", lambda: 0.0, scale_error=bad)


def test_the_station_gives_each_gauge_its_scale_in_the_configs_order() -> None:
    minus = orthocal.posture("-", "x", G)
    scales = (0.02, -0.03)
    with station(gauge_scale=scales) as (st, clock, gauges):
        assert [ind["name"] for ind in st.config()["indicators"]] == ["A", "B"]
        assert st.gauge_scale == {"A": 0.02, "B": -0.03}
        go(st, clock, minus)
        for name, s, direction in (("A", scales[0], "y"), ("B", scales[1], "z")):
            travel = st.indicators[name].travel_mm(st.source("x", direction)())
            assert abs(travel) > 0.2  # so that the scale shows: > 4 µm
            assert gauges[name].read() == pytest.approx((1 + s) * travel,
                                                        abs=DIGIT / 2 + 1e-9)
    with VirtualStation(gauges=GaugeSpec(scale={"B": 0.001}, line_time=False)) as st:
        assert st.gauge_scale == {"A": 0.0, "B": 0.001}
    for bad in ((0.1, 0.2, 0.3), {"Q": 0.1}):
        with pytest.raises(ValueError):
            VirtualStation(gauges=GaugeSpec(scale=bad, line_time=False))


# --- the command line, the journal, resume ---------------------------------------------


def test_both_options_survive_the_journal_round_trip() -> None:
    params = sim_params(SimOptions.from_args(parsed_simulate("--leg-bow", "0.01,-0.02,0.03",
                                                      "--gauge-scale", "0.001,-0.002")))
    saved = json.loads(json.dumps(params))  # the journal header is JSON
    assert saved["leg_bow_mm"] == [0.01, -0.02, 0.03]
    assert saved["gauge_scale"] == [0.001, -0.002]
    one = sim_params(SimOptions.from_args(parsed_simulate("--leg-bow", "0.008", "--gauge-scale",
                                                   "0.002")))
    assert one["leg_bow_mm"] == [0.008] * 3 and one["gauge_scale"] == [0.002] * 2
    six = sim_params(SimOptions(seed=1, gauge_scale="0.001", indicators=6))
    assert six["gauge_scale"] == [0.001] * 6
    plain = sim_params(SimOptions.from_args(parsed_simulate()))
    assert plain["leg_bow_mm"] == [0.0] * 3 and plain["gauge_scale"] == [0.0] * 2
    old = {k: v for k, v in saved.items() if k not in ("leg_bow_mm", "gauge_scale")}
    for header, bow, scale in ((saved, [0.01, -0.02, 0.03], {"A": 0.001, "B": -0.002}),
                               (old, [0.0] * 3, {"A": 0.0, "B": 0.0})):
        st = start_station(header, None)
        try:
            assert st.machine.leg_bow.tolist() == bow
            assert st.gauge_scale == scale
            assert {n: s.scale_error for n, s in st.indicators.items()} == scale
        finally:
            st.close()


BAD = [
    (["--leg-bow", "thick"], "--leg-bow"),
    (["--leg-bow", "0.01,0.02"], "--leg-bow"),
    (["--leg-bow", "0,nan,0"], "--leg-bow"),
    (["--leg-bow", "inf"], "--leg-bow"),
    (["--leg-bow", "8"], "--leg-bow"),  # 8 µm given as mm
    (["--gauge-scale", "0.2"], "--gauge-scale"),  # 0.2 % given as a fraction
    (["--gauge-scale", "-0.5"], "--gauge-scale"),
    (["--gauge-scale", "nan"], "--gauge-scale"),
    (["--gauge-scale", "1%"], "--gauge-scale"),
    (["--gauge-scale", "0.001,0.002,0.003"], "--gauge-scale"),  # two gauges
]


@pytest.mark.parametrize("argv, option", BAD)
def test_bad_values_are_one_line_naming_the_option_and_exit_2(
        argv: list[str], option: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(BadInput, match=f"^{option}: "):
        sim_params(SimOptions.from_args(parsed_simulate(*argv)))
    code = cli.main(["run", "--simulate", "--seed", "5", "--out", str(tmp_path / "runs"), *argv])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"orthocal: error: {option}: ") and err.count("\n") == 1, err
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


@pytest.mark.parametrize("argv, option", [
    (["--leg-bow", "0.01,0.02"], "--leg-bow"),
    (["--leg-bow", "-2"], "--leg-bow"),
    (["--gauge-scale", "0.001,0.002"], "--gauge-scale"),  # six gauges: one or six
    (["--gauge-scale", "big"], "--gauge-scale"),
])
def test_orthocal_sim_checks_them_before_serving(
        argv: list[str], option: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sim.toml"
    code = cli.main(["sim", "--config-out", str(out), *argv])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith(f"orthocal: error: {option}: "), err
    assert err.count("\n") == 1 and not out.exists()


def test_an_interrupted_run_resumes_with_the_same_bow_and_scales(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from station.commands import run as cmd_run
    from station.errors import RunFailed

    stations: list[VirtualStation] = []

    def keep(st: VirtualStation) -> None:
        stations.append(st)
        if len(stations) == 1:
            st.controller.faults.alarm_after_moves = 5

    args = simulated(tmp_path / "runs", true_drho=(0.7, -1.1, 0.5), leg_bow="0.004,0.008,-0.006",
                     gauge_scale="0.001,-0.002", hook=keep)
    with pytest.raises(RunFailed, match="alarm 17"):
        cmd_run.run(args)
    (run_dir,) = list((tmp_path / "runs").glob("run-*"))
    header = read_journal(run_dir / "journal.jsonl")[0]  # the run's header
    assert header["simulation"]["leg_bow_mm"] == [0.004, 0.008, -0.006]
    assert header["simulation"]["gauge_scale"] == [0.001, -0.002]
    capsys.readouterr()
    code = cmd_run.resume(resumed(run_dir, hook=keep))
    result = json.loads(capsys.readouterr().out)
    assert result["status"] == "ok", result["message"]
    assert code == (3 if report.not_converged(result) else 0), result["message"]
    assert len(stations) == 2
    for st in stations:
        assert st.machine.leg_bow.tolist() == [0.004, 0.008, -0.006]
        assert st.gauge_scale == {"A": 0.001, "B": -0.002}


def test_a_whole_simulated_run_with_bowed_legs_completes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # Through the command line's own parsing; how far the bow biases the result is
    # the error budget's to say, not this test's.
    code = cli.main(["run", "--simulate", no_figures_file(tmp_path), "--seed", "11",
                     "--leg-bow", "0.008", "--gauge-scale", "0.001", "--out",
                     str(tmp_path / "runs"), "--json", "--yes",
                     "--sim-procedure", json.dumps(FAST)])
    result = json.loads(capsys.readouterr().out)
    # "ok" even where the loop could not prove convergence (its message says so, and
    # the exit status is 3)
    assert result["status"] == "ok", result["message"]
    assert code == (3 if report.not_converged(result) else 0), result["message"]
    assert result["verification"] is not None
    (run_dir,) = list((tmp_path / "runs").glob("run-*"))
    header = read_journal(run_dir / "journal.jsonl")[0]  # the run's header
    assert header["simulation"]["leg_bow_mm"] == [0.008] * 3
    assert header["simulation"]["gauge_scale"] == [0.001] * 2


def test_the_simulators_bow_is_the_maths_bow() -> None:
    # drivers/sim/bowed_legs.py is computed from the end point alone, apart from
    # orthocal.measurement's bow, so that each checks the other: tilted axes, leg
    # errors, a misplaced plane, joints at and around the test postures.
    from drivers.sim.bowed_legs import bow_mm

    rng = np.random.default_rng(23)
    g = orthocal.Geometry()
    postures = np.array([orthocal.posture(s, i, g) for s, i in
                         [("0", None), *((s, i) for i in "xyz" for s in "+-")]])
    for _ in range(20):
        drho, dl = rng.uniform(-1.5, 1.5, 3), rng.uniform(-0.5, 0.5, 3)
        tilt = rng.uniform(-0.5, 0.5, 3)
        rho = postures + rng.uniform(-2, 2, postures.shape)
        mount = g.mount_plane + rng.uniform(-5, 5)
        for leg in "xyz":
            t_sim = contact_fraction(rho, leg, g, drho, dl, tilt, mount)
            t_maths = orthocal.contact_fraction(rho, leg, g, drho, dl, mount, tilt)
            np.testing.assert_allclose(t_sim, t_maths, rtol=0, atol=1e-12)
            np.testing.assert_allclose(bow_mm(t_sim, 0.008), orthocal.bow_at(t_maths, 0.008),
                                       rtol=0, atol=1e-15)


def test_each_gauge_plane_bows_by_its_own_sagitta_as_the_maths_has_it() -> None:
    # plane_bow: each gauge plane's own sagitta on top of its leg's, so that a machine
    # can be bowed as the statement assumes (orthocal.budget_columns: each plane within
    # ±s, half of it common); its deviations are orthocal.deviations' with one bow per
    # gauge plane, at every test posture of a tilted, gapped machine
    from drivers.sim.legs import PLANES
    from orthocal.stands import GAUGES

    assert PLANES == GAUGES  # plane_bow's order is the maths' gauges'
    tilt, gap = np.array([0.2, 0.1, -0.15]), np.array([0.1, -0.05, 0.08])
    leg = np.array([0.001, 0.0, -0.002])
    own = np.array([0.003, -0.002, 0.004, 0.001, -0.003, 0.002])
    machine = VirtualOrthoglide(G, DRHO, np.zeros(3), true_tilt=tilt, true_gap=gap,
                                leg_bow=leg, plane_bow=own)
    plain = VirtualOrthoglide(G, DRHO, np.zeros(3), true_tilt=tilt, true_gap=gap)
    params = np.concatenate([DRHO, np.zeros(3), tilt, gap])
    bows = {g: own[n] + leg["xyz".index(g[0])] for n, g in enumerate(GAUGES)}
    seen = []
    for gauge_leg, direction in GAUGES:
        for sign in "+-":
            rho = orthocal.posture(sign, gauge_leg, G)
            sim = machine.readings(rho, gauge_leg, direction) \
                - machine.readings(PI0, gauge_leg, direction)
            key = [(sign, gauge_leg, direction)]
            assert float(sim) == pytest.approx(
                orthocal.deviations(key, G, params, bow=bows)[0], abs=1e-12)
            seen.append(float(sim) - float(plain.readings(rho, gauge_leg, direction)
                                           - plain.readings(PI0, gauge_leg, direction)))
    # every plane bowed (z along y: the leg's −2 µm and the plane's +2 µm cancel)
    assert sum(abs(s) > 1e-4 for s in seen) == 10
    with pytest.raises(ValueError, match="plane_bow"):
        VirtualOrthoglide(G, plane_bow=(0.0, 0.0, 0.0))
