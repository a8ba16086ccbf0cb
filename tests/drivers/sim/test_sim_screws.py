"""The simulator's screws (``--joint-lead``, ``--joint-pitch``; drivers.sim.screws): the
drive counts its motor, the carriage stands at the motor plus each joint's error
counted from home, through its dead band; what the gauges then see agrees with
orthocal's model of joint errors (docs/model.md, "Joint positioning errors"), and
the options are checked, journaled and named in the result."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from builders import PAPER_KEYS as PAPER
from builders import parsed_simulate

import orthocal
from drivers.sim.machine import VirtualOrthoglide
from station.commands import cli
from station.commands.options import SimOptions
from station.commands.simulate.launch import sim_params, start_station
from station.errors import BadInput

G = orthocal.Geometry()
L = G.leg_length
PI0 = orthocal.posture("0", None, G)
DRHO = np.array([0.6, -0.4, 0.9])
LEAD = (100.0, -80.0, 60.0)


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def machine(**kw) -> tuple[VirtualOrthoglide, Clock]:
    clock = Clock()
    return VirtualOrthoglide(G, true_drho=DRHO, clock=clock, **kw), clock


def go(m: VirtualOrthoglide, clock: Clock, rho) -> None:
    clock.t += m.move_to(np.asarray(rho, dtype=float)) + 0.01


def test_the_carriage_is_the_count_plus_the_lead_from_home() -> None:
    m, clock = machine(joint_lead=LEAD)
    k = np.array(LEAD) * 1e-6
    for rho in ([L + 60.0, L - 20.0, L - 100.0], [L, L, L], [250.0, 330.0, 300.0]):
        go(m, clock, rho)
        rho = np.array(rho)
        # the drive counts its motor: it reports what it was told
        assert m.actual() == pytest.approx(rho, abs=1e-12)
        assert m.joint_values() == pytest.approx(rho + DRHO + k * (rho - L), abs=1e-12)
    # 100 µm/m over 60 mm: 6 µm, what the carriage is off at Π_x^+
    go(m, clock, [L + 60.0, L, L])
    assert (m.joint_values() - DRHO)[0] - (L + 60.0) == pytest.approx(0.006, abs=1e-12)
    # exact screws: the carriage is the count, to the bit
    exact, clock2 = machine()
    rho = np.array([L + 60.0, L - 20.0, L - 100.0])
    go(exact, clock2, rho)
    assert np.array_equal(exact.joint_values(), rho + DRHO)


def test_the_play_follows_the_nut_and_the_offsets_move_the_motor_on_its_screw() -> None:
    b = np.array([0.01, 0.006, 0.008])
    m, clock = machine(joint_lead=LEAD, backlash=b)
    k = np.array(LEAD) * 1e-6
    up = np.array([L + 30.0, L + 30.0, L + 30.0])
    go(m, clock, up - 1.0)
    go(m, clock, up)  # arrived from below: B/2 short of the nut
    assert m.joint_values() - DRHO == pytest.approx(up + k * (up - L) - b / 2, abs=1e-12)
    go(m, clock, up + 1.0)
    go(m, clock, up)  # from above: B/2 beyond
    assert m.joint_values() - DRHO == pytest.approx(up + k * (up - L) + b / 2, abs=1e-12)
    # offsets written: a commanded ρ puts the motor at ρ + o on its screw, whose error
    # counts from the home switch (model.md (J1): ε at ρ + o)
    o = np.array([-0.6, 0.4, -0.9])
    m2, clock2 = machine(joint_lead=LEAD)
    m2.set_offsets(o)
    go(m2, clock2, up)
    assert m2.joint_values() == pytest.approx(up + o + DRHO + k * (up + o - L), abs=1e-12)


def test_a_periodic_error_and_a_home_elsewhere() -> None:
    m, clock = machine(joint_pitch=(2.0, 5.0))
    for rho in ([L + 1.25, L + 2.5, L - 3.75], [L + 41.0, L - 7.3, L - 60.1]):
        go(m, clock, rho)
        travel = np.array(rho) - L
        assert m.joint_values() - DRHO == pytest.approx(
            np.array(rho) + 2e-3 * np.sin(2 * np.pi * travel / 5.0), abs=1e-12)
    home = np.array([L - 100.0, L - 100.0, L - 100.0])
    m2, clock2 = machine(joint_lead=LEAD, home_position=home)
    go(m2, clock2, PI0)  # a constant at Π0, the zero error's to take
    assert m2.joint_values() - DRHO == pytest.approx(PI0 + np.array(LEAD) * 1e-4, abs=1e-12)
    for bad, said in (({"joint_lead": (1.0, 2.0)}, "joint_lead"),
                      ({"joint_pitch": (1.0, 0.0)}, "period"),
                      ({"joint_pitch": (-1.0, 5.0)}, "amplitude")):
        with pytest.raises(ValueError, match=said):
            machine(**bad)


def deviations_of(m: VirtualOrthoglide, clock: Clock) -> np.ndarray:
    """The paper's 12 deviations as the machine's legs give them (noise-free), every
    stop approached from below as the station's default does."""
    out = []
    for sign, leg, along in PAPER:
        readings = []
        for s, lg in ((sign, leg), ("0", None)):
            rho = orthocal.posture(s, lg, G)
            go(m, clock, rho - 0.05)
            go(m, clock, rho)
            readings.append(m.leg_reading(leg, along))
        out.append(readings[0] - readings[1])
    return np.array(out)


def test_the_gauges_see_what_orthocal_says_a_lead_does_at_second_order() -> None:
    theta = np.concatenate([DRHO, np.zeros(9)])
    lead, clock = machine(joint_lead=LEAD, backlash=(0.004, 0.004, 0.004))
    exact, clock2 = machine(backlash=(0.004, 0.004, 0.004))
    seen = deviations_of(lead, clock)
    # the model's tables of the same screws, and the same play: every stop from below
    errors = orthocal.JointErrors(*(orthocal.lead_table(k, (150.0, 400.0), L)
                                    .with_reversal(0.004) for k in LEAD))
    model = orthocal.joint_error_deviations(PAPER, G, theta, errors, "forward")
    assert seen == pytest.approx(model, abs=1e-9)
    # the change a lead makes: about a micrometre, the closed form (J4) within 0.03 µm
    change = (seen - deviations_of(exact, clock2)) * 1e3
    closed = orthocal.lead_deviation_change(PAPER, G, LEAD) * 1e3
    assert np.max(np.abs(change - closed)) < 0.03
    assert 0.5 < np.max(np.abs(change)) < 1.5


# --- the options -----------------------------------------------------------------------


def test_the_options_are_journaled_and_resume_rebuilds_the_screws() -> None:
    params = sim_params(SimOptions.from_args(parsed_simulate(
        "--joint-lead", "100,-80,60", "--joint-pitch", "2,5")))
    saved = json.loads(json.dumps(params))  # the journal header is JSON
    assert saved["joint_lead_um_per_m"] == [100.0, -80.0, 60.0]
    assert saved["joint_pitch"] == [2.0, 5.0]
    one = sim_params(SimOptions.from_args(parsed_simulate("--joint-lead", "50")))
    assert one["joint_lead_um_per_m"] == [50.0] * 3 and one["joint_pitch"] == [0.0, 0.0]
    old = {k: v for k, v in saved.items() if k not in ("joint_lead_um_per_m", "joint_pitch")}
    for header, lead, pitch in ((saved, [100.0, -80.0, 60.0], 2.0), (old, [0.0] * 3, 0.0)):
        st = start_station(header, None)
        try:
            assert st.machine.screws.lead_um_per_m.tolist() == lead
            assert st.machine.screws.pitch_um == pitch
            assert st.machine.screws.exact == (header is old)
        finally:
            st.close()


@pytest.mark.parametrize("argv, option", [
    (["--joint-lead", "fast"], "--joint-lead"),
    (["--joint-lead", "100,-80"], "--joint-lead"),
    (["--joint-lead", "nan"], "--joint-lead"),
    (["--joint-lead", "0.5,0,1e5"], "--joint-lead"),  # 10 % off: a unit slipped
    (["--joint-pitch", "2"], "--joint-pitch"),
    (["--joint-pitch", "2,0"], "--joint-pitch"),
    (["--joint-pitch=-1,5"], "--joint-pitch"),
    (["--joint-pitch", "nan,5"], "--joint-pitch"),
])
def test_bad_screws_are_one_line_naming_the_option_and_exit_2(
        argv: list[str], option: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(BadInput, match=f"^{option}: "):
        sim_params(SimOptions.from_args(parsed_simulate(*argv)))
    code = cli.main(["run", "--simulate", "--seed", "5", "--out", str(tmp_path / "runs"), *argv])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith(f"orthocal: error: {option}: "), err
    assert err.count("\n") == 1
    out = tmp_path / "sim.toml"
    assert cli.main(["sim", "--config-out", str(out), *argv]) == 2
    assert capsys.readouterr().err.startswith(f"orthocal: error: {option}: ")
    assert not out.exists()


@pytest.mark.parametrize("text, said", [
    ("[simulation]\njoint_lead = [100, -80]\n", "simulation.joint_lead"),
    ("[simulation]\njoint_pitch = [2.0, 0.0]\n", "simulation.joint_pitch: the period"),
    ("[simulation]\njoint_pitch = 2.0\n", "simulation.joint_pitch"),
])
def test_the_sim_files_keys_are_checked_in_its_words(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, said: str) -> None:
    path = tmp_path / "sim.toml"
    path.write_text(text)
    code = cli.main(["run", "--simulate", str(path), "--yes", "--out", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and said in err, err
    assert " --" not in err
