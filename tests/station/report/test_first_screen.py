"""The first screen: ``orthocal run``'s summary opens with what the operator needs
(the verdict, each joint's Δρ as found → as left, the offsets, the tool before →
after, what to do, the mountings and the time, where the report is), each value
once, at 95 % and labelled; the rest only with ``--verbose``; report.html opens
with the same block."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
from builders import Completed, cli
from stated_runs import stated

from station import report

ROOT = Path(__file__).resolve().parents[3]
REHEARSAL = ROOT / "examples" / "rehearsal.toml"
TRUE_DRHO = {"x": 0.7, "y": -1.1, "z": 0.35}  # examples/rehearsal.toml's hidden Δρ
NUMBER = r"([+−-]\d+\.\d+)"


def _num(text: str) -> float:
    return float(text.replace("−", "-"))


@pytest.fixture(scope="module")
def rehearsed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Completed, dict[str, Any]]:
    """``orthocal run --simulate examples/rehearsal.toml``, once for the module; its
    report without figures (the first screen is text; figures have their own tests)."""
    here = tmp_path_factory.mktemp("rehearsal")
    sim = here / "rehearsal.toml"
    sim.write_text(REHEARSAL.read_text(encoding="utf-8") + "\n[report]\nfigures = false\n",
                   encoding="utf-8")
    done = cli("run", "--simulate", str(sim), "--out", "runs", cwd=here)
    run_dir = next((here / "runs").glob("run-*"))
    result = json.loads((run_dir / "result.json").read_text())
    return done, {**result, "run_dir": str(run_dir)}  # the record's is relative to here


def _completed(done: Completed) -> None:
    """Completed: converged (0) or not (3, the headline says why); both are verdicts."""
    assert done.returncode in (0, 3), done.stderr[-2000:]
    head = done.stdout.splitlines()[0]
    assert head == "orthocal run: COMPLETED" if done.returncode == 0 else \
        head.startswith("orthocal run: NOT CONVERGED — "), head


def test_the_rehearsal_ends_as_its_comment_says(rehearsed: Any) -> None:
    done, _ = rehearsed
    said = stated(REHEARSAL)
    assert said is not None and said.argv[:2] == ("run", "--simulate")
    assert said.ends_so(done.returncode, done.stdout, done.stderr) is None, \
        said.ends_so(done.returncode, done.stdout, done.stderr)


def test_the_first_twelve_lines_hold_verdict_joints_and_tool(rehearsed: Any) -> None:
    done, result = rehearsed
    _completed(done)
    first = done.stdout.splitlines()[:12]
    for axis, truth in TRUE_DRHO.items():
        line = next(ln for ln in first if ln.startswith(f"  joint {axis} "))
        found = re.search(rf"as found {NUMBER} mm ± (\d+\.\d) µm → as left {NUMBER} ± "
                          rf"(\d+\.\d) µm \(95 %\)", line)
        assert found is not None, line
        value, half = _num(found[1]), float(found[2]) / 1000
        # the statement holds the hidden truth within its 95 % interval, which is
        # tens of µm, not a millimetre
        assert value - half <= truth <= value + half, line
        assert 0.001 < half < 0.05, line
        left, left_half = _num(found[3]), float(found[4])
        assert abs(left) <= 10.0 and 0.1 < left_half < 10.0, line
    tool = next(ln for ln in first if ln.startswith("  at the tool "))
    figures = re.search(r"(\d+\.\d) → (\d+\.\d) µm RMS \(95 %: (\d+\.\d)–(\d+\.\d) µm\)", tool)
    assert figures is not None, tool
    before, after, lo, hi = map(float, figures.groups())
    assert before > 3 * after and lo <= after <= hi, tool
    acc = result["accuracy"]
    assert before == pytest.approx(1000 * acc["before"]["rms_mm"], abs=0.06)
    assert after == pytest.approx(1000 * acc["after"]["rms_mm"], abs=0.06)
    # with the geometry in the controller: the statement's figure, on the next line
    after_tool = first[first.index(tool) + 1]
    assert after_tool.startswith(" " * 16 + "with the geometry in the controller "), after_tool
    comp = next(q for q in result["statement"] if q["name"] == "tool.compensated.rms")
    assert f"{1000 * comp['value']:.1f} µm RMS" in after_tool
    assert any(ln.startswith("  offsets       x ") and "(written)" in ln for ln in first)


def test_without_verbose_only_the_first_screen(rehearsed: Any) -> None:
    done, result = rehearsed
    _completed(done)
    lines = done.stdout.splitlines()
    # the headline, the joints, the offsets, the tool (two lines), what the joints' screws
    # were taken to be, one line per advice, the mountings, the report, the details; a
    # line beyond 160 characters goes on below, indented further
    labelled = [ln for ln in lines if not ln.startswith(" " * 16)]
    assert len(labelled) == 10 + (len(result["advice"]) > 0), done.stdout
    assert any(line.startswith("  joints        the tool's figures take x, y, z stated exact")
               for line in lines), done.stdout
    assert all(len(ln) <= 160 for ln in lines), [len(ln) for ln in lines]
    todo = next(i for i, ln in enumerate(lines) if ln.startswith("  to do "))
    said: list[str] = []  # each advice: from its line at 16 columns, on at 18
    for ln in lines[todo:]:
        if ln.startswith(" " * 18):
            said[-1] += " " + ln[18:]
        elif ln.startswith(" " * 16) or ln is lines[todo]:
            said.append(ln[16:])
        else:
            break
    assert said == [a["text"] for a in result["advice"]]
    assert lines[-1].startswith("  details ") and "--verbose" in lines[-1]
    for detail in ("  model ", "  closed loop ", "  budget ", "  squareness "):
        assert not any(ln.startswith(detail) for ln in lines), detail
    assert any(ln.startswith("  mountings     ") for ln in lines)
    assert any(ln.startswith("  report        ") and ln.endswith("report.html")
               for ln in lines)


def test_verbose_adds_the_details_and_repeats_no_value(rehearsed: Any) -> None:
    first, result = rehearsed
    # resume of a finished run prints its summary again, and exits as the run did
    done = cli("resume", result["run_dir"], "--verbose", cwd=Path(result["run_dir"]))
    assert done.returncode == first.returncode, done.stderr
    text = done.stdout
    assert text.startswith(first.stdout.splitlines()[0])
    for detail in ("  model ", "  closed loop ", "  budget ", "  squareness "):
        assert any(ln.startswith(detail) for ln in text.splitlines()), detail
    # each joint's Δρ as found, once: the statement line no longer repeats it
    for axis in TRUE_DRHO:
        line = next(ln for ln in text.splitlines() if ln.startswith(f"  joint {axis} "))
        value = re.search(rf"as found {NUMBER} mm", line)[1]
        assert text.count(value + " mm") == 1, value
    # no Δρ with an unlabelled ± anywhere: every ± line says 95 %
    for ln in text.splitlines():
        if "±" in ln and "Δρ" in ln:
            assert "95 %" in ln, ln


def test_the_report_opens_with_the_same_block(rehearsed: Any) -> None:
    _, result = rehearsed
    page = (Path(result["run_dir"]) / "report.html").read_text(encoding="utf-8")
    top = page.split("What was done")[0]
    assert 'id="first-screen"' in top
    for line in report.summary_text(result, verbose=False).splitlines()[1:6]:
        text = line.strip().partition("  ")[2]
        assert text.strip().replace("→", "&#8594;") in top or text.strip() in top, line
