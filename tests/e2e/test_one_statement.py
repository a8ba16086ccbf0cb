"""One statement of the machine (docs/design.md, "The statement of the machine"): a run's
first screen and its ``--verbose`` details print every ± of a joint's Δρ, a tilt, a gap,
a squareness and the tool as the statement's ``expanded`` (to the digits printed),
every "to do" line is one of ``advice``'s texts, no two pieces of advice contradict, and
the loop's verdict agrees with the statement's decisions."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from fakes import FakeRig, fake_config, run_on

from station.record.io import parse_result
from station.record.quantity_text import figure, interval, plus_minus
from station.record.result import RunResult
from station.report.text import summary_text

GAPS = (0.15, -0.10, 0.12)
TILTS = (0.2, 0.1, -0.15)
#: "±" and what follows it, as a view prints it: a number and its unit.
PM = re.compile(r"± (\d+(?:\.\d+)?) (µm|mm/m|mrad|µm/m)")


def _run(out: Path, **machine: Any) -> RunResult:
    rig = FakeRig(**{"seed": 12, "noise_mm": 0.001, "mount_error_mm": 5.0,
                     "true_drho": (0.6, -0.4, 0.9), **machine})
    config = fake_config(uncertainty={"leg_straightness_mm": 0.0005,
                                      "temperature_change_c": 0.1},
                         settle_s=0.0, cycles=3)
    code, doc = run_on(rig, out, config)
    assert code in (0, 3), doc.get("message")
    return parse_result(doc)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, RunResult]:
    out = tmp_path_factory.mktemp("statement")
    return {"gapped": _run(out / "gapped", true_gap=GAPS, backlash=(0.0, 0.0, 0.004)),
            "tilted": _run(out / "tilted", true_tilt=TILTS)}


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_every_plus_minus_printed_is_a_quantity_s_expanded(runs, kind: str) -> None:
    result = runs[kind]
    assert result.statement, "the run states its machine"
    text = summary_text(result, verbose=True)
    # a value as stated, or its magnitude (advice says "leans … by 0.200 ± 0.021")
    stated = {t for q in result.statement for t in (plus_minus(q), plus_minus(q).lstrip("+-"))}
    printed = PM.findall(text)
    assert printed, "the summary prints values at 95 %"
    for line in text.splitlines():
        for match in re.finditer(r"([+−-]?\d+(?:\.\d+)? (?:mm )?± \d+(?:\.\d+)? "
                                 r"(?:µm|mm/m|mrad|µm/m))", line):
            said = match.group(1).replace("−", "-")
            assert said in stated, f"{said!r} in {line.strip()!r} is no stated quantity"


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_the_tool_s_intervals_are_the_statement_s(runs, kind: str) -> None:
    result = runs[kind]
    q = {x.name: x for x in result.statement or []}
    text = summary_text(result, verbose=False)
    for name in ("tool.after.rms", "tool.after.max", "tool.compensated.rms"):
        assert interval(q[name]) in text.replace("−", "-"), name
    after = q["tool.after.rms"]
    lo, hi = after.interval_95 or (0.0, 0.0)
    assert 0.0 <= lo <= (after.value or 0.0) <= hi
    # a max is never below its RMS, value and both ends
    mx = q["tool.after.max"]
    assert (mx.value or 0.0) >= (after.value or 0.0)
    assert mx.interval_95 is not None and mx.interval_95[0] >= lo and mx.interval_95[1] >= hi
    assert figure(after, "RMS") in text.replace("−", "-")


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_every_to_do_is_an_advice_text_and_none_contradict(runs, kind: str) -> None:
    result = runs[kind]
    texts = [a.text for a in result.advice or []]
    assert texts
    lines = summary_text(result, verbose=False).splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("  to do"))
    todo = [lines[start][16:]]
    todo += [ln[16:] for ln in lines[start + 1:] if ln.startswith(" " * 16)]
    assert [t.replace("−", "-") for t in todo] == [t.replace("−", "-") for t in texts]
    ids = {a.id for a in result.advice or []}
    # no "nothing" beside an act; no rail advice beside "undecided"
    assert not ("nothing" in ids and len(ids) > 1)
    assert not ("undecided.layout" in ids and any(i.startswith(("shim.", "rail."))
                                                  for i in ids))
    gains = any(q.name == "tool.compensated.rms" and q.decision == "gain"
                for q in result.statement or [])
    for a in result.advice or []:
        if a.id.startswith(("shim.", "rail.")):
            assert ("controller" in a.text) == gains, a.text
        names = {q.name for q in result.statement or []}
        assert set(a.rests_on) <= names, a.id


def test_the_gaps_act_and_the_controller_gains_on_the_gapped_machine(runs) -> None:
    result = runs["gapped"]
    q = {x.name: x for x in result.statement or []}
    for name, true in zip(("gap_xy", "gap_xz", "gap_yz"), GAPS, strict=True):
        assert q[name].decision == "act"
        lo, hi = q[name].interval_95 or (0.0, 0.0)
        assert lo < true < hi, (name, lo, hi)
    assert q["tool.compensated.rms"].decision == "gain"
    ids = [a.id for a in result.advice or []]
    assert {"rail.gap_xy", "rail.gap_xz", "rail.gap_yz", "controller"} <= set(ids)


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_the_loop_s_verdict_is_the_statement_s(runs, kind: str) -> None:
    result = runs[kind]
    left = [q for q in result.statement or [] if q.name.endswith(".as_left")]
    assert len(left) == 3
    within = all(q.decision == "within" for q in left)
    assert result.converged is within
    assert (result.loop is not None and result.loop.stopped == "converged") is within
    for q in left:
        found = next(x for x in result.statement or [] if x.name ==
                     q.name.replace("as_left", "as_found"))
        assert found.expanded == q.expanded  # one uncertainty for the joint
    budget = result.uncertainty_budget
    assert budget is not None and not hasattr(budget, "error")
    for q in left:
        assert budget.expanded_95_mm[q.name.split(".")[0]] == pytest.approx(q.expanded)
