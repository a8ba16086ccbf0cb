"""Advice only where a value stands out of its noise and makes physical sense: the
joints' lost motion is advised for compensation only beyond the decision table's k_act
(one false alarm in a thousand machines over three joints, as every "act"), never for a
negative value (a reversal is a play), in the statement's decision, its advice, the
accuracy section and the first screen's "to do"."""

from __future__ import annotations

from pathlib import Path

import pytest
from builders import FAST
from fakes import FakeRig, fake_config, run_on

from orthocal.lost_motion import Reversal, standing_out
from station import report
from station.analysis.reversal import advice
from station.record.result_accuracy import DriveCount
from station.record.result_statement import Quantity
from station.statement.advice import advice as statement_advice
from station.statement.decisions import GAIN, NO_GAIN

NOISE_ONLY = Reversal(value={"x": 0.0004, "y": -0.0001, "z": -0.0002},
                      std_errors={"x": 0.00035, "y": 0.00035, "z": 0.00035}, dof=40.0,
                      n={"x": 9, "y": 9, "z": 9})


def test_noise_and_negative_reversals_are_not_advised() -> None:
    # the values the report once advised: each ±0.7 µm at 95 %, two of them negative
    said = advice(NOISE_ONLY)
    assert "compensate it in" not in said and "backlash" not in said
    assert said.startswith("nothing to compensate")
    assert standing_out(NOISE_ONLY.value, NOISE_ONLY.std_errors, NOISE_ONLY.dof) == {}


def test_a_negative_reversal_beyond_its_noise_is_no_play() -> None:
    rev = Reversal(value={"x": -0.005, "y": 0.004, "z": None},
                   std_errors={"x": 0.0002, "y": 0.0002, "z": None}, dof=40.0,
                   n={"x": 9, "y": 9, "z": 0})
    said = advice(rev)
    assert "joint y 4.0 µm" in said and "joint x −" not in said and "joint x -" not in said
    assert standing_out(rev.value, rev.std_errors, rev.dof) == {"y": 0.004}


@pytest.mark.parametrize(("value_um", "se_um", "advised"), [
    (1.0, 0.25, True),    # 1.0 − 3.92 × 0.25 = +0.02 µm: beyond k_act (40 dof)
    (1.0, 0.26, False),   # 1.0 − 3.92 × 0.26 = −0.02 µm: not beyond it
])
def test_the_gate_is_k_act_both_sides(value_um: float, se_um: float,
                                      advised: bool) -> None:
    rev = Reversal(value={"x": value_um / 1000}, std_errors={"x": se_um / 1000},
                   dof=40.0, n={"x": 9})
    assert ("joint x 1.0 µm" in advice(rev)) is advised
    assert bool(standing_out(rev.value, rev.std_errors, rev.dof)) is advised


def _run(tmp_path: Path, backlash: tuple[float, float, float]) -> dict:
    rig = FakeRig(true_drho=(0.4, -0.3, 0.2), noise_mm=0.001, backlash=backlash, seed=3)
    code, result = run_on(rig, tmp_path / "runs",
                          fake_config(**{**FAST, "cycles": 3, "max_extra_passes": 1}))
    assert code in (0, 3), result.get("message")
    return result


def test_joints_without_play_get_no_backlash_advice(tmp_path: Path) -> None:
    result = _run(tmp_path, (0.0, 0.0, 0.0))
    tool = result["accuracy"]["reversal"]
    assert tool["advice"].startswith("nothing to compensate")
    assert not [a for a in result["advice"] if a["id"] in ("backlash", "repair")]
    text = report.summary_text(result)
    todo = [ln for ln in text.splitlines() if "backlash" in ln]
    assert todo == [], todo


def test_joints_with_play_get_it(tmp_path: Path) -> None:
    result = _run(tmp_path, (0.006, 0.006, 0.006))
    plays = [a for a in result["advice"] if a["id"] == "backlash"]
    assert len(plays) == 1
    assert plays[0]["rests_on"] == ["reversal_x", "reversal_y", "reversal_z"]
    decided = {q["name"]: q["decision"] for q in result["statement"]}
    assert all(decided[f"reversal_{a}"] == "compensate" for a in "xyz")
    # one decision, said the same in the accuracy section and on the first screen
    assert result["accuracy"]["reversal"]["advice"] == "; ".join(a["text"] for a in plays)
    first = report.summary_text(result, verbose=False)
    assert all(a["text"] in first.replace("−", "-") for a in plays)
    assert "backlash (reversal) parameter: joint x +" in first.replace("−", "-")


def test_a_record_without_advice_gets_none_made_up() -> None:
    # The first screen prints the record's advice verbatim and makes up none of its
    # own: a record without it (a model with no Δρ, or older than the statement) says
    # so, rather than reading its sections a second way.
    from result_builders import golden_result

    from station.report.first_screen import NO_ADVICE

    result = golden_result()
    said = [a["text"] for a in result["advice"]]
    todo = _todo(report.summary_text(result, verbose=False))
    assert todo == said
    result["advice"] = None
    assert _todo(report.summary_text(result, verbose=False)) == [NO_ADVICE]


def _todo(text: str) -> list[str]:
    """The first screen's "to do" lines: the first labelled, the rest below it."""
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.strip().startswith("to do"))
    out = [lines[start].strip().removeprefix("to do").strip()]
    for ln in lines[start + 1:]:
        if not ln.startswith(" " * 16) or not ln.strip():
            break
        out.append(ln.strip())
    return out


def _tool(name: str, value_mm: float, decision: str | None) -> Quantity:
    return Quantity(name=name, value=value_mm, unit="mm", expanded=None,
                    interval_95=(0.5 * value_mm, 1.5 * value_mm), k=None, dof=None,
                    decision=decision, basis=[])


@pytest.mark.parametrize("count", [None, DriveCount(target_mm={"x": 0.01, "y": 0.01,
                                                              "z": 0.01},
                                                    rms_mm=0.0052, max_mm=0.0145)])
def test_the_geometry_advised_says_what_the_drives_count_leaves_either_way(
        count: DriveCount | None) -> None:
    # (J17): the tool's figures are the geometry's; a 0.01 mm drive adds 5.2 µm RMS
    q = [_tool("tool.after.rms", 0.0016, None), _tool("tool.compensated.rms", 0.0002, GAIN)]
    said = statement_advice(fake_config(), q, [], True, None, drive_count=count)
    (item,) = [a for a in said if a.id == "controller"]
    assert "falls from 1.6 to 0.2 µm" in item.text
    either = "(the drive's count adds 5.2 µm RMS at the tool either way)"
    assert (either in item.text) is (count is not None)
    # no gain: no advice, count or not
    q[1] = _tool("tool.compensated.rms", 0.0015, NO_GAIN)
    assert not [a for a in statement_advice(fake_config(), q, [], True, None, drive_count=count)
                if a.id == "controller"]
