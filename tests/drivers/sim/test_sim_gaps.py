"""The simulator's axes that do not meet (``--true-gap X,Y,Z``: gap_xy, gap_xz, gap_yz in
mm; docs/model.md, "Axes that do not meet"), as ``--true-tilt`` is given: on ``run
--simulate`` and ``orthocal sim``, kept in the journal header for resume, recorded
in the result beside the tilts.

The readings are those of the real gauge driver over the pseudo-terminals of a
virtual station on a stepped clock (nothing depends on the host's speed); what
they should be is computed from orthocal.leg_reading alone. No whole run here.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import parsed_simulate

import orthocal
from drivers.indicators import SerialIndicator
from drivers.sim.specs import GaugeSpec, MachineTruth
from drivers.sim.station import VirtualStation
from station.commands import cli
from station.commands.options import SimOptions
from station.commands.simulate.launch import gaps_mm, sim_params, start_station
from station.commands.simulate.station_setups import gauges_for
from station.config import parse_config
from station.engine.results import base_result
from station.errors import BadInput
from station.record.migrate import migrate
from station.record.result import Simulation
from station.report.format import true_value

G = orthocal.Geometry()
M = G.mount_plane
PI0 = orthocal.posture("0", None, G)
DRHO = np.array([0.9, -1.2, 0.6])
GAP = (0.3, -0.2, 0.25)  # gap_xy, gap_xz, gap_yz (mm): a frame's tenths of a millimetre
GAP_NAMES = ("gap_xy", "gap_xz", "gap_yz")
DIGIT = 0.001  # the gauges' quantisation (mm)
# Two stands off the leg's middle, so that the gauge planes differ from L/2.
STANDS = {"A": 2.5, "D": -3.0}
# Long plungers (stroke, preload; mm): every gauge is read at every posture, also at
# the other legs' postures, where it travels tens of mm, and none leaves its stroke.
LONG = (100.0, 50.0)


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


@contextmanager
def six_gauges(gap: Any) -> Iterator[tuple[VirtualStation, Clock, dict[str, SerialIndicator]]]:
    """A virtual station on a stepped clock, its six gauges (two per leg, D reversed,
    long plungers) mounted at Π0, each read by the real driver over its
    pseudo-terminal."""
    clock = Clock()
    with ExitStack() as stack:
        gauges = gauges_for(6, GaugeSpec(noise_mm=0.0, line_time=False, mount_errors=STANDS,
                                         strokes={n: LONG for n in "ABCDEF"}), mounted=True)
        st = stack.enter_context(VirtualStation(MachineTruth(drho=DRHO, gap=gap),
                                                gauges=gauges, clock=clock))
        gauges = {n: stack.enter_context(SerialIndicator(n, ind.port, "mitutoyo",
                                                         timeout_s=2.0))
                  for n, ind in st.indicators.items()}
        yield st, clock, gauges


def path() -> list[np.ndarray]:
    """Π0, then each leg's two postures, then joints off them."""
    postures = [PI0, *(orthocal.posture(s, leg, G) for leg in "xyz" for s in "+-")]
    rng = np.random.default_rng(31)
    return postures + [p + rng.uniform(-3.0, 3.0, 3) for p in postures[1:4]]


def readings_along(gap: Any) -> tuple[np.ndarray, list[tuple[str, str, str, float]]]:
    """Every gauge's reading at each posture of path() (rows; columns in the order of
    the mount log), with that log: (name, leg, direction, stand error)."""
    with six_gauges(gap) as (st, clock, gauges):
        mounts = list(st.mount_log)
        rows = []
        for rho in path():
            clock.t += st.machine.move_to(rho) + 0.01
            rows.append([gauges[name].read() for name, *_ in mounts])
        assert st.out_of_stroke == []
        return np.array(rows), mounts


def predicted(gap: Any, mounts: list[tuple[str, str, str, float]]) -> np.ndarray:
    """What the maths says each gauge reads along path(): its travel from where it
    was zeroed (Π0), negated for a reversed gauge."""
    rows = []
    for rho in path():
        row = []
        for _name, leg, direction, stand in mounts:
            sign, axis = (-1.0 if direction.startswith("-") else 1.0), direction.lstrip("-")
            at = [float(orthocal.leg_reading(r, leg, axis, G, DRHO, mount=M + stand, gap=gap))
                  for r in (rho, PI0)]
            row.append(sign * (at[0] - at[1]))
        rows.append(row)
    return np.array(rows)


# --- the machine under the gauges --------------------------------------------------------


def test_the_gauges_see_the_gaps_that_leg_reading_predicts() -> None:
    gapped, mounts = readings_along(GAP)
    straight, mounts_0 = readings_along((0.0, 0.0, 0.0))
    assert mounts == mounts_0
    assert [(n, leg, d) for n, leg, d, _ in mounts] == [
        ("A", "x", "y"), ("B", "x", "z"), ("C", "y", "x"), ("D", "y", "-z"),
        ("E", "z", "x"), ("F", "z", "y")]
    assert {n: s for n, _, _, s in mounts if s} == STANDS
    want, want_0 = predicted(GAP, mounts), predicted(None, mounts)
    # each reading is its exact value to within half a digit ...
    np.testing.assert_allclose(gapped, want, rtol=0, atol=DIGIT / 2 + 1e-9)
    np.testing.assert_allclose(straight, want_0, rtol=0, atol=DIGIT / 2 + 1e-9)
    # ... so the gaps' effect, gapped minus gapless, is leg_reading's to within one
    np.testing.assert_allclose(gapped - straight, want - want_0, rtol=0, atol=DIGIT + 1e-9)
    # Π0, where every gauge was zeroed, reads zero; elsewhere the gaps show, tens of µm
    assert np.all(gapped[0] == 0.0) and np.all(straight[0] == 0.0)
    assert np.max(np.abs(gapped - straight)) > 0.03
    assert np.count_nonzero(np.abs(want - want_0) > 5 * DIGIT) >= 10


def test_the_station_hands_its_gaps_to_the_machine() -> None:
    with VirtualStation(MachineTruth(gap=GAP), gauges=GaugeSpec(line_time=False)) as st:
        assert st.machine.true_gap.tolist() == list(GAP)
    with VirtualStation(gauges=GaugeSpec(line_time=False)) as st:
        assert st.machine.true_gap.tolist() == [0.0, 0.0, 0.0]


# --- the command line, the journal, the result ---------------------------------------------


def test_the_option_survives_the_journal_round_trip() -> None:
    params = sim_params(SimOptions.from_args(parsed_simulate("--true-gap", "0.3,-0.2,0.25",
                                                      "--true-tilt", "0.1,0,-0.1")))
    saved = json.loads(json.dumps(params))  # the journal header is JSON
    assert saved["true_gap"] == list(GAP)
    assert saved["true_tilt"] == [0.1, 0.0, -0.1]
    # not given: axes that meet; given as numbers (benches, tests): the same as text
    assert sim_params(SimOptions.from_args(parsed_simulate()))["true_gap"] == [0.0, 0.0, 0.0]
    assert sim_params(SimOptions(seed=1, true_gap=GAP))["true_gap"] == list(GAP)
    # a journal from before the gaps has none: it resumes with axes that meet
    old = {k: v for k, v in saved.items() if k != "true_gap"}
    for header, gap in ((saved, list(GAP)), (old, [0.0, 0.0, 0.0])):
        st = start_station(header, None)
        try:
            assert st.machine.true_gap.tolist() == gap
            assert st.machine.true_tilt.tolist() == [0.1, 0.0, -0.1]
            config = parse_config(st.config(), "virtual station config")
        finally:
            st.close()
        result = base_result(Path("run"), config, header, "2026-01-01T00:00:00")
        # the record as the run starts it, as result.json would hold it
        doc = json.loads(result.model_dump_json(exclude_unset=True))
        assert doc["simulation"]["true_gap"] == dict(zip(GAP_NAMES, gap, strict=True))
        assert list(doc["simulation"]).index("true_gap") == \
            list(doc["simulation"]).index("true_tilt") + 1
        # the report's hidden truth of an identified gap
        sim = Simulation.model_validate(doc["simulation"])
        assert [true_value(sim, n) for n in GAP_NAMES] == gap
    # a result from before the gaps is read as one whose axes met (station.record.
    # migrate): their truth is 0
    del doc["schema_version"], doc["simulation"]["true_gap"]
    sim = Simulation.model_validate(migrate(doc)["simulation"])
    assert true_value(sim, "gap_xy") == 0.0
    assert true_value(sim, "tilt_zy") == -0.1
    assert true_value(None, "tilt_zy") is None  # not a simulated run


BAD = [
    ["--true-gap", "1,2"],
    ["--true-gap", "a,b,c"],
    ["--true-gap", "1,2,3,4"],
    ["--true-gap", "0.1,nan,0"],
    ["--true-gap", "inf,0,0"],
    ["--true-gap", ""],
]


@pytest.mark.parametrize("argv", BAD)
def test_bad_values_are_one_line_naming_the_option_and_exit_2(
        argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(BadInput, match=r"^--true-gap: "):
        sim_params(SimOptions.from_args(parsed_simulate(*argv)))
    code = cli.main(["run", "--simulate", "--seed", "5", "--out", str(tmp_path / "runs"), *argv])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("orthocal: error: --true-gap: ") and err.count("\n") == 1, err
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


@pytest.mark.parametrize("argv", BAD[:2])
def test_orthocal_sim_checks_them_before_serving(
        argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sim.toml"
    code = cli.main(["sim", "--config-out", str(out), *argv])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("orthocal: error: --true-gap: "), err
    assert err.count("\n") == 1 and not out.exists()


def test_numbers_given_directly_are_checked_too() -> None:
    assert gaps_mm(None) == [0.0, 0.0, 0.0]
    assert gaps_mm([0, -0.5, 1]) == [0.0, -0.5, 1.0]
    for bad in ((0.1, 0.2), (0.1, float("nan"), 0.0), ("x", 0, 0)):
        with pytest.raises(BadInput, match=r"^--true-gap: "):
            gaps_mm(bad)  # type: ignore[arg-type]
