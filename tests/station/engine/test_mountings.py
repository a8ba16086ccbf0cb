"""What a calibration costs the operator: mountings counted, expected, and saved.

A verification that cannot yet show its verdict measures more cycles on the gauges
already mounted before the loop mounts every setup again; the first measurement
does not (a new mounting is what averages the stands there). The run states how
many mountings it took and the operator's time at them; ``--plan`` and the run's
start say how many to expect."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from builders import FAST, simulated
from fakes import FakeRig, fake_config, run_on

from station import report
from station.analysis import verdict
from station.analysis.verdict import judge
from station.commands import run as cmd_run
from station.engine.closed_loop import mountings_expected
from station.record.journal_file import read_journal

NOISY = {**FAST, "model": "rho", "max_extra_passes": 1}  # up to 2 × 2 cycles a mounting


def test_expected_mountings_follow_the_loop() -> None:
    # three setups, three write-backs at most, two extra passes each: every pass after
    # the first starts on the gauges its pass before ended with (3 + 2 × 2 in the
    # first round, then 3 rounds × 3 passes × 2)
    assert mountings_expected(3, 3, 2) == {"fewest": 3, "usual": 5, "per_write_back": 2,
                                           "most": 3 + 2 * 2 + 3 * 3 * 2}
    assert mountings_expected(3, 1, 0) == {"fewest": 3, "usual": 5, "per_write_back": 2,
                                           "most": 5}
    assert mountings_expected(1, 3, 0, verify=False) == {
        "fewest": 1, "usual": 1, "per_write_back": 0, "most": 1}
    # a second gauge plane, read in the run's second pass alone (Plan.setups_of): the
    # three middles first, then all six with the last middle's gauges kept (five new),
    # then the middles again (two new): 3 + 5 + 2 for two write-backs
    plane = mountings_expected(3, 3, 0, second=6, later=3)
    assert plane == {"fewest": 3, "usual": 8, "per_write_back": 2, "most": 3 + 5 + 2 * 2}
    assert plane["usual"] + plane["per_write_back"] == 10
    # one further pass a round, two write-backs: 3 × 2 passes, the first two as above
    assert mountings_expected(3, 2, 1, second=6, later=3)["most"] == 3 + 5 + 4 * 2
    # nothing verified: the first measurement's passes alone, a recheck's second
    # pass reads both planes too
    assert mountings_expected(3, 2, 1, verify=False, second=6, later=3)["most"] == 3 + 5


def _run(tmp_path: Path, capsys, procedure: dict[str, Any]) -> dict[str, Any]:
    # How many cycles a mounting takes is the engine's decision: the run is the
    # engine's on the Protocol-level fakes (tests/helpers/fakes.py), 4 µm gauges, exact stands.
    rig = FakeRig(true_drho=(0.4, -0.3, 0.2), noise_mm=0.004, seed=5)
    code, result = run_on(rig, tmp_path / "runs", fake_config(**procedure))
    assert result["status"] == "ok", result.get("message")
    assert code == (3 if report.not_converged(result) else 0)
    return result


def _cycles_per_mounting(result: dict[str, Any]) -> dict[tuple[str, int], int]:
    records = read_journal(Path(result["run_dir"]) / "journal.jsonl")
    out: dict[tuple[str, int], int] = {}
    for r in records:
        if r["type"] == "cycle":
            out[(r["phase"], r["setup"])] = out.get((r["phase"], r["setup"]), 0) + 1
    return out


def test_a_noisy_verification_takes_more_cycles_where_its_gauges_are(tmp_path: Path,
                                                                    capsys) -> None:
    result = _run(tmp_path, capsys, NOISY)
    cycles = _cycles_per_mounting(result)
    assert all(n == 2 for (phase, _), n in cycles.items() if phase == "m")
    verification = [n for (phase, _), n in cycles.items() if phase.startswith("v")]
    assert verification and all(2 <= n <= 4 for n in verification)
    assert max(verification) > 2  # 4 µm gauges: two cycles cannot show 2 µm
    records = read_journal(Path(result["run_dir"]) / "journal.jsonl")
    mounts = [r for r in records if r["type"] == "setup"]
    assert result["timing"]["mountings"] == len(mounts)
    assert result["timing"]["operator_s"] == pytest.approx(
        sum(r["operator_s"] for r in mounts), abs=0.01)
    assert all(r["operator_s"] >= 0.0 for r in mounts)
    assert f"mountings     {len(mounts)}" in report.summary_text(result)


def test_at_most_cycles_turns_it_off(tmp_path: Path, capsys) -> None:
    result = _run(tmp_path, capsys, {**NOISY, "max_cycles_in_mounting": 2})
    assert set(_cycles_per_mounting(result).values()) == {2}


def test_the_plan_says_how_many_mountings_to_expect(tmp_path: Path, capsys) -> None:
    assert cmd_run.run(simulated(tmp_path / "runs", plan=True, json=False)) == 0
    text = capsys.readouterr().out
    # FAST: 3 setups, max_iterations 3 by default, no extra passes
    assert "mountings: expect 5 (one write-back, verified at once); 3 if the machine is " \
           "within tolerance, 2 more per further write-back (the last setup's gauges stay " \
           "on across each); up to 9" in text
    assert cmd_run.run(simulated(tmp_path / "runs", plan=True, json=True)) == 0
    assert json.loads(capsys.readouterr().out)["mountings"] == \
        {"fewest": 3, "usual": 5, "per_write_back": 2, "most": 9}


def _ident(drho_um: float, se_um: float, **others_um: float) -> SimpleNamespace:
    names = ("drho_x", "drho_y", "drho_z")
    values = {n: 0.0 for n in names} | {"drho_x": drho_um} | others_um
    return SimpleNamespace(parameters={n: v / 1000 for n, v in values.items()},
                           std_errors=dict.fromkeys(names, se_um / 1000), std_error_dof=None,
                           ambiguity_mm={})


def _judged(own: SimpleNamespace, previous: SimpleNamespace | None,
            limit: float = 0.0025, passes_left: bool = True) -> Any:
    """The verdict as the flow gives it: a verification judged on the rounds joined
    (the previous round's Δρ̂ moved by nothing here: its offsets aimed at zero)."""
    joined = None if previous is None else verdict.joined_round(
        own, verdict.joined_round(previous, None, None, None), None, None)
    return judge(own, previous, limit, None, passes_left=passes_left,
                 joined=joined)


def test_a_leftover_below_converge_mm_is_written_where_it_keeps_converged_out_of_reach(
) -> None:
    # 1.9 µm, 4.6 standard errors out, under converge_mm = 2 µm: a correction "too
    # small to matter", yet the machine cannot be shown within 2.5 µm with it there
    # (1.9 + 1.96 × 0.4 > 2.5), and it contradicts the quiet round written (0 ± 0.1)
    # beyond both noises, so the rounds are not joined: written, passes left or not.
    for left in (True, False):
        after_write = _judged(_ident(1.9, 0.4), _ident(0.0, 0.1), passes_left=left)
        assert after_write.verdict == "significant" and after_write.significant == ["drho_x"]
    # shown within the limit: converge_mm spares it
    assert _judged(_ident(1.5, 0.1), _ident(0.0, 0.1), 0.0035).verdict == "converged"
    # a noisier look (1.7 ± 0.5) at a machine a quiet round fixed (0 ± 0.1): within the
    # noise of both, joined with it the machine is shown within 2.5 µm; nothing written
    quiet = _judged(_ident(1.7, 0.5), _ident(0.0, 0.1))
    assert quiet.verdict == "converged" and quiet.significant == []
    # not seen at 95 % on the rounds joined (0.5 ± 1.06 µm), not shown within: measured
    # again, with passes left; with none left, nothing beyond the noise is written
    for left in (True, False):
        unseen = _judged(_ident(1.0, 1.5), _ident(0.0, 1.5), passes_left=left)
        assert unseen.significant == [] and unseen.verdict == "unproven"
    # a first measurement keeps the floor: a machine within tolerance is left alone
    assert judge(_ident(1.9, 0.4), None, 0.0025, None).significant == []


def test_an_undecided_verification_writes_rather_than_mounts_the_same_machine_again(
) -> None:
    # The first round (stands by eye, se 1.4 µm) left Δρ_x off; the verification sees
    # 1.9 ± 0.45 µm, joined with the first 1.72 ± 0.43: under converge_mm, not beyond
    # both rounds' noise at the loop's false-alarm k, and 1.72 + 1.96 × 0.43 > 2.5
    # keeps "converged" out of reach. A further pass would mount every setup again to
    # look at the same machine; a write and its verification cost the same mountings
    # and leave it ~0.4 µm off instead of ~1.7: written, with passes left. Δρ_y is seen
    # too (0.9 ± 0.43 joined) but shown within 2.5 µm: spared.
    seen = _judged(_ident(1.9, 0.45, drho_y=1.0), _ident(0.0, 1.4))
    assert seen.verdict == "significant" and seen.significant == ["drho_x"]


def test_converged_rests_on_the_rounds_joined() -> None:
    # 1.0 ± 0.8 µm alone cannot be shown within 2.5 µm (1.0 + 1.96 × 0.8); joined
    # with the round before (0.7 ± 0.5 µm) it can, and nothing is written either way.
    previous = _ident(0.0, 0.8)
    alone = judge(_ident(1.0, 0.8), previous, 0.0025, None, passes_left=True)
    assert alone.verdict == "unproven"
    joined = ({"drho_x": 0.0007, "drho_y": 0.0, "drho_z": 0.0},
              dict.fromkeys(("drho_x", "drho_y", "drho_z"), 0.0005))
    both = judge(_ident(1.0, 0.8), previous, 0.0025, None, passes_left=True,
                 joined=joined)
    assert both.verdict == "converged" and both.significant == []
    assert both.shown_mm["drho_x"] == pytest.approx(0.0007 + 1.96 * 0.0005, rel=1e-3)


def test_the_progress_bar_counts_what_really_happens() -> None:
    from builders import station_config

    from station.console.progress import Progress
    from station.plan.steps import Read, build_plan

    plan = build_plan(station_config())
    reads = [s for s in plan.steps("m") if isinstance(s, Read)]
    progress = Progress(plan, verify=True, enabled=False)
    assert progress.bar.total_steps == 2 * len(reads)  # the one-side approach's stops too

    def phase(code: str, extra_cycle: bool = False) -> None:
        for r in reads:
            progress("read", phase=code, setup=r.setup, cycle=r.cycle, sign=r.sign)
        if extra_cycle:  # one cycle more in the first mounting
            for r in (r for r in reads if r.setup == 0 and r.cycle == 1):
                progress("read", phase=code, setup=0, cycle=plan.cycles + 1, sign=r.sign)

    phase("m")
    phase("v", extra_cycle=True)
    per_cycle = sum(1 for r in reads if r.setup == 0 and r.cycle == 1)
    assert progress.bar.total_steps == progress.steps == 2 * len(reads) + per_cycle
    phase("v2")  # a second write-back's verification: counted as it starts
    assert progress.bar.total_steps == progress.steps == 3 * len(reads) + per_cycle


def test_piped_progress_never_counts_past_its_total(tmp_path, capsys) -> None:
    # 1 µm gauges and stands taken as exact: the verification's mountings take cycles
    # beyond the planned two and a second write-back adds a pass; each grows the total
    # first, saying by how much.
    import re

    from builders import FAST
    from fakes import FakeRig, fake_config, run_on

    rig = FakeRig(seed=1, noise_mm=0.001, mount_error_mm=0.0, true_drho=(1.0, -0.8, 0.6))
    run_on(rig, tmp_path / "runs", fake_config(**{
        **FAST, "model": "rho", "max_extra_passes": 2, "plunger_guard": False,
        "stand_tolerance_mm": 0}))
    lines = capsys.readouterr().err.splitlines()
    total, said, kinds = None, 0, set()
    for line in lines:
        if (grown := re.match(r"\+(\d+) readings: another (cycle|pass)", line)):
            said += int(grown[1])
            kinds.add(grown[2])
        elif (step := re.match(r"\[(\d+)/(\d+)\].* cycle (\d+)/(\d+) ", line)):
            done, count, cycle, cycles = map(int, step.groups())
            assert done <= count and cycle <= cycles, line
            if total is not None:
                assert count == total + said, line  # grown by exactly what was said
            total, said = count, 0
    assert kinds == {"cycle", "pass"}  # the run did both


def test_a_verification_held_by_the_carried_bows_is_form_limited_only_where_they_hold_it(
) -> None:
    # 1.0 ± 1.6 µm after a write-back, two passes left, of which 1.2 µm is the floor
    # the bows carried from the second plane leave (orthocal.carry.prior_floor): even at
    # Δρ̂ = 0 the passes could reach 1.96 × √(1.2² + (1.6² − 1.2²)/3) = 2.64 µm, not
    # 2.5, and without the floor 1.20: the bows hold it, no pass is taken
    own, previous = _ident(1.0, 1.6), _ident(0.0, 1.6)
    held = judge(own, previous, 0.0025, None, passes_left=True,
                 floor=dict.fromkeys(("drho_x", "drho_y", "drho_z"), 0.0012), passes=(1, 2))
    assert held.verdict == "form-limited"
    # a floor of 0.6 µm: 1.96 × √(0.36 + 2.2/3) = 2.05 µm is within reach: measured again
    light = judge(own, previous, 0.0025, None, passes_left=True,
                  floor=dict.fromkeys(("drho_x", "drho_y", "drho_z"), 0.0006), passes=(1, 2))
    assert light.verdict == "unproven"
    # no pass left, and the noise alone (1.96 × √(1.6² − 1.2²) = 2.07 µm) within it: still
    # the bows'; with a noisier round (2.5 µm: the noise alone is out too) it is not
    last = judge(own, previous, 0.0025, None, passes_left=False,
                 floor=dict.fromkeys(("drho_x", "drho_y", "drho_z"), 0.0012), passes=(3, 0))
    assert last.verdict == "form-limited"
    noisy = judge(_ident(1.0, 2.5), _ident(0.0, 2.5), 0.0025, None, passes_left=False,
                  floor=dict.fromkeys(("drho_x", "drho_y", "drho_z"), 0.0012), passes=(3, 0))
    assert noisy.verdict == "unproven"
