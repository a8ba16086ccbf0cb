"""The closed loop's maths (orthocal.loop), its state machine (station.engine.closed_loop) and
the virtual stands' misplacement that makes the loop necessary."""

from __future__ import annotations

import numpy as np
import pytest

import orthocal
from drivers.sim.machine import VirtualOrthoglide
from drivers.sim.specs import GaugeSpec
from drivers.sim.station import VirtualStation
from orthocal import Geometry
from orthocal.loop import (
    WRITABLE,
    after_correction,
    joined_with_previous,
    predicted_after_correction,
    significant_corrections,
)
from station.engine.closed_loop import (
    LoopState,
    LoopStep,
    extra_passes_allowed,
    mountings_expected,
    next_step,
    phase_of,
)

G = Geometry()
KEYS = [(s, i, j) for i in "xyz" for s in "+-" for j in "xyz" if j != i]


def measured(true: np.ndarray, mount_error: dict[str, float]) -> dict:
    """Exact deviations of a machine with parameters ``true`` whose stand on leg i
    stands at L/2 + mount_error[i] (no noise)."""
    r0 = orthocal.posture("0", None, G)
    out = {}
    for s, i, j in KEYS:
        m = G.mount_plane + mount_error[i]
        rs = orthocal.posture(s, i, G)
        out[(s, i, j)] = float(
            orthocal.leg_reading(rs, i, j, G, true[:3], true[3:], mount=m)
            - orthocal.leg_reading(r0, i, j, G, true[:3], true[3:], mount=m))
    return out


def test_misplaced_stands_bias_one_round_and_a_second_removes_it() -> None:
    # What the closed loop is for: offsets 2-3 mm, stands 8 mm off the legs' middles.
    true = np.array([2.4, -2.9, 2.1, 0.0, 0.0, 0.0])
    mounts = {"x": 8.0, "y": 8.0, "z": 8.0}
    left = true.copy()
    errors = []
    for _ in range(3):
        ident = orthocal.identify(measured(left, mounts), G, model="rho")
        left[:3] -= [ident.parameters[n] for n in WRITABLE]
        errors.append(float(np.max(np.abs(left[:3]))))
    assert errors[0] > 0.010  # one round leaves more than 10 µm
    assert errors[1] < 0.0005  # a second removes it to below 0.5 µm
    assert errors[2] < errors[1] / 10  # the bias shrinks with the offsets themselves


def test_after_correction_keeps_what_cannot_be_written() -> None:
    params = {"drho_x": 1.0, "drho_y": -0.5, "drho_z": 0.2, "dL_x": 0.3, "dL_y": 0.0,
              "dL_z": -0.1}
    after = after_correction(params)
    assert all(after[n] == 0.0 for n in WRITABLE)
    assert after["dL_x"] == 0.3 and after["dL_z"] == -0.1
    # Δρ-only: a perfect correction predicts zero deviations.
    assert np.allclose(predicted_after_correction(KEYS, G, {"drho_x": 1.0, "drho_y": 2.0,
                                                            "drho_z": -1.0}), 0.0)
    # With ΔL the prediction is the deviations of ΔL alone, not zero.
    pred = predicted_after_correction(KEYS, G, params)
    exact = orthocal.deviations(KEYS, G, np.array([0, 0, 0, 0.3, 0.0, -0.1]))
    assert np.allclose(pred, exact) and np.max(np.abs(pred)) > 0.01


def test_significance_needs_both_three_sigma_and_converge_mm() -> None:
    se = {"drho_x": 0.001, "drho_y": 0.001, "drho_z": 0.0001}
    # 2.5 σ: noise; 4 σ but below converge_mm: not worth a round; both: significant.
    params = {"drho_x": 0.0025, "drho_y": 0.004, "drho_z": 0.0025}
    assert significant_corrections(params, se, converge_mm=0.002, k=3.0) == ["drho_y", "drho_z"]
    assert significant_corrections(params, se, converge_mm=0.003, k=3.0) == ["drho_y"]
    assert significant_corrections(params, {"drho_x": None}, converge_mm=0.0, k=3.0) == []
    # After a write-back the previous correction's own noise counts too:
    # 4 σ of this measurement is under 3 σ of both (4 < 3·√2).
    prev = {"drho_x": 0.001, "drho_y": 0.001, "drho_z": 0.0001}
    assert significant_corrections(params, se, 0.002, previous_std_errors=prev, k=3.0) == ["drho_z"]
    # A previous se inflated by misfit (the stands' bias) does not hide a correction:
    # a round ten times noisier left an error this one resolves, so its term fades
    # (se²/se_prev: 4 σ > 3·√1.01) and Δρ_y is written where equal rounds hold it.
    big = {"drho_x": 0.01, "drho_y": 0.01, "drho_z": 0.01}
    assert significant_corrections(params, se, 0.002, previous_std_errors=big,
                                   k=3.0) == ["drho_y", "drho_z"]
    # continuous where the rounds' noises meet: just above se_prev = se, still √2
    near = {"drho_x": 0.00101, "drho_y": 0.00101, "drho_z": 0.0001}
    assert significant_corrections(params, se, 0.002, previous_std_errors=near,
                                   k=3.0) == ["drho_z"]
    assert significant_corrections({"drho_x": 0.0045}, se, 0.002,
                                   previous_std_errors=big, k=3.0) == ["drho_x"]


def test_significance_takes_k_from_students_t_on_the_noise_dof() -> None:
    se = {"drho_x": 0.001}
    # the noise known exactly (dof None): the normal's k for FALSE_ALARM, 3.59
    assert significant_corrections({"drho_x": 0.0036}, se, 0.002) == ["drho_x"]
    assert significant_corrections({"drho_x": 0.0035}, se, 0.002) == []
    assert significant_corrections({"drho_x": 0.0036}, se, 0.002, dof=1e6) == ["drho_x"]
    # two cycles give ~12 dof: k = 4.96, 4.5 σ is noise that would rewrite a fixed machine
    assert significant_corrections({"drho_x": 0.0045}, se, 0.002, dof=12) == []
    assert significant_corrections({"drho_x": 0.0050}, se, 0.002, dof=12) == ["drho_x"]
    # a fixed k overrides
    assert significant_corrections({"drho_x": 0.0035}, se, 0.002, k=3.0, dof=12) == ["drho_x"]
    # two rounds of 12 dof each: Welch–Satterthwaite gives 24, k = 4.18 on √2 σ
    both = {"drho_x": 0.0060}  # 4.24 of √2 σ
    assert significant_corrections(both, se, 0.002, previous_std_errors=se, dof=12,
                                   previous_dof=12) == ["drho_x"]
    assert significant_corrections(both, se, 0.002, previous_std_errors=se, dof=12,
                                   previous_dof=4) == []

@pytest.mark.parametrize("se_prev", [1.4, 0.45, 0.3])
def test_writing_the_rounds_joined_leaves_less_than_leaving_or_writing_one_look(
        se_prev: float) -> None:
    # Why a verification writes the rounds' joined Δρ̂ (station.engine.flow Flow.write):
    # a written round leaves e ~ N(0, se_prev²); the verification reads e + n, n ~ N(0,
    # 0.45²). Among the looks seen at 95 % on the rounds joined (the loop writes no
    # others in its dead zone), writing the joined value leaves less mean square error
    # than leaving the machine as it stands, and than writing the verification's own
    # look, which is worse than leaving it where the written round was the quieter.
    rng = np.random.default_rng(7)
    se = 0.45
    e = rng.normal(0.0, se_prev, 1_000_000)
    look = e + rng.normal(0.0, se, e.size)
    # joined_with_previous is linear in the look: its weight, from the function itself
    one, one_se = joined_with_previous({"drho_x": 1.0}, {"drho_x": se}, {"drho_x": 0.0},
                                       {"drho_x": se_prev}, {}, k=1e9)
    joined, joined_se = one["drho_x"] * look, one_se["drho_x"]
    seen = np.abs(joined) > 1.96 * joined_se
    assert seen.sum() > 1000
    write_joined = np.mean((e - joined)[seen] ** 2)
    stand = np.mean(e[seen] ** 2)
    write_look = np.mean((e - look)[seen] ** 2)
    assert write_joined < stand and write_joined < write_look
    # the posterior's variance, whatever was seen
    assert write_joined == pytest.approx(joined_se ** 2, rel=0.1)
    if se_prev == se:
        assert write_look == pytest.approx(stand, rel=0.05)  # one noise for another
    else:
        assert bool(write_look < stand) == (se_prev > se)


def walk(max_iterations: int, verify: bool, significant: list[bool],
         writes: list[str]) -> list[LoopStep]:
    """Drive next_step with scripted outcomes; returns every step taken."""
    state = LoopState(max_iterations, verify)
    steps: list[LoopStep] = []
    sig, wr = iter(significant), iter(writes)
    while True:
        step = next_step(state)
        steps.append(step)
        if step.kind == "finish":
            return steps
        if step.kind == "measure":
            state.measured(next(sig))
        else:
            state.wrote(next(wr))


def test_one_round_when_the_verification_finds_nothing() -> None:
    steps = walk(3, True, [True, False], ["written"])
    assert [s.kind for s in steps] == ["measure", "write", "measure", "finish"]
    assert [s.phase for s in steps if s.kind == "measure"] == ["m", "v"]
    assert steps[-1].reason == "converged"


def test_rounds_until_converged_or_max_iterations() -> None:
    steps = walk(3, True, [True, True, False], ["written", "written"])
    assert [s.round for s in steps if s.kind == "write"] == [1, 2]
    assert [s.phase for s in steps if s.kind == "measure"] == ["m", "v", "v2"]
    assert steps[-1].reason == "converged"
    steps = walk(2, True, [True, True, True], ["written", "written"])
    assert [s.round for s in steps if s.kind == "write"] == [1, 2]
    assert steps[-1].reason == "max_iterations"


@pytest.mark.parametrize("status,reason", [("refused", "refused"), ("declined", "declined"),
                                           ("failed-restored", "failed"),
                                           ("skipped", "skipped")])
def test_a_write_that_does_not_happen_stops_the_loop(status: str, reason: str) -> None:
    steps = walk(3, True, [True, True], ["written", status])
    assert steps[-1] == LoopStep("finish", reason=reason)
    assert sum(1 for s in steps if s.kind == "measure") == 2


def walk_verdicts(max_extra: int, verdicts: list[str]) -> list[LoopStep]:
    """next_step with a verdict per measurement: a round's first pass or, when the
    step says extra, a further pass of it; every write-back succeeds."""
    state = LoopState(3, True, max_extra_passes=max_extra)
    steps: list[LoopStep] = []
    it = iter(verdicts)
    while (step := next_step(state)).kind != "finish":
        steps.append(step)
        if step.kind == "write":
            state.wrote("written")
        elif step.extra:
            state.extended(next(it))
        else:
            state.measured(next(it))
    return [*steps, step]


def test_an_unproven_verification_is_measured_again_until_it_decides() -> None:
    # The first verification can tell neither a correction nor convergence: it is
    # measured again (v+1), pooled; then it shows the machine within converge_mm.
    steps = walk_verdicts(2, ["significant", "unproven", "converged"])
    assert [(s.kind, s.phase, s.extra) for s in steps[:-1]] == [
        ("measure", "m", 0), ("write", None, 0), ("measure", "v", 0), ("measure", "v+1", 1)]
    assert steps[-1].reason == "converged"
    # or the pooled passes find a correction after all: written, then verified afresh
    steps = walk_verdicts(2, ["significant", "unproven", "significant", "converged"])
    assert [s.phase for s in steps if s.kind == "measure"] == ["m", "v", "v+1", "v2"]
    assert [s.round for s in steps if s.kind == "write"] == [1, 2]
    assert steps[-1].reason == "converged"


def test_a_correction_seen_but_not_beyond_the_noise_is_never_written() -> None:
    # suspected: what is left is seen at 95 % yet not beyond both rounds' noise; the
    # further passes may make it significant (then written), else the loop says so
    steps = walk_verdicts(1, ["significant", "suspected", "significant", "converged"])
    assert [(s.kind, s.phase or s.round) for s in steps[:-1]] == [
        ("measure", "m"), ("write", 1), ("measure", "v"), ("measure", "v+1"),
        ("write", 2), ("measure", "v2")]
    steps = walk_verdicts(1, ["significant", "suspected", "suspected"])
    assert steps[-1].reason == "not-converged" and sum(s.kind == "write" for s in steps) == 1


def test_a_verification_that_cannot_show_convergence_ends_not_converged() -> None:
    steps = walk_verdicts(2, ["significant", "unproven", "unproven", "unproven"])
    assert [s.phase for s in steps if s.kind == "measure"] == ["m", "v", "v+1", "v+2"]
    assert steps[-1] == LoopStep("finish", reason="not-converged")
    assert walk_verdicts(0, ["significant", "unproven"])[-1].reason == "not-converged"
    # a later round's passes are its own: v2+1 after v2
    steps = walk_verdicts(1, ["significant", "significant", "unproven", "converged"])
    assert [s.phase for s in steps if s.kind == "measure"] == ["m", "v", "v2", "v2+1"]


def test_shown_within_is_the_95_percent_bound_of_what_is_left() -> None:
    from orthocal.loop import shown_within

    se = {"drho_x": 0.0005, "drho_y": None, "drho_z": 0.001}
    shown = shown_within({"drho_x": -0.001, "drho_y": 0.0, "drho_z": 0.0005}, se, dof=None)
    assert shown["drho_x"] == pytest.approx(0.001 + 1.959964 * 0.0005, rel=1e-6)
    assert shown["drho_y"] == float("inf")  # no standard error: nothing is shown
    # Student's t on few dof widens it; the aim of objective tool is where it counts from
    t12 = shown_within({"drho_z": 0.0005}, se, dof=12, target={"drho_z": 0.0015})
    assert t12["drho_z"] == pytest.approx(0.001 + 2.178813 * 0.001, rel=1e-6)


def test_no_verification_means_one_write() -> None:
    steps = walk(3, False, [True], ["written"])
    assert [s.kind for s in steps] == ["measure", "write", "finish"]
    assert steps[-1].reason == "not-verified"
    assert [phase_of(n) for n in range(4)] == ["m", "v", "v2", "v3"]


def test_machine_reading_follows_the_stand_plane() -> None:
    machine = VirtualOrthoglide(G, true_drho=(2.0, -1.0, 0.5))
    for mount in (None, G.mount_plane + 8.0):
        want = orthocal.leg_reading(machine.actual(), "x", "y", G, machine.true_drho,
                                    machine.true_dl, mount=mount)
        assert machine.leg_reading("x", "y", mount) == pytest.approx(float(want), abs=1e-12)


def test_every_mounting_draws_a_new_stand_error_within_the_bound() -> None:
    with VirtualStation(gauges=GaugeSpec(noise_mm=0.0, line_time=False, mount_error_mm=8.0),
                        seed=3) as st:
        for where in ("m:0", "v:0", "v2:0", "m:0"):
            st.place(where)
            st.mount("A", "x", "y")
        errors = [e for *_, e in st.mount_log]
        assert len(set(errors)) == 3 and all(abs(e) <= 8.0 for e in errors)
        assert errors[3] == errors[0]  # the same placement, replayed after a resume
    with VirtualStation(gauges=GaugeSpec(noise_mm=0.0, line_time=False,
                                         mount_errors={"A": -6.0}), seed=3) as st:
        st.mount("A", "x", "y")
        assert st.mount_log == [("A", "x", "y", -6.0)]


def test_with_tilts_the_verification_is_judged_against_the_tilts_left() -> None:
    # Tilts cannot be written: after writing Δρ a tilted machine still deviates,
    # exactly as the exact model with the same tilts and zero Δρ says.
    true = {"drho_x": 1.2, "drho_y": -0.8, "drho_z": 0.6, "tilt_yx": 0.4, "tilt_zx": -0.3,
            "tilt_zy": 0.2}
    full = orthocal.deviations(KEYS, G, np.array([true.get(n, 0.0)
                                                  for n in orthocal.PARAM_NAMES]))
    ident = orthocal.identify(dict(zip(KEYS, full, strict=True)), G, model="rho+tilt")
    pred = predicted_after_correction(KEYS, G, ident.parameters)
    left = orthocal.deviations(KEYS, G, np.array(
        [0.0 if n.startswith("drho") else true.get(n, 0.0) for n in orthocal.PARAM_NAMES]))
    assert np.max(np.abs(left)) > 0.005  # far from zero: judging against zero would fail
    assert np.allclose(pred, left, atol=1e-6)


def test_the_report_says_every_reason_the_loop_can_stop() -> None:
    # The engine names the reasons (the run JSON's loop.stopped); the report, which
    # reads the result and not the engine, says each in words.
    from station.engine.closed_loop import STOP_REASONS
    from station.report.rounds import STOP_TEXT

    assert set(STOP_TEXT) == set(STOP_REASONS)
    assert all(STOP_TEXT[r] for r in STOP_REASONS)


def test_a_first_measurement_writes_only_what_stands_out_of_its_noise() -> None:
    # a machine within tolerance: the first measurement shows it, nothing is written
    steps = walk_verdicts(2, ["converged"])
    assert [s.kind for s in steps] == ["measure", "finish"]
    assert steps[-1].reason == "converged"
    # undecided: measured again in the same mounting's phase (m+1), then decided
    steps = walk_verdicts(2, ["unproven", "converged"])
    assert [s.phase for s in steps if s.kind == "measure"] == ["m", "m+1"]
    assert not any(s.kind == "write" for s in steps)
    steps = walk_verdicts(1, ["suspected", "significant", "converged"])
    assert [(s.kind, s.phase or s.round) for s in steps[:-1]] == [
        ("measure", "m"), ("measure", "m+1"), ("write", 1), ("measure", "v")]
    # never decided: a recheck takes the passes of the verifications it did not need,
    # (1 + 1 extra) × (1 + 3 write-backs) = 8 in all, then ends not converged, nothing
    # written
    steps = walk_verdicts(1, ["unproven"] * 8)
    assert [s.phase for s in steps if s.kind == "measure"] == \
        ["m", *(f"m+{i}" for i in range(1, 8))]
    assert steps[-1].reason == "not-converged" and not any(s.kind == "write" for s in steps)
    # its operator mounts no more than the run's "most": 3 + 7 passes × 2 kept after the
    # first = 17 for 3 setups, max_extra_passes 1 and 3 write-backs
    assert mountings_expected(3, 3, 1)["most"] == 3 + 7 * 2
    # a verification keeps max_extra_passes: v, v+1, then not converged
    steps = walk_verdicts(1, ["significant", "unproven", "unproven"])
    assert [s.phase for s in steps if s.kind == "measure"] == ["m", "v", "v+1"]
    assert steps[-1].reason == "not-converged"


def test_a_first_measurement_without_verifications_keeps_max_extra_passes() -> None:
    # with verify off there are no verifications whose passes it could take
    assert extra_passes_allowed(0, 2, 3, verify=False) == 2
    assert extra_passes_allowed(0, 2, 3, verify=True) == 11
    assert extra_passes_allowed(1, 2, 3, verify=True) == 2
    assert extra_passes_allowed(0, 0, 1, verify=True) == 1


def test_a_verification_joins_the_round_before_it_moved_by_what_was_written() -> None:
    # Round 1 saw Δρ_x = 12 ± 1 µm and 12 µm was written off: it says the joint is
    # now at 0 ± 1; the verification sees 1.5 ± 1. Joined: 0.75 ± 0.71 µm.
    um = 1e-3
    values, ses = joined_with_previous(
        {"drho_x": 1.5 * um, "drho_y": 0.0}, {"drho_x": 1.0 * um, "drho_y": 2.0 * um},
        {"drho_x": 12.0 * um, "drho_y": 0.5 * um}, {"drho_x": 1.0 * um, "drho_y": 2.0 * um},
        {"drho_x": -12.0 * um}, k=3.6)
    assert values["drho_x"] == pytest.approx(0.75 * um, abs=1e-12)
    assert ses["drho_x"] == pytest.approx(um / np.sqrt(2.0), rel=1e-9)
    # y was not written: the earlier 0.5 µm is a measurement of the same joint
    assert values["drho_y"] == pytest.approx(0.25 * um, abs=1e-12)
    # a verification far from what was written (10 µm, 7 standard errors of the
    # difference): the write did not move the joint as said, nothing is joined
    values, ses = joined_with_previous(
        {"drho_x": 10.0 * um}, {"drho_x": 1.0 * um}, {"drho_x": 12.0 * um},
        {"drho_x": 1.0 * um}, {"drho_x": -12.0 * um}, k=3.6)
    assert values["drho_x"] == 10.0 * um and ses["drho_x"] == 1.0 * um
    # without a standard error on either side: this round's alone
    values, ses = joined_with_previous({"drho_x": 1.0 * um}, {"drho_x": 1.0 * um},
                                       {"drho_x": 0.0}, {"drho_x": None}, {}, k=3.6)
    assert values["drho_x"] == 1.0 * um and ses["drho_x"] == 1.0 * um
