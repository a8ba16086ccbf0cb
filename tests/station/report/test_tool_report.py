"""Accuracy at the tool in the report: report.html's section, the
headline that no longer lets "legs parallel" stand for "accurate", the summary's
"at the tool" and squareness lines, the stands, and results without the block.

The two real results (objective joints and objective tool, a simulated machine
with Δρ = (0.5, −0.3, 0.8) mm and tilts (0.2, 0.1, −0.15) mrad) are in
tests/data/result_tilted_{joints,tool}.json, made by the station; the synthetic
results below cover the rest.
"""

from __future__ import annotations

import copy
import html
import itertools
import json
import re
from pathlib import Path
from typing import Any

import pytest
from pydantic import ValidationError
from result_builders import golden_result, make_result

from station import report
from station.report import stand_table, tool

SAMPLES = Path(__file__).parents[2] / "data"
K = 1.96


def _sample(objective: str) -> dict[str, Any]:
    path = SAMPLES / f"result_tilted_{objective}.json"
    with path.open(encoding="utf-8") as f:
        return json.load(f)


@pytest.fixture(params=["joints", "tool"])
def sample(request: pytest.FixtureRequest) -> dict[str, Any]:
    return _sample(request.param)


def um(mm: float) -> str:
    """µm as the page formats them (one decimal)."""
    return report.fmt(1000 * mm, 1)


def section(page: str) -> str:
    """The "Accuracy at the tool" section: from its heading to the next h2."""
    start = page.index('<h2 id="accuracy">Accuracy at the tool</h2>')
    end = page.index("<h2", start + 10)
    return page[start:end]


def headline(page: str) -> str:
    """The result paragraph: the first paragraph after <h2>Result</h2>."""
    start = page.index("<h2>Result</h2>")
    return page[start:page.index("</p>", start)]


def text_of(fragment: str) -> str:
    return html.unescape(re.sub(r"<[^>]+>", "", fragment))


def rows_of(fragment: str) -> list[list[str]]:
    """The body rows' cells as text (the header row has none)."""
    rows = [[text_of(c) for c in re.findall(r"<td[^>]*>(.*?)</td>", row, re.S)]
            for row in re.findall(r"<tr>(.*?)</tr>", fragment, re.S)]
    return [r for r in rows if r]


def synthetic_accuracy(*, tilted: bool = True, objective: str = "joints") -> dict[str, Any]:
    """An accuracy block of the engine's shape on a 3³ grid: before 200 µm, after
    12 µm, squareness beyond (tilted) or within (square) its uncertainty."""
    levels = (-100.0, -20.0, 60.0)
    points = [list(p) for p in itertools.product(levels, repeat=3)]
    before = [[0.1 + 0.001 * x, -0.05, 0.02] for x, _, _ in points]
    after = [[0.0001 * y, -0.0001 * x, 0.002] for x, y, _ in points]
    sq = {"xy": 0.20, "xz": 0.10, "yz": -0.15} if tilted else {"xy": 0.004, "xz": -0.003,
                                                              "yz": 0.002}
    ses = dict.fromkeys(sq, 0.01)
    joints = {"after": {"rms_mm": 0.0121, "max_mm": 0.0302},
              "offsets_mm": {"x": -0.355, "y": 0.45, "z": -1.98},
              "target_drho_mm": {"drho_x": 0.0, "drho_y": 0.0, "drho_z": 0.0}}
    best = {"after": {"rms_mm": 0.0066, "max_mm": 0.0131},
            "offsets_mm": {"x": -0.311, "y": 0.43, "z": -1.98},
            "target_drho_mm": {"drho_x": 0.044, "drho_y": -0.02, "drho_z": 0.0}}
    objectives = {"joints": joints, "tool": best}
    other = "tool" if objective == "joints" else "joints"
    return {
        "workspace_mm": [[-100.0, 60.0]] * 3,
        "grid": {"points_per_axis": 3, "points": 27, "excluded": 0},
        "frame": "translation", "objective": objective,
        "before": {"rms_mm": 0.2004, "max_mm": 0.4101},
        "after": {"rms_mm": 0.0123, "max_mm": 0.0307,
                  "rms_interval_95_mm": [0.0111, 0.0135],
                  "max_interval_95_mm": [0.0270, 0.0342]},
        "after_method": "linearised (test)",
        "objectives": objectives,
        "alternative": {"objective": other, **objectives[other]},
        "squareness_mm_per_m": sq, "squareness_std_errors": ses,
        "squareness_advice": [
            "axis y leans toward +x by 0.200 ± 0.020 mm/m (tilt_yx): offsets cannot fix it; "
            "shim its rail by 32 µm over its 160 mm of travel, or compensate in the "
            "controller's kinematics (model.json)"] if tilted else [
            "axis y toward x (tilt_yx): +0.004 mm/m, within its uncertainty (±0.020): "
            "nothing to do"],
        "tilts": {"tilt_yx": sq["xy"], "tilt_zx": sq["xz"], "tilt_zy": sq["yz"]},
        "tilt_std_errors": {"tilt_yx": 0.01, "tilt_zx": 0.01, "tilt_zy": 0.01},
        "tilt_interval_95": None,
        # stated by the engine, none here: no best offsets, no decision, no gaps, not
        # in the controller
        "best_offsets_can_do": None, "squareness_decision": None, "gaps": None,
        "gap_std_errors": None, "gap_interval_95": None, "gap_advice": None,
        "compensated": None,
        "field": {"points_mm": points, "before_mm": before, "after_mm": after},
        "assumes": ["ΔL = 0 (leg lengths nominal; not identifiable beside the tilts)",
                    "frame 'translation': the tool offset is set by touching off"],
    }


def synthetic(**kwargs: Any) -> dict[str, Any]:
    result = make_result()
    result["accuracy"] = synthetic_accuracy(**kwargs)
    result["stands"] = {
        "stand_xy": {"gauges": ["xy"], "observable": True, "prior_sd_mm": 2.887,
                     "offset_mm": 1.3075, "std_error_mm": 1.9717},
        "stand_yx": {"gauges": ["yx"], "observable": False, "prior_sd_mm": 2.887,
                     "offset_mm": None, "std_error_mm": None,
                     "note": "not observable: the offsets Δρ are too small for this stand "
                             "to change the deviations"},
    }
    return result


_PAGES: dict[str, str] = {}


def page_of(result: dict[str, Any]) -> str:
    """``report.render_html(result)``, drawn once per distinct result and worker: most
    tests here read the two samples' pages, and drawing a page's figures costs about
    a second of CPU. The page is a function of the result alone."""
    key = json.dumps(result, sort_keys=True)
    if key not in _PAGES:
        _PAGES[key] = report.render_html(result)
    return _PAGES[key]


def _assert_self_contained(page: str) -> None:
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", page, re.I)
    assert not re.search(r"<script\b|<link\b|<image\b", page, re.I)
    assert not re.search(r"@import|url\(\s*['\"]?(?!#)", page, re.I)
    assert "<!DOCTYPE svg" not in page and "<?xml" not in page


# ------------------------------------------------------------- the real results


def test_section_states_before_and_after_in_um_right_after_the_result(
        sample: dict[str, Any], tmp_path: Path) -> None:
    page = report.write_html(sample, tmp_path).read_text(encoding="utf-8")
    _assert_self_contained(page)
    acc = sample["accuracy"]
    sec = section(page)
    # placed early: right after the result paragraph, before the fit and Figure 2
    assert page.index("<h2>Result</h2>") < page.index(sec) < page.index("Fit quality")
    assert page.index(sec) < page.index("<h2>Identified parameters</h2>")
    table = rows_of(sec[:sec.index("</table>")])
    assert table[0] == ["RMS |E|", um(acc["before"]["rms_mm"]), um(acc["after"]["rms_mm"]),
                        "–".join(um(v) for v in acc["after"]["rms_interval_95_mm"])]
    assert table[1] == ["max |E|", um(acc["before"]["max_mm"]), um(acc["after"]["max_mm"]),
                        "–".join(um(v) for v in acc["after"]["max_interval_95_mm"])]
    assert "after (offsets written)" in sec
    assert "[−100, 60]³ mm" in sec and "<code>translation</code>" in sec
    assert "300 points, 43 outside the soft limits left out" in sec
    for sentence in acc["assumes"]:
        assert html.escape(sentence) in sec
    assert "<code>model.json</code>" in sec and "compensates kinematics" in sec


def test_the_joints_sample_reads_as_the_engine_states_it() -> None:
    page = page_of(_sample("joints"))
    sec = text_of(section(page))
    assert "229.6" in sec and "13.7" in sec and "12.0–15.0" in sec and "28.2–37.5" in sec


def test_both_objectives_side_by_side_with_the_written_one_marked(
        sample: dict[str, Any]) -> None:
    sec = section(page_of(sample))
    part = sec[sec.index("<h3>The two objectives</h3>"):]  # tool error (µm), offsets (mm)
    rows, offsets, *_ = ({r[0].split(":")[0]: r for r in rows_of(t)} for t in part.split("</tab"))
    assert set(rows) == set(offsets) == {"joints", "tool"}
    chosen = sample["accuracy"]["objective"]
    for name, row in rows.items():
        obj = sample["accuracy"]["objectives"][name]
        assert row[1:3] == [um(obj["after"]["rms_mm"]), um(obj["after"]["max_mm"])]
        assert offsets[name][1:] == [report.fmt(obj["offsets_mm"][a], signed=True) for a in "xyz"]
        assert row[-1] == ("written" if name == chosen else "not chosen")


def test_squareness_with_its_95_interval_and_the_advice(sample: dict[str, Any]) -> None:
    acc = sample["accuracy"]
    sec = section(page_of(sample))
    part = sec[sec.index("<h3>Squareness of the axes</h3>"):]
    rows = rows_of(part[:part.index("</table>")])
    assert [r[0] for r in rows] == ["XY", "XZ", "YZ"]
    for row, pair in zip(rows, ("xy", "xz", "yz"), strict=True):
        assert row[1] == report.fmt(acc["squareness_mm_per_m"][pair], signed=True)
        assert row[2] == report.fmt(K * acc["squareness_std_errors"][pair])
        assert row[-1] == "beyond its uncertainty"  # 0.1–0.2 mm/m against ±0.02
    assert "k = 1.96" in part
    for advice in acc["squareness_advice"]:
        assert html.escape(advice) in sec
    assert "shim its rail" in sec and "offsets cannot fix it" in sec


def test_the_error_field_is_an_inline_svg_in_the_section(sample: dict[str, Any]) -> None:
    page = page_of(sample)
    sec = section(page)
    assert sec.count("<svg") == 1 and "<figure><svg" in sec
    assert "Figure 1. The tool-point error E over the workspace" in sec
    # z slices of the grid and the scale arrow, drawn as text in the SVG's glyphs
    # (matplotlib writes text as paths; the caption says what the picture shows)
    assert "arrow in the corner" in sec and "three horizontal slices" in sec
    # the legs' figures follow, renumbered
    assert "Figure 2. The 12 leg deviations" in page and "Figure 3. Identified" in page


def test_the_headline_says_what_the_tool_does(sample: dict[str, Any]) -> None:
    acc = sample["accuracy"]
    head = text_of(headline(page_of(sample)))
    assert "legs now parallel to within" in head  # the fact stays
    assert "the legs' parallelism, the method's means, not the tool's accuracy" in head
    assert (f"at the tool, by the identified model, commanded points land within "
            f"{um(acc['after']['rms_mm'])} µm RMS (max {um(acc['after']['max_mm'])} µm; "
            f"95 %: ") in head
    assert f"against {um(acc['before']['rms_mm'])} µm RMS" in head
    assert "frame translation" in head
    # the tilts dominate this machine: the headline says the squareness is most of it
    assert "the axes' squareness, which offsets cannot fix, is most of it" in head


def test_summary_has_the_tool_line_and_labels_the_legs_parallelism(
        sample: dict[str, Any]) -> None:
    acc = sample["accuracy"]
    lines = report.summary_text(sample).splitlines()
    ver = next(ln for ln in lines if ln.startswith("  verification  "))
    assert "legs' parallelism (the method's means, not the tool's accuracy)" in ver
    at, before, after = next(ln for ln in lines if "  at the tool " in ln), acc["before"], \
        acc["after"]
    iv = "–".join(um(v) for v in after["rms_interval_95_mm"])
    assert f"{um(before['rms_mm'])} → {um(after['rms_mm'])} µm RMS (95 %: {iv} µm)" in at
    assert f"max {um(before['max_mm'])} → {um(after['max_mm'])} µm" in at
    aim, alt = next(ln for ln in lines if ln.startswith("  objective  ")), acc["alternative"]
    assert f"objective     {acc['objective']} (" in aim and ") written" in aim
    assert f"objective {alt['objective']} would leave {um(alt['after']['rms_mm'])} µm" in aim
    sq = next(ln for ln in lines if ln.startswith("  squareness    "))
    for pair in ("xy", "xz", "yz"):
        assert (f"{pair.upper()} {report.fmt(acc['squareness_mm_per_m'][pair], signed=True)}"
                f" ± {report.fmt(K * acc['squareness_std_errors'][pair])}") in sq
    assert "offsets cannot fix it" in sq
    assert lines.index(at) < lines.index(ver) < lines.index(aim) < lines.index(sq)


def test_where_the_stands_were(sample: dict[str, Any]) -> None:
    page = page_of(sample)
    part = page[page.index("<h3>Where the stands were</h3>"):]
    rows = {r[0]: r for r in rows_of(part[:part.index("</table>")])}
    assert set(rows) == set(sample["stands"])
    for name, est in sample["stands"].items():
        if est["observable"]:
            assert rows[name][2:4] == [report.fmt(est["offset_mm"], 2, signed=True),
                                       report.fmt(est["std_error_mm"], 2)]
        else:
            assert rows[name][2] == "—" and "not observable" in rows[name][4]
    assert rows["stand_xy"][1] == "leg x, along y"


def test_the_tool_objectives_left_over_is_measured_from_its_aim() -> None:
    text = report.summary_text(_sample("tool"))
    left = next(ln for ln in text.splitlines() if ln.startswith("  joint x "))  # its aim:
    assert "as left +43.5 ± " in left and "(aimed at +43.6 µm, objective tool)" in left
    assert "correction max 43.50 µm" not in text


def test_a_result_without_accuracy_renders_and_claims_nothing(
        sample: dict[str, Any]) -> None:
    result = copy.deepcopy(sample)
    del result["accuracy"]
    page = report.render_html(result)
    assert "commanded points land" not in page
    assert "accuracy at the tool is not stated by this result" in headline(page)
    assert "not stated" in section(page)
    assert "Figure 1. The 12 leg deviations" in page
    assert "at the tool" not in (text := report.summary_text(result))
    first = page[page.index('id="first-screen"'):page.index("</section>")]
    assert "legs' parallelism" in text and "at the tool" not in first
    assert um(sample["accuracy"]["after"]["rms_mm"]) + " µm" not in page.replace(first, "")


def test_a_result_whose_accuracy_failed_says_so(sample: dict[str, Any]) -> None:
    result = copy.deepcopy(sample)
    result["accuracy"] = {"error": "not stated: singular matrix <b>"}
    page = report.render_html(result)
    assert "commanded points land" not in page
    assert "not stated (singular matrix &lt;b&gt;)" in headline(page)
    assert "singular matrix &lt;b&gt;" in section(page) and "<b>)" not in page
    assert section(page).count("<svg") == 0
    assert "  at the tool   not stated: singular matrix <b>" in report.summary_text(result)


# --------------------------------------------------------- synthetic: everywhere


def test_synthetic_section_numbers_field_and_marks() -> None:
    result = synthetic()
    page = report.render_html(result)
    _assert_self_contained(page)
    sec = section(page)
    assert "200.4" in sec and "12.3" in sec and "11.1–13.5" in sec and "27.0–34.2" in sec
    assert sec.count("<svg") == 1
    assert page.count("<svg") == 3  # the field beside the legs' two figures
    objectives = sec[sec.index("The two objectives"):]
    marks = [r[-1] for r in rows_of(objectives[:objectives.index("</table>")])]
    assert marks == ["written", "not chosen"]
    assert "shim its rail by 32 µm" in sec
    head = text_of(headline(page))
    assert "commanded points land within 12.3 µm RMS (max 30.7 µm; 95 %: 11.1–13.5 µm RMS" \
        in head
    assert "objective tool's offsets would cancel part of it, to 6.6 µm RMS" in head
    assert "Where the stands were" in page and "+1.31" in page


def test_synthetic_summary_lines() -> None:
    text = report.summary_text(synthetic(objective="tool"))
    at = next(ln for ln in text.splitlines() if ln.startswith("  at the tool"))
    assert "200.4 → 12.3 µm RMS (95 %: 11.1–13.5 µm), max 410.1 → 30.7 µm (95 %: 27.0" in at
    aim = next(ln for ln in text.splitlines() if ln.startswith("  objective"))
    assert "objective     tool (the least predicted tool error) written" in aim and \
        "objective joints would leave 12.1 µm RMS (max 30.2 µm)" in aim
    assert "XY +0.200 ± 0.020, XZ +0.100 ± 0.020, YZ −0.150 ± 0.020 mm/m (95 %, k = 1.96)" \
        in text


def test_a_square_machine_is_said_to_be_square() -> None:
    result = synthetic(tilted=False)
    page = report.render_html(result)
    assert "square within their uncertainty" in text_of(headline(page))
    assert "squareness, which offsets cannot fix, is most of it" not in page
    sec = section(page)
    assert sec.count("within its uncertainty") >= 3 and "nothing to do" in sec
    assert "square within its uncertainty" in report.summary_text(result)
    assert "offsets cannot fix it" not in report.summary_text(result)


def test_an_axis_leans_by_the_results_decision_not_by_its_95_interval(
        sample: dict[str, Any]) -> None:
    # A squareness beyond its 95 % half-width is one square machine in seven over the
    # three axes: the result's squareness_decision says when an axis counts as leaning
    # (k for one false alarm in a thousand, or none when the model test kept no tilt).
    acc = sample["accuracy"]
    se = acc["squareness_std_errors"]
    k_beyond = 0.9 * min(abs(v) / se[p] for p, v in acc["squareness_mm_per_m"].items())
    for decision, leans in ((None, True), ({"k": k_beyond, "rule": "r"}, True),
                            ({"k": 1e6, "rule": "beyond 1e6 standard errors"}, False),
                            ({"k": None, "rule": "the model test kept no tilt"}, False)):
        result = copy.deepcopy(sample)
        if decision is None:
            result["accuracy"].pop("squareness_decision", None)
        else:
            result["accuracy"]["squareness_decision"] = decision
        # the squareness table and the summary are the subject: no figures to draw
        page = report.render_html(result, figures=False)
        part = section(page)[section(page).index("<h3>Squareness of the axes</h3>"):]
        rows = rows_of(part[:part.index("</table>")])
        text = report.summary_text(result)
        assert ("offsets cannot fix it" in text) is leans
        # never "within" of an interval that excludes zero (the lean is decided apart)
        beyond = {r[0] for r in rows if abs(float(r[1].replace("−", "-"))) > float(r[2])}
        apart = "beyond its 95 % interval; no lean of the axis told apart"
        assert [r[-1] for r in rows] == ["beyond its uncertainty" if leans else apart
                                         if r[0] in beyond else "within its uncertainty"
                                         for r in rows]
        assert "square within its uncertainty" not in text and beyond
        assert ("out of square beyond their 95 % interval" in text) is not leans
        assert ("shear the motions, not the rails" in text) is not leans
        if decision is not None:
            assert html.escape(decision["rule"]) in part


def test_offsets_not_written_say_the_after_figures_are_what_writing_would_give() -> None:
    result = synthetic()
    result["status"], result["offsets_written"] = "refused", None
    result["writeback"] = {"status": "refused", "reason": "too large"}
    page = report.render_html(result)
    sec = section(page)
    assert "after, had the offsets been written" in sec and "chosen</b> (not written)" in sec
    assert "as the machine stands, the offsets not written" in text_of(headline(page))
    at = next(ln for ln in report.summary_text(result).splitlines() if "  at the tool" in ln)
    assert "200.4 µm RMS (max 410.1 µm) as the machine stands, over [−100, 60]³ mm; written, " \
        "the offsets would leave 12.3 µm RMS (95 %: 11.1–13.5 µm)" in at and "→" not in at
    aim = next(ln for ln in report.summary_text(result).splitlines() if "  objective " in ln)
    assert "objective     joints (the paper's Δρ: legs parallel) NOT written" in aim


@pytest.mark.parametrize("damage", ["bad-field", "no-tilts", "nan"])
def test_odd_accuracy_blocks_never_raise(damage: str) -> None:
    """Blocks the record admits but the report cannot use all of: a field of no
    usable shape, no tilts, a squareness that was not finite (written as null)."""
    result = synthetic()
    acc = result["accuracy"]
    if damage == "bad-field":
        acc["field"] = {"points_mm": [[1, 2]], "before_mm": [[0.0]], "after_mm": []}
    elif damage == "no-tilts":
        acc.update(tilts=None, tilt_std_errors=None, squareness_std_errors={},
                   squareness_advice=["the tilts were not identified: squareness not stated"])
    elif damage == "nan":
        acc["squareness_mm_per_m"]["xy"] = float("inf")
    page = report.render_html(result)
    text = report.summary_text(result)
    assert page.rstrip().endswith("</html>") and "nan" not in text.lower()
    if damage == "bad-field":
        assert section(page).count("<svg") == 0 and page.count("<svg") == 2
    if damage == "no-tilts":
        assert "Squareness is not stated" in page and "squareness    not stated" in text
        assert "is most of it" not in page
    if damage == "nan":
        assert "XY" not in next(ln for ln in text.splitlines() if "squareness" in ln)


@pytest.mark.parametrize("damage", [
    "no-field", "bad-field", "no-intervals", "no-objectives", "nan", "not-a-dict", "empty",
])
def test_broken_accuracy_blocks_are_refused_before_a_line_is_drawn(damage: str) -> None:
    """A block that is not the record's (station.record.result_accuracy) is the
    engine's bug or a damaged file: the report's boundary refuses the document."""
    result = synthetic()
    acc = result["accuracy"]
    if damage == "no-field":
        del acc["field"]
    elif damage == "bad-field":
        acc["field"] = {"points_mm": [[1, 2]], "before_mm": "x", "after_mm": None}
    elif damage == "no-intervals":
        acc["after"] = {"rms_mm": 0.0123}
    elif damage == "no-objectives":
        del acc["objectives"], acc["alternative"]
    elif damage == "nan":
        acc["after"]["rms_mm"] = float("nan")  # null where a figure is required
    elif damage == "not-a-dict":
        result["accuracy"] = ["what"]
    elif damage == "empty":
        result["accuracy"] = {}
    with pytest.raises(ValidationError):
        report.render_html(result)
    with pytest.raises(ValidationError):
        report.summary_text(result)


def test_old_and_failed_results_have_no_false_statement() -> None:
    old = make_result()  # an older result: no accuracy, no stands
    page = report.render_html(old)
    assert "commanded points land" not in page and "Where the stands were" not in page
    assert "not stated" in section(page) and page.count("<svg") == 2
    aborted = make_result(verify=False)
    aborted.update(status="aborted", identified={}, std_errors={}, offsets_written=None,
                   writeback=None)
    assert "Accuracy at the tool" not in report.render_html(aborted)
    failed = make_result()
    failed.update(status="failed", identified={}, accuracy=None)  # as base_result has it
    assert "Accuracy at the tool" not in report.render_html(failed)
    assert "at the tool" not in report.summary_text(failed)


def test_tool_helpers_read_a_missing_block_as_not_stated() -> None:
    bare = report.as_result(make_result())  # no accuracy block, no stands
    assert tool.statement(bare) == (None, None)
    failed = report.as_result({**make_result(), "accuracy": {"error": "not stated: x"}})
    assert tool.statement(failed) == (None, "x")
    assert tool.tool_clause(bare) is None and tool.summary_lines(bare) == []
    no_drho = report.as_result(make_result(model="L"))  # nothing to state it of
    assert tool.html_section(no_drho) == "" and stand_table.stands_html(bare) == ""


def test_a_verification_s_correction_is_the_one_its_verdict_and_write_rest_on() -> None:
    # A verification's own Δρ̂ is one look; what the loop judges and writes after it
    # is that look joined with the rounds before (iterations[n].joined). The report's
    # "correction max" is the joined one, so it matches the offsets written next.
    result = golden_result()
    it = result["iterations"][1]
    joined = max(abs(it["joined"]["drho_mm"][f"drho_{a}"]) for a in "xyz")
    own = max(abs(it["identified"][f"drho_{a}"]) for a in "xyz")
    assert report.fmt(1000 * joined, 2) != report.fmt(1000 * own, 2)  # they differ here
    line = next(ln for ln in report.summary_text(result).splitlines()
                if ln.strip().startswith("verification 1"))
    assert f"correction max {report.fmt(1000 * joined, 2)} µm, rounds joined" in line
    # that the offsets written next are the joined one: engine/test_closed_loop_run
