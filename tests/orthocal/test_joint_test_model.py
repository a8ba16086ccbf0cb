"""The station's own test of a joint (orthocal.joint_test; docs/model.md, "The station's
own joint test"): where the targets go, what the gauge on the carriage reads at each
(the closed form (J10) against the simulator's carriage through its screw and its
lost motion, drivers.sim.machine and drivers.sim.length_reference), the table the readings
give back (J11)–(J13), and the check values model.md prints."""

from __future__ import annotations

import math

import numpy as np
import pytest

import orthocal
from drivers.sim.fake import SteppedClock
from drivers.sim.length_reference import VirtualReference
from drivers.sim.machine import VirtualOrthoglide
from orthocal import JointTable, lead_um_per_m
from orthocal.joint_test import (
    gauge_readings,
    iso_targets,
    null_targets,
    plunger_sign,
    reference_lengths,
    station_table,
)

G = orthocal.Geometry()
L = G.leg_length
LEADS = (100.0, -80.0, 60.0)
BACKLASH = (0.006, 0.0, 0.004)
PITCH = (2.0, 20.0)
DRHO = (0.6, -0.4, 0.9)
# The default simulated station's test (model.md's check values): the travel the run
# needs within the soft limits [200.25, 380.25], eight targets of gauge blocks.
LO, HI = 200.25, 370.25


def faces_of(count: int = 8) -> list[float]:
    t = iso_targets(0.0, HI - LO, count)
    return [round(float(v), 3) for v in t[:-1]] + [HI - LO]


def truth(rho: np.ndarray, axis: int, side: str, pitch: tuple[float, float] = PITCH
          ) -> np.ndarray:
    """ε of the simulated screw (J2), homed at Π0, and its lost motion (∓B/2)."""
    a, p = pitch
    e = 1e-6 * LEADS[axis] * (rho - L) + 1e-3 * a * np.sin(2 * np.pi * (rho - L) / p)
    return e + (-0.5 if side == "forward" else 0.5) * BACKLASH[axis]


# --- the targets -----------------------------------------------------------------------


def test_the_targets_are_irregular_with_exact_ends() -> None:
    for count in (5, 8, 13):
        t = iso_targets(LO, HI, count)
        p = (HI - LO) / (count - 1)
        assert t[0] == LO and t[-1] == HI and t.size == count
        steps = np.diff(t)
        assert np.all(steps >= 0.5 * p - 1e-9) and np.all(steps <= 1.5 * p + 1e-9)
        # irregular: no two interior offsets from the even spacing alike
        offsets = t[1:-1] - (LO + p * np.arange(1, count - 1))
        assert len({round(v, 6) for v in offsets}) == count - 2
        assert np.all(np.abs(offsets) <= p / 4 + 1e-12)
    with pytest.raises(ValueError, match="at least two"):
        iso_targets(LO, HI, 1)
    assert list(null_targets(LO, [0.0, 20.0, 55.5], "-")) == [LO, LO + 20.0, LO + 55.5]
    assert list(null_targets(HI, [10.0, 30.0], "+")) == [HI, HI - 20.0]
    assert plunger_sign("-") == -1 and plunger_sign("+") == 1
    with pytest.raises(ValueError, match="plunger"):
        plunger_sign("x")


# --- (J10): the closed form against the simulator ------------------------------------------


def simulator_readings(axis: int, plunger: str, targets: np.ndarray, faces: list[float]
                       ) -> dict[tuple[int, str], float]:
    """What the simulated gauge reads at each target from each side, relative to its
    reading at the datum approached from above: a machine with the leads, the pitch,
    the lost motion and offsets, the gauge on carriage ``axis`` reading the reference
    through the carriage's true position."""
    clock = SteppedClock()
    machine = VirtualOrthoglide(G, DRHO, speed_mm_s=1000.0, accel_mm_s2=20000.0, clock=clock,
                                backlash=BACKLASH, joint_lead=LEADS, joint_pitch=PITCH)

    def go(rho: float) -> None:
        target = [L, L, L]
        target[axis] = rho
        clock.t += machine.move_to(target) + 1e-6

    reference = VirtualReference(machine.joint_values)
    go(targets[0] + 1.0)
    go(targets[0])
    source = reference.mount("xyz"[axis], plunger_sign(plunger))
    o = 0.05
    out = {}
    for k, rho in enumerate(targets):
        reference.set_face("xyz"[axis], faces[k])
        for side, start in (("reverse", rho + o), ("forward", rho - o)):
            go(start)
            go(rho)
            out[(k, side)] = source()
    return {key: v - out[(0, "reverse")] for key, v in out.items()}


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("plunger", ["-", "+"])
def test_the_closed_form_reads_what_the_simulated_gauge_reads(axis: int, plunger: str) -> None:
    faces = faces_of()
    datum = LO if plunger == "-" else HI
    targets = null_targets(datum, faces, plunger)
    rf, rr = gauge_readings(targets, faces, plunger, truth(targets, axis, "forward"),
                            truth(targets, axis, "reverse"))
    got = simulator_readings(axis, plunger, targets, faces)
    for k in range(len(targets)):
        assert got[(k, "forward")] == pytest.approx(rf[k] - rr[0], abs=1e-10)
        assert got[(k, "reverse")] == pytest.approx(rr[k] - rr[0], abs=1e-10)
    # at the nulls the gauge reads the joint's error alone (J10): s·(ε_k − ε̄_0)
    s = plunger_sign(plunger)
    mid = 0.5 * (truth(targets[:1], axis, "forward") + truth(targets[:1], axis, "reverse"))
    assert rf == pytest.approx(s * (truth(targets, axis, "forward") - mid), abs=1e-12)


# --- (J11)-(J13): the table the readings give ----------------------------------------------


def readings_of(targets: np.ndarray, faces, plunger: str, axis: int, repeats: int = 3,
                drift_mm: float = 0.0, zero_mm: float = 1.234):
    """The approaches' mean readings a test takes: (J10) plus the gauge's zero and a
    linear drift in the targets' order, the first target from above only."""
    rf, rr = gauge_readings(targets, faces, plunger, truth(targets, axis, "forward"),
                            truth(targets, axis, "reverse"))
    n = len(targets)
    drift = drift_mm * np.arange(n) / n
    fwd = np.repeat((rf + zero_mm + drift)[:, None], repeats, axis=1)
    rev = np.repeat((rr + zero_mm + drift)[:, None], repeats, axis=1)
    fwd[0, :] = np.nan  # the datum on a soft limit: from above only
    closing_r = np.full(repeats, rr[0] + zero_mm + drift_mm)
    return fwd, rev, np.full(repeats, np.nan), closing_r


@pytest.mark.parametrize("plunger", ["-", "+"])
def test_the_table_is_the_joints_error_referred_to_the_datum(plunger: str) -> None:
    faces = faces_of()
    datum = LO if plunger == "-" else HI
    targets = null_targets(datum, faces, plunger)
    for axis in range(3):
        fwd, rev, cf, cr = readings_of(targets, faces, plunger, axis, drift_mm=0.004)
        found = station_table(targets, faces, plunger, fwd, rev, cf, cr, reference_u95_mm=0.0005,
                              mpe_mm=0.003, alpha_per_k=11.5e-6, temperature_change_k=0.5)
        true = JointTable(np.sort(targets), truth(np.sort(targets), axis, "forward"),
                          truth(np.sort(targets), axis, "reverse")).referred_to_pi0(L)
        got = found.table.referred_to_pi0(L)
        assert np.all(np.diff(found.table.targets_mm) > 0)
        assert got.forward_mm == pytest.approx(true.forward_mm, abs=1e-12)
        assert got.reverse_mm == pytest.approx(true.reverse_mm, abs=1e-12)
        # the datum's drift is taken out; its reversal is −B at every target
        assert found.drift_mm == pytest.approx(0.004, abs=1e-12)
        assert found.table.reversal_mm == pytest.approx([-BACKLASH[axis]] * 8, abs=1e-12)
        datum_side = "forward"
        assert found.inferred == ((pytest.approx(datum), datum_side),)
        # the lead of a pure-lead table is the screw's, the pitch's aliasing aside
        pure = station_table(targets, faces, plunger, *readings_pitchless(targets, faces,
                                                                          plunger, axis),
                             reference_u95_mm=0.0005, mpe_mm=0.003, alpha_per_k=11.5e-6,
                             temperature_change_k=0.5)
        assert lead_um_per_m(pure.table).value_um_per_m == pytest.approx(LEADS[axis], abs=1e-6)


def readings_pitchless(targets, faces, plunger, axis):
    rf, rr = gauge_readings(targets, faces, plunger,
                            truth(targets, axis, "forward", (0.0, 1.0)),
                            truth(targets, axis, "reverse", (0.0, 1.0)))
    return (np.c_[rf, rf], np.c_[rr, rr], [rf[0], rf[0]], [rr[0], rr[0]])


def test_the_uncertainty_combines_reference_gauge_temperature_and_noise() -> None:
    faces = faces_of()
    targets = null_targets(LO, faces, "-")
    fwd, rev, cf, cr = readings_of(targets, faces, "-", 0)
    rng = np.random.default_rng(5)
    noisy = (fwd + rng.normal(0, 0.0005, fwd.shape), rev + rng.normal(0, 0.0005, rev.shape))
    found = station_table(targets, faces, "-", *noisy, cf, cr + rng.normal(0, 0.0005, 3),
                          reference_u95_mm=0.0008, mpe_mm=0.003, alpha_per_k=11.5e-6,
                          temperature_change_k=0.5)
    parts, u95 = found.parts, found.table.u95_mm
    assert u95 is not None
    assert parts["reference"] == pytest.approx([0.0] + [0.0004] * 7)  # U/2, none at the datum
    f = np.asarray(faces)
    assert parts["temperature"] == pytest.approx(11.5e-6 * 0.5 * f / math.sqrt(3))
    # the gauge's MPE over the reading's span from the datum, in proportion below 0.2 mm
    assert np.all(parts["gauge"] <= 0.003 / math.sqrt(3) * 0.03 / 0.2)
    assert parts["gauge"][-1] > parts["gauge"][1] > 0.0
    # the noise: the pooled scatter of 3 approaches a side, 8 targets and the datum again
    assert found.noise_dof == 7 * 2 * 2 + 2 + 2 and 0.0003 < found.noise_mm < 0.0008
    assert np.all(parts["noise"] > found.noise_mm / math.sqrt(6) - 1e-12)
    assert u95 == pytest.approx(2 * np.sqrt(sum(p**2 for p in parts.values())))
    # the points' uncertainty makes the lead's interval (J3)
    lead = lead_um_per_m(found.table)
    assert lead.points_um_per_m > 0 and lead.interval_95_um_per_m[0] < lead.value_um_per_m


def test_a_reference_warmer_than_20_c_is_longer() -> None:
    f = reference_lengths([0.0, 100.0], 11.5e-6, 25.0)
    assert f == pytest.approx([0.0, 100.00575])
    assert list(reference_lengths([0.0, 100.0], 11.5e-6)) == [0.0, 100.0]


def test_a_table_refuses_a_target_read_from_neither_side() -> None:
    targets = null_targets(LO, [0.0, 50.0, 100.0], "-")
    kw = {"reference_u95_mm": 0.0, "mpe_mm": 0.003, "alpha_per_k": 0.0,
          "temperature_change_k": 0.0}
    rows = np.array([[0.0, 0.0], [np.nan, np.nan], [0.0, 0.0]])
    with pytest.raises(ValueError, match="approached from neither side"):
        station_table(targets, [0.0, 50.0, 100.0], "-", rows, rows, [0.0, 0.0], [0.0, 0.0], **kw)
    # the datum read at the start and at the end from no common side: no drift line
    fwd = np.zeros((3, 2))
    rev = np.array([[np.nan, np.nan], [0.0, 0.0], [0.0, 0.0]])
    with pytest.raises(ValueError, match="datum"):
        station_table(targets, [0.0, 50.0, 100.0], "-", fwd, rev, [np.nan, np.nan], [0.0, 0.0],
                      **kw)


# --- model.md's check values ---------------------------------------------------------------

CHECK_TARGETS = [200.25, 225.969, 245.617, 277.407, 297.055, 316.702, 348.492, 370.25]
CHECK = {  # joint x: lead +100 µm/m, B = 6 µm; without and with a 2 µm pitch of 20 mm, µm
    (0.0, 1.0): ([+3.000, +0.428, -1.537, -4.716, -6.680, -8.645, -11.824, -14.000],
                 [-3.000, -5.572, -7.537, -10.716, -12.681, -14.645, -17.824, -20.000]),
    (2.0, 20.0): ([+3.000, +2.377, +0.450, -6.274, -8.367, -10.441, -10.775, -14.000],
                  [-3.000, -3.623, -5.550, -12.274, -14.367, -16.441, -16.775, -20.000])}


def test_model_md_check_values() -> None:
    faces = faces_of()
    assert faces == pytest.approx([0.0, 25.719, 45.367, 77.157, 96.805, 116.452, 148.242, 170.0])
    targets = null_targets(LO, faces, "-")
    assert targets == pytest.approx(CHECK_TARGETS, abs=1e-9)
    for pitch, (fwd, rev) in CHECK.items():
        rf, rr = gauge_readings(targets, faces, "-", truth(targets, 0, "forward", pitch),
                                truth(targets, 0, "reverse", pitch))
        assert 1e3 * rf == pytest.approx(fwd, abs=6e-4)
        assert 1e3 * rr == pytest.approx(rev, abs=6e-4)
    # the pitch, sampled at eight targets, moves the lead found by +7.77 µm/m and leaves
    # 1.41 µm RMS about the line
    t = np.asarray(targets)
    table = JointTable(t, truth(t, 0, "forward"), truth(t, 0, "reverse")).referred_to_pi0(L)
    lead = lead_um_per_m(table)
    assert lead.value_um_per_m == pytest.approx(107.770, abs=1e-3)
    assert lead.residual_rms_um == pytest.approx(1.408, abs=1e-3)
