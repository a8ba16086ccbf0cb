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

from station.history.store import HistoryStore, default_url
from station.history.trend import MONTH_DAYS, drift, series

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
