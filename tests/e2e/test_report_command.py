"""``[report] figures`` and ``orthocal report RUN_DIR``: a run may write its report
without figures (the tests' runs do, builders.NO_FIGURES), and the report command
draws the whole report again from result.json; the run directory's config.toml,
which a resumed run reads, keeps the choice."""

from __future__ import annotations

import tomllib
from pathlib import Path

from builders import station_data

from station.config import StationConfig, parse_config
from station.config.toml import dump_toml


def _figures(page: str) -> int:
    return page.count("<svg")


def _run(orthocal, tmp_path: Path, figures: bool = False):
    return orthocal("run", "--simulate", "--seed", "5", "--noise", "0.001", "--yes", "--json",
                    "--sim-procedure", '{"cycles": 2, "readings": 3, "settle_s": 0}',
                    "--out", str(tmp_path / "runs"), figures=figures)


def test_a_run_without_figures_then_the_report_command_draws_them(orthocal, tmp_path: Path
                                                                   ) -> None:
    run = _run(orthocal, tmp_path)
    assert run.code in (0, 3), run.err
    page = (run.run_dir / "report.html").read_text(encoding="utf-8")
    assert _figures(page) == 0
    assert f"orthocal report {run.run_dir}" in page  # says how to draw them
    saved = tomllib.loads((run.run_dir / "config.toml").read_text(encoding="utf-8"))
    assert saved["report"] == {"figures": False}

    drawn = orthocal("report", str(run.run_dir))
    assert drawn.code == 0, drawn.err
    assert drawn.out.strip() == str(run.run_dir / "report.html")
    page = (run.run_dir / "report.html").read_text(encoding="utf-8")
    # the error field at the tool, the deviations, the parameters, the loop's rounds
    assert _figures(page) >= 3 and "Figure 1." in page
    assert "orthocal report" not in page

    again = orthocal("report", str(run.run_dir), "--no-figures")
    assert again.code == 0
    assert _figures((run.run_dir / "report.html").read_text(encoding="utf-8")) == 0


def test_a_run_with_figures_draws_them(orthocal, tmp_path: Path) -> None:
    run = _run(orthocal, tmp_path, figures=True)
    assert run.code in (0, 3), run.err
    assert _figures((run.run_dir / "report.html").read_text(encoding="utf-8")) >= 3


def test_the_report_of_a_directory_without_a_result_is_bad_input(orthocal, tmp_path: Path
                                                                  ) -> None:
    out = orthocal("report", str(tmp_path))
    assert out.code == 2
    (line,) = out.err.strip().splitlines()
    assert "result.json" in line and "cannot read" in line


def test_report_figures_is_a_boolean_named_in_one_line() -> None:
    import pytest

    from station.errors import BadInput

    with pytest.raises(BadInput, match=r"^config: report\.figures: "):
        parse_config(station_data(report={"figures": "sometimes"}))


def test_the_saved_config_keeps_history_and_report() -> None:
    config = parse_config(station_data(report={"figures": False},
                                       history={"enabled": False, "url": "sqlite:///h.db"}))
    again = StationConfig.model_validate(tomllib.loads(dump_toml(config)))
    assert again == config
    assert again.report.figures is False and again.history.enabled is False
