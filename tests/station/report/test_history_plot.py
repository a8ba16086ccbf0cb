"""``orthocal history --plot FILE``: a machine's parameters over its runs drawn as
PNG or SVG, with each parameter's drift per month (station.history.trend)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from builders import Completed, cli
from result_builders import golden_result

from station.history.entry import entry_of
from station.history.store import HistoryStore, default_url
from station.history.trend import MIN_SPAN_DAYS, MONTH_DAYS, drift, series, why_no_drift
from station.report import as_result

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _frame(x: float, se: float = 0.0005) -> dict[str, Any]:
    return {"joint_error_mm": {a: {"value_mm": v, "std_error_mm": se}
                               for a, v in zip("xyz", (x, -0.3, 0.2), strict=True)},
            "dof": 30.0}


def _entry(name: str, machine: str, day: int, x: float, **extra: Any) -> dict[str, Any]:
    started = datetime(2026, 1, 1, 10, tzinfo=UTC) + timedelta(days=day)
    return {"run_dir": f"/runs/{name}", "machine_id": machine,
            "started": started.isoformat(),
            "finished": (started + timedelta(hours=1)).isoformat(), "status": "ok",
            "stopped": "converged", "converged": True, "as_found": _frame(x),
            "as_left": _frame(x + 0.05), "layout": {
                "tilt_yx": {"value": 0.1, "std_error": 0.01},
                "gap_xy": {"value": 0.004, "std_error": 0.001}}, **extra}


def test_the_drift_is_the_weighted_slope_of_the_as_found_values() -> None:
    # x drifts 2 µm per 31 days; the as-left values (offset by 50 µm) must not count:
    # they rest on the same verification as the as-found
    entries = [_entry(f"r{i}", "OG-1", 31 * i, 0.400 + 0.002 * i) for i in range(3)]
    points = series(entries)
    assert {"drho_x", "drho_y", "drho_z", "tilt_yx", "gap_xy"} == set(points)
    d = drift(points["drho_x"])
    assert d is not None and d.runs == 3
    per_month = 0.002 * MONTH_DAYS / 31.0
    assert d.per_month == pytest.approx(per_month, rel=1e-9)
    # σ of a slope over months 0, m, 2m with equal σ = 0.5 µm: σ/√(Σ(x − x̄)²)
    m = 31.0 / MONTH_DAYS
    assert d.std_error == pytest.approx(0.0005 / math.sqrt(2 * m * m), rel=1e-9)
    assert drift(points["drho_y"]).per_month == pytest.approx(0.0, abs=1e-12)
    assert drift(points["drho_x"][:1]) is None  # one run: no slope
    # values scattered beyond their σ: the slope's σ grows with them
    noisy = [_entry(f"n{i}", "OG-1", 31 * i, 0.4 + (0.01 if i == 1 else 0.0))
             for i in range(3)]
    assert drift(series(noisy)["drho_x"]).std_error > 10 * d.std_error


def orthocal(*argv: str, cwd: Path) -> Completed:
    return cli("history", *argv, cwd=cwd)


@pytest.fixture
def runs(tmp_path: Path) -> Path:
    out = tmp_path / "runs"
    out.mkdir()
    with HistoryStore(default_url(out)) as store:
        store.record(_entry("a", "OG-0007", 0, 0.400))
        store.record(_entry("b", "OG-0007", 40, 0.404))
        store.record(_entry("c", "OG-0042", 10, 0.1))
    return out


def test_the_figure_as_svg_and_png(runs: Path, tmp_path: Path) -> None:
    svg = tmp_path / "og7.svg"
    done = orthocal("--out", str(runs), "--machine", "OG-0007", "--plot", str(svg),
                    cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    root = ET.parse(svg).getroot()
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    text = " ".join(t for t in root.itertext())
    assert "OG-0007" in text and "OG-0042" not in text
    assert "µm/month" in text and "mrad/month" in text  # the drift, per panel
    assert "gaps between the axes" in text and "as found" in text and "as left" in text
    png = tmp_path / "og7.PNG"
    done = orthocal("--out", str(runs), "--machine", "OG-0007", "--plot", str(png),
                    cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert png.read_bytes()[:8] == PNG_SIGNATURE


def test_what_cannot_be_plotted_is_said_in_one_line(runs: Path, tmp_path: Path) -> None:
    with HistoryStore(default_url(runs)) as store:  # a row this version cannot read
        store.record({**_entry("d", "OG-BAD", 5, 0.1), "as_found": {"joint_error_mm": {
            "x": {"value_mm": None}}}})
    for argv, words in ((["--plot", "h.pdf"], "'.pdf'"),
                        (["--plot", "h.svg", "--machine", "OG-BAD"], "cannot be drawn"),
                        (["--plot", "history"], "(none)"),
                        (["--plot", "h.svg"], "3 machines (OG-0007, OG-0042, OG-BAD)"),
                        (["--plot", "h.svg", "--machine", "OG-9"], "no runs")):
        bad = orthocal("--out", str(runs), *argv, cwd=tmp_path)
        assert bad.returncode == 2 and words in bad.stderr, (argv, bad.stderr)
        assert len(bad.stderr.strip().splitlines()) == 1 and "Traceback" not in bad.stderr
        assert not (tmp_path / "h.svg").exists()


def _close(name: str, machine: str, seconds: float, x: float) -> dict[str, Any]:
    """A run ``seconds`` after the first of :func:`_entry`'s day 0 (a test rerun)."""
    entry = _entry(name, machine, 0, x)
    started = datetime.fromisoformat(entry["started"]) + timedelta(seconds=seconds)
    return {**entry, "started": started.isoformat(),
            "finished": (started + timedelta(seconds=30)).isoformat()}


def test_no_drift_from_runs_less_than_a_week_apart(tmp_path: Path) -> None:
    # two runs 35 s apart once gave +3.54e+04 ± 1.4e+05 µm/month
    close = [_close("a", "OG-5", 0, 0.400), _close("b", "OG-5", 35, 0.4014)]
    points = series(close)["drho_x"]
    assert drift(points) is None and why_no_drift(points) == "runs span less than 7 days"
    week = [_entry("a", "OG-5", 0, 0.400), _entry("b", "OG-5", MIN_SPAN_DAYS, 0.401)]
    assert drift(series(week)["drho_x"]) is not None  # a week: stated
    out = tmp_path / "runs"
    out.mkdir()
    with HistoryStore(default_url(out)) as store:
        for entry in close:
            store.record(entry)
    svg = tmp_path / "h.svg"
    done = orthocal("--out", str(out), "--machine", "OG-5", "--plot", str(svg), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "machine OG-5: drift of e per month ± 95 %: not stated, runs span less than " \
        "7 days" in done.stdout
    text = " ".join(ET.parse(svg).getroot().itertext())
    assert "e x: drift not stated, runs span less than 7 days" in text
    assert "/month (" not in text  # no slope drawn anywhere


def test_error_bars_are_the_statement_s_expanded_uncertainty() -> None:
    result = golden_result()
    stated = {q["name"]: q for q in result["statement"]}
    entry = {**entry_of(as_result(result)), "machine_id": "OG-1",
             "started": "2026-01-01T10:00:00+00:00", "finished": "2026-01-01T10:20:00+00:00"}
    points = series([entry])
    for state in ("as found", "as left"):  # one uncertainty for the joint, both states
        p = next(p for p in points["drho_x"] if p.state == state)
        key = f"drho_x.{state.replace(' ', '_')}"
        assert p.basis == "statement", state
        assert p.expanded_95 == pytest.approx(stated[key]["expanded"]), state
        # e = Δρ − o with the offsets Δρ was stated with
        assert p.value == pytest.approx(stated[key]["value"] - (
            result["offsets_before"]["x"] if state == "as found" else
            result["offsets_final"]["x"]))
        # not the scatter's (about 2 standard errors): the stated inputs' part is in it
        assert p.expanded_95 > 2.5 * p.std_error
    for name in ("tilt_yx", "gap_xy"):
        (p,) = points[name]
        assert p.basis == "statement"
        assert p.value == pytest.approx(stated[name]["value"])
        assert p.expanded_95 == pytest.approx(stated[name]["expanded"])


def test_a_run_from_before_the_statement_keeps_its_legacy_bars() -> None:
    result = {k: v for k, v in golden_result().items() if k not in ("statement", "advice")}
    budget = result["uncertainty_budget"]
    assert budget["statement"] == "remaining.total"
    entry = {**entry_of(as_result(result)), "machine_id": "OG-1",
             "started": "2026-01-01T10:00:00+00:00", "finished": "2026-01-01T10:20:00+00:00"}
    found = [p for p in series([entry])["drho_x"] if p.state == "as found"]
    assert found[0].basis == "certificate" and \
        found[0].expanded_95 == pytest.approx(budget["expanded_95_mm"]["drho_x"])
    left = [p for p in series([entry])["drho_x"] if p.state == "as left"]
    assert left[0].basis == "scatter"
    # a run whose budget states nothing: the scatter's interval, and said to be one
    bare = {**entry, "as_found": entry_of(as_result({**result, "uncertainty_budget": {
        "error": "not stated: a model without Δρ"}}))["as_found"]}
    fallback = next(p for p in series([bare])["drho_x"] if p.state == "as found")
    assert fallback.basis == "scatter" and fallback.expanded_95 < 0.002


def test_the_figure_labels_its_error_bars_and_says_what_e_is(tmp_path: Path) -> None:
    # a calibrated machine: e = −1818.6 µm is minus the offset it holds, Δρ is 0.4 µm
    held = {"x": 1.8190, "y": 0.0, "z": 0.0}
    first = _entry("a", "OG-6", 0, -1.8186, offsets_before=held)
    second = _entry("b", "OG-6", 10, -1.8185, offsets_before=held)
    for entry in (first, second):  # x's certificate stated, y's and z's not (older runs)
        entry["as_found"]["joint_error_mm"]["x"]["expanded_95_mm"] = 0.0119
    # a run that states the machine: its statement's U, as found and as left alike
    third = _entry("c", "OG-6", 20, -1.8184, offsets_before=held)
    for frame in (third["as_found"], third["as_left"]):
        for v in frame["joint_error_mm"].values():
            v.update(expanded_95_mm=0.0012, stated=True)
    out = tmp_path / "runs"
    out.mkdir()
    with HistoryStore(default_url(out)) as store:
        store.record(first)
        store.record(second)
        store.record(third)
    svg = tmp_path / "h.svg"
    done = orthocal("--out", str(out), "--machine", "OG-6", "--plot", str(svg), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    row = next(line for line in done.stdout.splitlines() if "/runs/a" in line)
    assert "+0.4, -300.0, +200.0" in row and "-1818.6, -300.0, +200.0" in row  # Δρ, e
    assert "Δρ as found: each joint's zero error at the run's start" in done.stdout
    assert "e = Δρ − o: the same error without any offset" in done.stdout
    text = " ".join(ET.parse(svg).getroot().itertext())
    assert "e x as found, ± U 95 % of the run's statement" in text
    assert "e x as left, ± U 95 % of the run's statement" in text
    assert "e x as found, ± U 95 % of its budget (a run from before the statement)" in text
    assert "e x as left, ± 95 % of its scatter alone (a run from before the statement)" \
        in text
    assert "e y as found, ± 95 % of its scatter alone (a run from before the statement)" \
        in text
    assert "statistical interval" not in text and "certificate" not in text
    assert "error bars 95 % expanded uncertainty" not in text  # what they were called
    assert "e = Δρ − o: each joint's zero error without the controller's offsets" in text
