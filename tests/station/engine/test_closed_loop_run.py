"""The closed loop: misplaced stands bias the first round and the loop removes it, and
rollback restores the offsets from before the first round, end to end over the
simulators (real Modbus server, pty gauges); a machine that one round fixes gets
exactly one write-back, and the loop says when and why it stopped without
converging, in whole runs of the engine on the Protocol-level fakes (tests/helpers/fakes.py,
the same virtual machine without the wire)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from builders import FAST, resumed, simulated
from fakes import FakeRig, fake_config, run_on
from result_builders import make_result
from truth import assert_truth, drho

from station import report
from station.commands import run as cmd_run
from station.record.journal_file import read_journal

PROCEDURE = {**FAST, "model": "rho"}


def run(tmp_path: Path, capsys, **extra: Any) -> dict[str, Any]:
    code = cmd_run.run(simulated(tmp_path / "runs", **{
        "seed": 5, "noise": 0.001, "procedure": PROCEDURE, "mount_error": 0.0, **extra}))
    result = json.loads(capsys.readouterr().out)
    # completed: 0, or 3 where the loop did not converge (the run says why)
    assert result["status"] == "ok", result.get("message")
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    return result


def engine_run(tmp_path: Path, *, seed: int = 5, noise: float = 0.001,
               mount_error: float = 0.0, procedure: dict[str, Any] = PROCEDURE,
               **machine: Any) -> dict[str, Any]:
    """The loop's decisions are the engine's: a whole run of it on the Protocol-level
    fakes (tests/helpers/fakes.py), in front of the same virtual machine, with ``run``'s
    defaults and checks."""
    rig = FakeRig(seed=seed, noise_mm=noise, mount_error_mm=mount_error, **machine)
    code, result = run_on(rig, tmp_path / "runs", fake_config(**procedure))
    assert result["status"] == "ok", result.get("message")
    assert code == (3 if report.not_converged(result) else 0), result.get("message")
    return result


def writes(result: dict[str, Any]) -> int:
    return sum(1 for it in result["iterations"] if it["offsets_written"] is not None)


def test_a_first_round_that_leaves_more_than_converge_mm_takes_a_second(tmp_path: Path,
                                                                        capsys) -> None:
    true = (2.5, -2.9, 2.2)
    # the verification measured again where it cannot yet show ±converge_mm: a bias
    # of several µm left by the first round is then written, whatever the noise drew
    result = run(tmp_path, capsys, true_drho=true, mount_error=8.0,
                 procedure={**PROCEDURE, "max_extra_passes": 2}, figures=True)
    # Two cycles of 1 µm gauges: what the second round leaves (its own error, the
    # drive's rounding) is shown within ±converge_mm in most runs, not all; the run
    # says which, and its statement holds either way.
    assert result["status"] == "ok" and result["loop"]["stopped"] in (
        "converged", "not-converged")
    assert result["simulation"]["mount_error_mm"] == 8.0
    its = result["iterations"]
    assert [it["phase"] for it in its][:2] == ["m", "v"] and writes(result) >= 2
    assert its[-1]["offsets_written"] is None and its[-1]["significant"] == []
    first_error = max(abs(its[0]["identified"][f"drho_{a}"] - t)
                      for a, t in zip("xyz", true, strict=True))
    # The stands are modelled, so the first round is not biased by them but uncertain
    # (one cycle of 1 µm gauges with the stands' terms: ~6 µm standard error): it leaves
    # more than converge_mm, which the second round removes.
    assert first_error > result["loop"]["converge_mm"]
    # the total written plus what the last round found left is the truth within the
    # last round's uncertainty; what is left is no more than that round resolves
    assert_truth(result, drho(true))
    joined = its[-1]["joined"]["drho_mm"]  # the rounds joined: the statement's as left
    assert result["remaining"]["estimate"] == pytest.approx({n: joined[n] for n in drho(true)},
                                                            abs=1e-12)
    # what the verification wrote is its look joined with the rounds before
    # (iterations[1].joined), the offsets before it minus the joined Δρ̂ (1 µm counts)
    before, after = its[0]["offsets_written"], its[1]["offsets_written"]
    for a in "xyz":
        assert after[a] == pytest.approx(
            before[a] - its[1]["joined"]["drho_mm"][f"drho_{a}"], abs=5e-4 + 1e-6)
    for a in "xyz":
        name = f"drho_{a}"
        assert result["offsets_written"][a] == pytest.approx(
            result["offsets_before"][a] - result["identified"][name], abs=0.0011)
    # Each round leaves less than the first; once at the gauges' noise (1 µm), two
    # rounds' RMS draw in either order, so the last is within that noise of the least
    # before it (a strict order failed where both verifications were at the noise).
    rms = [it["deviations_rms_mm"] for it in its]
    assert max(rms[1:]) < rms[0]
    assert rms[-1] <= min(rms[1:-1], default=rms[1]) + 0.001
    run_dir = Path(result["run_dir"])
    records = read_journal(run_dir / "journal.jsonl")
    rounds = [r.get("round") for r in records
              if r["type"] == "writeback" and r["stage"] == "done"]
    assert rounds == list(range(1, writes(result) + 1))
    # one record per pass of each verification (a pass measured again adds one)
    rounds_seen = [r["round"] for r in records if r["type"] == "verification"]
    assert sorted(set(rounds_seen)) == list(range(1, len(its))) and rounds_seen == \
        sorted(rounds_seen)
    text = report.summary_text(result)
    assert "closed loop" in text and "converged" in text
    assert ("NOT" in text) is (not result["converged"])
    html = (run_dir / "report.html").read_text()
    assert "<h2>Closed loop</h2>" in html and html.count("<svg") >= 3
    # Rollback restores the offsets from before the first round, not the last.
    code = cmd_run.rollback(resumed(run_dir, yes=True))
    assert code == 0
    restored = json.loads(capsys.readouterr().out)["restored"]
    assert restored == pytest.approx(result["offsets_before"], abs=1e-9)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_machine_one_round_fixes_gets_exactly_one_write_back(tmp_path: Path, capsys,
                                                               seed: int) -> None:
    # Gauges of 0.5 µm noise: what the first round's own noise leaves (~0.5 µm) is
    # 4σ under converge_mm, so only a bias could ask for a second round. At 1 µm the
    # loop's false-alarm rate rewrites one run in a thousand by design.
    # The stands exact and the station told so (stand_tolerance_mm 0: at L/2); modelled
    # within ±5 mm, their unknown positions widen the first round's SE by micrometres.
    # Where the verification cannot yet show every axis within ±converge_mm it is
    # measured again (a further pass, pooled): still one write-back. Without the
    # plunger guard, whose polls take gauge draws as often as the timing allows, each
    # seed reads the same every run.
    result = engine_run(tmp_path, seed=seed, true_drho=(0.3, -0.2, 0.4), mount_error=0.0,
                 noise=0.0005, procedure={**PROCEDURE, "stand_tolerance_mm": 0,
                                          "max_extra_passes": 2, "plunger_guard": False})
    assert writes(result) == 1 and len(result["iterations"]) == 2
    assert result["converged"] is True
    limit = result["loop"]["converged_within_mm"]
    assert limit == pytest.approx(0.002 + 0.0005, abs=1e-12)  # half the drive's µm count
    assert all(b <= limit for b in result["iterations"][-1]["shown_within_95_mm"].values())


def test_a_verification_too_noisy_to_show_convergence_is_measured_again(
        tmp_path: Path, capsys) -> None:
    # 4 µm gauges, two cycles of three readings: one verification shows the offsets no
    # better than ±5 µm at 95 %, above converge_mm (2 µm), and finds nothing beyond its
    # noise. "Converged" would promise what the data do not show: the verification is
    # measured again (every setup remounted, the passes pooled), and the run says
    # where it ends. (More cycles in the mounting come first by default,
    # test_mountings.py; off here, to see the passes.)
    true = (0.4, -0.3, 0.2)
    result = engine_run(tmp_path, true_drho=true, noise=0.004, mount_error=0.0,
                 procedure={**PROCEDURE, "max_extra_passes": 1,
                            "max_cycles_in_mounting": 2, "plunger_guard": False})
    ver = result["iterations"][1]
    assert ver["passes"] == ["v", "v+1"] and result["loop"]["extra_passes"] >= 1
    records = read_journal(Path(result["run_dir"]) / "journal.jsonl")
    again = {(r["setup"], r["cycle"]) for r in records if r["type"] == "cycle"
             and r["phase"] == "v+1"}
    assert again == {(s, c) for s in range(3) for c in (1, 2)}
    assert [r.get("passes") for r in records if r["type"] == "verification"][:2] == \
        [None, ["v", "v+1"]]
    # the pooled pass has the cycles of both
    assert all(st["n"] == 4 for st in result["verification"]["deviations"].values())
    # The engine on the fakes with the plunger guard off reads the same draws every run:
    # after the second write-back the verification, measured twice, shows the offsets
    # within ±3.6 to ±4.8 µm, not within converge_mm and half the drive's count (2.5
    # µm), and the run says so with its numbers.
    last = result["iterations"][-1]
    bounds = last["shown_within_95_mm"]
    assert result["converged"] is False and result["loop"]["stopped"] == "not-converged"
    worst = max(bounds.values())
    assert worst > result["loop"]["converged_within_mm"] >= 0.002
    assert f"by up to {1000 * worst:.1f} µm" in result["message"]
    # the headline says how far (limit converge_mm + half a count), the advice what to do
    assert "(limit 2.5 µm)" in result["message"]
    remedy = next(a for a in result["advice"] if a["id"] == "converge")
    assert "more cycles or readings" in remedy["text"] or "stands" in remedy["text"]
    assert "NOT CONVERGED" in report.summary_text(result)
    assert_truth(result, drho(true))


def test_max_iterations_stops_the_loop_and_says_why(tmp_path: Path, capsys) -> None:
    # the stands' bias of the first round stands out once the verification is
    # measured enough (further passes pooled)
    result = engine_run(tmp_path, true_drho=(2.5, -2.9, 2.2), mount_error=8.0,
                 procedure={**PROCEDURE, "max_iterations": 1, "max_extra_passes": 2})
    assert writes(result) == 1 and result["converged"] is False
    assert result["loop"]["stopped"] == "max_iterations"
    assert "did not converge" in result["message"]
    assert "NOT CONVERGED" in report.summary_text(result)
    # what the last verification found is still on the machine, and the run says so
    last = result["iterations"][-1]
    assert result["remaining"]["round"] == 2 and last["significant"]
    # what is left: the rounds joined (the statement's as left), one estimate
    assert result["remaining"]["estimate"] == pytest.approx({
        n: (last["joined"] or {"drho_mm": last["identified"]})["drho_mm"][n]
        for n in ("drho_x", "drho_y", "drho_z")}, abs=1e-12)
    # the first screen's "as left": what the last verification found, at 95 %
    joints = [ln for ln in report.summary_text(result).splitlines()
              if ln.startswith("  joint ")]
    assert len(joints) == 3 and all(" → as left " in ln and "not verified" not in ln
                                    and "unchanged" not in ln for ln in joints), joints


def test_without_verification_nothing_is_claimed_about_what_is_left(tmp_path: Path,
                                                                   capsys) -> None:
    result = engine_run(tmp_path, true_drho=(0.3, -0.2, 0.4),
                 procedure={**PROCEDURE, "verify": False})
    assert writes(result) == 1 and len(result["iterations"]) == 1
    assert result["remaining"] is None
    joints = [ln for ln in report.summary_text(result).splitlines()
              if ln.startswith("  joint ")]
    assert len(joints) == 3 and all("as left not verified" in ln for ln in joints), joints


def test_report_says_why_the_loop_did_not_go_on() -> None:
    it = {"phase": "m", "model": "rho", "identified": {"drho_x": 0.5},
          "std_errors": {"drho_x": 0.001}, "std_errors_dof": None,
          "deviations_rms_mm": 0.2, "residual_rms_mm": 0.001, "noise_floor_mm": 0.001,
          "fit_ok": True, "significant": ["drho_x"], "shown_within_95_mm": None,
          "verdict": None, "offsets_written": {"x": -0.5}, "writeback": "written"}
    second = {**it, "phase": "v", "identified": {"drho_x": 0.02}, "offsets_written": None,
              "writeback": "declined"}

    def loop(stopped: str, detail: str | None) -> dict[str, Any]:
        return {"stopped": stopped, "detail": detail, "write_backs": 1, "max_iterations": 3,
                "converge_mm": 0.002, "converged_within_mm": None, "extra_passes": 0,
                "max_extra_passes": 0}

    # a run's record (result_builders) with these rounds
    declined = {**make_result(), "iterations": [it, second], "converged": False,
                "loop": loop("declined", "declined by the operator")}
    text = report.summary_text(declined)
    assert "NOT CONVERGED" in text and "the operator declined a correction" in text
    html = report.render_html(declined)
    assert "did not converge" in html and "declined by the operator" in html
    off = {**make_result(), "iterations": [it], "converged": False,
           "loop": loop("not-verified", None)}
    assert "closed loop   off: verification is off" in report.summary_text(off)
    assert "NOT CONVERGED" not in report.summary_text(off)


def test_a_tilted_machine_is_verified_against_the_tilts_it_keeps(tmp_path: Path,
                                                                  capsys) -> None:
    # Gauges of 0.2 µm noise, stands exact and the station told so: with the tilts in
    # the model Δρ is known 1.6 times less well, and one round must leave it within
    # what the verification can show inside ±converge_mm (stands modelled within ±5
    # mm couple with the tilts and leave Δρ a floor of about 1 µm no pass lowers).
    result = engine_run(tmp_path, true_drho=(1.5, -1.0, 0.8), true_tilt=(0.4, -0.3, 0.2),
                 noise=0.0002, procedure={**PROCEDURE, "model": "rho+tilt",
                                          "max_extra_passes": 2, "stand_tolerance_mm": 0})
    ver = result["verification"]
    # Tilts cannot be written: the verification still deviates by ~10 µm RMS, as the
    # model predicts, and only noise is left once the prediction is taken off.
    assert ver["deviations_rms_mm"] > 0.005
    assert ver["deviations_rms_mm"] == pytest.approx(ver["expected_rms_mm"], rel=0.2)
    assert ver["vs_expected_rms_mm"] < 0.002
    assert result["converged"] is True and writes(result) == 1
    assert "judged against the model after correction" in report.summary_text(result)


def test_a_calibrated_machine_is_left_alone(tmp_path: Path, capsys) -> None:
    # its offsets exactly right: a recheck writes nothing and says so
    result = engine_run(tmp_path, true_drho=(0.0, 0.0, 0.0),
                 procedure={**PROCEDURE, "cycles": 3, "readings": 5, "max_extra_passes": 2})
    assert result["loop"]["stopped"] == "converged" and result["converged"] is True
    assert writes(result) == 0 and result["loop"]["write_backs"] == 0
    assert result["message"].startswith("within tolerance, nothing written")
    records = read_journal(Path(result["run_dir"]) / "journal.jsonl")
    assert not any(r["type"] == "writeback" for r in records)
    assert result["iterations"][0]["verdict"] == "converged"
