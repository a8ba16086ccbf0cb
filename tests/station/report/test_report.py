"""The run report: result.json is strict JSON, report.html stands alone and says
what happened, summary_text names the numbers, for complete and broken runs alike."""

from __future__ import annotations

import copy
import html
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError
from result_builders import (
    AXES,
    NO_GUARD_STOPS,
    PAPER_BEFORE,
    RHO_MAX,
    RHO_MIN,
    L,
    make_result,
)

from orthocal import coverage_factor
from station import report
from station.record.result import SCHEMA_VERSION
from station.report.format import um


def failed_result() -> dict:
    """Died on a device fault in the second setup: no fit, no write-back."""
    return {
        "schema_version": SCHEMA_VERSION,
        "run_dir": "runs/failed", "status": "failed",
        "message": "axis y alarm 17 (following error) at posture Π_y^+",
        "started": "2024-05-02T11:00:00+02:00", "finished": "2024-05-02T11:01:10+02:00",
        "duration_s": 70.0, "simulated": False, "simulation": None,
        "machine": {"id": None, "leg_length": L, "rho_min": RHO_MIN, "rho_max": RHO_MAX},
        "model": "rho", "method": "nonlinear", "identified": {}, "std_errors": {},
        "setups": [{"leg": "x", "indicators": {"A": "y", "B": "z"}, "cycles_used": 3,
                    "cycles_max": 5, "repeats": 0, "flagged": False, "spread_mm": 0.004}],
        "offsets_before": {"x": 0.0, "y": 0.0, "z": 0.0}, "offsets_written": None,
        "offsets_final": {"x": 0.0, "y": 0.0, "z": 0.0}, "offsets_held_by": "controller",
        "writeback": None, "verification": None, "plunger_guard": NO_GUARD_STOPS,
        "timing": {"wall_s": 70.0, "moves": 13, "readings": 60, "retries": 0,
                   "outliers_rejected": 0, "mountings": 1, "operator_s": 20.0},
    }


def refused_result() -> dict:
    r = make_result(verify=False)
    r["status"] = "refused"
    r["message"] = "correction of axis z exceeds max_abs_offset_mm = 1.0"
    r["offsets_written"] = None
    r["offsets_final"] = r["offsets_before"]  # nothing written: as the run found them
    r["writeback"] = {"status": "refused", "reason": r["message"]}
    return r


ALL_CASES = {
    "full-run": lambda: make_result(),
    "failed": failed_result,
    "refused": refused_result,
    "full-model": lambda: make_result(model="full"),
    "L-model": lambda: make_result(model="L"),
    "no-verification": lambda: make_result(verify=False),
    "paper-data": lambda: make_result(measured=PAPER_BEFORE, verify=False),
}


# ------------------------------------------------------------------ result.json


@pytest.mark.parametrize("case", sorted(ALL_CASES))
def test_result_json_round_trips(tmp_path: Path, case: str) -> None:
    result = ALL_CASES[case]()
    path = report.write_result(result, tmp_path)
    assert path == tmp_path / "result.json"
    text = path.read_text(encoding="utf-8")
    loaded = json.loads(text)
    assert loaded["status"] == result["status"]
    assert loaded.get("identified") == result.get("identified")
    assert loaded["offsets_written"] == result["offsets_written"]
    assert list(tmp_path.iterdir()) == [path], "temporary file left behind"
    assert path.stat().st_mode & 0o044 == 0o044, "report must be readable by others"


def test_result_json_has_no_nan_tokens_and_keeps_schema_order(tmp_path: Path) -> None:
    result = make_result()
    result["sigma_mm"] = float("nan")
    result["deviations"]["+xy"]["std"] = float("inf")
    result["identified"] = {k: np.float64(v) for k, v in result["identified"].items()}
    result["correlation"]["matrix"] = np.array([[1.0, float("nan"), 0.0]] * 3)
    text = report.write_result(result, tmp_path).read_text(encoding="utf-8")
    assert not re.search(r"\b(NaN|Infinity)\b", text)

    def strict(token: str) -> None:
        raise ValueError(f"non-standard JSON token {token}")

    loaded = json.loads(text, parse_constant=strict)
    assert loaded["sigma_mm"] is None
    assert loaded["deviations"]["+xy"]["std"] is None
    assert loaded["correlation"]["matrix"][0] == [1.0, None, 0.0]
    assert loaded["identified"]["drho_z"] == pytest.approx(float(result["identified"]["drho_z"]))
    keys = list(loaded)
    assert keys[:3] == ["schema_version", "run_dir", "status"]
    assert keys.index("identified") < keys.index("verification") < keys.index("timing")
    assert list(loaded["deviations"]) == list(report.DEVIATION_KEYS)


def test_result_json_is_validated_as_it_is_written(tmp_path: Path) -> None:
    """A field the record (station.record.result) does not declare, one it requires
    missing, or a value of another type is the engine's bug: it raises, no file."""
    for broken in ({**make_result(), "extra_field": 1.0},
                   {k: v for k, v in make_result().items() if k != "timing"},
                   {**make_result(), "writeback": {"status": "written", "reason": None,
                                                   "round": "1"}}):
        with pytest.raises(ValidationError):
            report.write_result(broken, tmp_path)
        with pytest.raises(ValidationError):
            report.jsonable(broken)
    assert not (tmp_path / "result.json").exists()


def test_jsonable_matches_the_file(tmp_path: Path) -> None:
    result = make_result()
    result["sigma_mm"] = float("nan")
    printed = json.dumps(report.jsonable(result), allow_nan=False)
    assert json.loads(printed) == json.loads(report.write_result(result, tmp_path).read_text())


def test_result_json_replaces_old_file_whole(tmp_path: Path) -> None:
    (tmp_path / "result.json").write_text("{ half a file")
    report.write_result(make_result(), tmp_path)
    assert json.loads((tmp_path / "result.json").read_text())["status"] == "ok"


def test_write_result_does_not_alter_the_callers_dict(tmp_path: Path) -> None:
    result = make_result()
    result["sigma_mm"] = float("nan")
    snapshot = copy.deepcopy(result)
    report.write_result(result, tmp_path)
    assert math.isnan(result["sigma_mm"])
    result["sigma_mm"] = snapshot["sigma_mm"] = 0.0
    assert result == snapshot


# ------------------------------------------------------------------ report.html


def _assert_self_contained(page: str) -> None:
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", page, re.I)
    assert not re.search(r"<script\b", page, re.I)
    assert not re.search(r"<link\b", page, re.I)
    assert not re.search(r"@import|url\(\s*['\"]?(?!#)", page, re.I)  # url(#id) is in-page
    assert "<!DOCTYPE svg" not in page and "<?xml" not in page


@pytest.mark.parametrize("case", sorted(ALL_CASES))
def test_html_is_self_contained_for_every_kind_of_run(tmp_path: Path, case: str) -> None:
    result = ALL_CASES[case]()
    path = report.write_html(result, tmp_path)
    page = path.read_text(encoding="utf-8")
    _assert_self_contained(page)
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    assert report.STATUS_TEXT[result["status"]] in page
    if result.get("identified"):
        assert page.count("<svg") == 2
    if result.get("message"):
        assert html.escape(result["message"]) in page


def test_html_contains_the_numbers(tmp_path: Path) -> None:
    result = make_result()
    page = report.write_html(result, tmp_path).read_text(encoding="utf-8")
    for name, value in result["identified"].items():
        assert report.fmt(value, signed=True) in page, name
        assert report.fmt(result["std_errors"][name]) in page, name
    for name, value in result["identified"].items():  # the table's, in µm
        assert report.fmt(1000 * value, 1, signed=True) in page, name
    for key, dev in result["deviations"].items():  # in µm, the table's one unit
        assert report.fmt(1000 * dev["mean"], 1, signed=True) in page, key
        assert report.fmt(1000 * (dev["mean"] - dev["model"]), 1, signed=True) in page, key
    for axis, value in result["offsets_written"].items():  # as left, mm
        assert report.fmt(value, 4, signed=True) in page, axis
    assert report.fmt(1000 * result["verification"]["deviations_rms_mm"], 1) in page
    assert report.fmt(1000 * result["residual_rms_mm"], 2) in page
    assert result["fit_note"] in page
    assert "Π<sub>x</sub><sup>+</sup> along y" in page
    assert "hidden truth" in page


def test_html_full_model_shows_leg_lengths_and_correlation(tmp_path: Path) -> None:
    result = make_result(model="full")
    page = report.render_html(result)
    assert "ΔL<sub>z</sub>" in page
    corr = result["correlation"]["matrix"]
    strongest = max(abs(corr[i][j]) for i in range(6) for j in range(6) if i != j)
    assert strongest > 0.9  # Δρ_i and ΔL_i act almost alike: the table must show it
    assert report.fmt(strongest, 4 if strongest >= 0.995 else 2) in page.replace("−", "")


def test_html_explains_refused_and_missing_sections() -> None:
    refused = report.render_html(refused_result())
    assert "NOT written" in refused
    assert "max_abs_offset_mm = 1.0" in refused
    # nothing written: the offsets as left are those as found
    rows = re.findall(r'<td class="l">joint [xyz]</td><td class="num">(.*?)</td>'
                      r'<td class="num">(.*?)</td>', refused)
    assert len(rows) == 3 and all(found == left for found, left in rows)
    failed = report.render_html(failed_result())
    assert "did not complete" in failed
    assert "after measuring 1 setup (leg x, 3 cycles)" in failed
    assert "No parameters were identified" in failed
    assert "as configured in the station config" in failed
    no_ver = report.render_html(make_result(verify=False))
    assert "No verification measurement was made" in no_ver
    assert no_ver.count("<svg") == 2


def test_html_escapes_hostile_text(tmp_path: Path) -> None:
    evil = '<script>alert("x")</script>'
    result = make_result(run_dir=f"runs/{evil}")
    result["message"] = f"odd {evil}"
    result["fit_note"] = evil
    result["writeback"]["reason"] = evil
    result["setups"][0]["indicators"] = {evil: "y"}
    page = report.write_html(result, tmp_path).read_text(encoding="utf-8")
    assert "<script" not in page
    assert "&lt;script&gt;" in page


def test_html_survives_nan_and_missing_fields() -> None:
    result = make_result()
    result["std_errors"]["drho_y"] = float("nan")
    result["deviations"]["+yx"]["std"] = None
    # what the record lets be missing: the correlation, the mountings' count and time
    del result["correlation"]
    result["timing"].update(mountings=None, operator_s=None)
    page = report.render_html(result)
    assert "nan" not in page.lower().replace("nanometre", "")
    assert page.count("<svg") == 2
    assert report.render_html({**failed_result(), "status": "aborted"}).count("Aborted") >= 1


# ------------------------------------------------------------------ summary


def test_summary_names_status_values_and_report() -> None:
    result = make_result()
    text = report.summary_text(result)
    assert text.splitlines()[0].startswith("orthocal run: COMPLETED")
    for name, value in result["identified"].items():
        # each joint's Δρ as found, with its 95 % half-width (k from Student's t)
        line = next(ln for ln in text.splitlines() if ln.startswith(f"  joint {name[-1]} "))
        found = re.search(r"as found ([+−]\d+\.\d{3}) mm ± (\d+\.\d) µm", line)
        assert found is not None, line
        assert float(found[1].replace("−", "-")) == pytest.approx(value, abs=0.0005)
        half = coverage_factor(result.get("std_errors_dof")) * result["std_errors"][name]
        assert float(found[2]) == pytest.approx(1000 * half, abs=0.05)
    # the small errors in µm, as the closed loop's lines and the report's tables say them
    assert f"residual      {um(result['residual_rms_mm'])} µm RMS" in text
    for axis in AXES:
        assert report.fmt(result["offsets_written"][axis]) in text
    before, after = result["deviations_rms_mm"], result["verification"]["deviations_rms_mm"]
    assert f"deviations RMS {um(before)} → {um(after)} µm" in text
    assert str(Path(result["run_dir"]) / "report.html") in text
    assert len(report.summary_text(result, verbose=False).splitlines()) <= 12


def test_summary_of_failed_and_refused_runs() -> None:
    failed = report.summary_text(failed_result())
    assert failed.startswith("orthocal run: FAILED — axis y alarm 17")
    assert "identified" not in failed
    refused = report.summary_text(refused_result())
    assert "not written (refused: correction of axis z" in refused
    assert "verification" not in refused
