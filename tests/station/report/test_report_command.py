"""``[report] figures`` and ``orthocal report RUN_DIR``: a run may write its report
without figures (the tests' runs do, builders.NO_FIGURES), and the report command
draws the whole report again from result.json; the run directory's config.toml,
which a resumed run reads, keeps the choice. The command never replaces a file
without saying so: ``--out FILE`` refuses an existing FILE unless ``--force``, and
``--no-figures`` refuses to drop a report's figures unless ``--force``."""

from __future__ import annotations

import json
import shutil
import tomllib
from pathlib import Path

from builders import cli, station_data
from result_builders import GOLDEN, golden_result

from station.config import StationConfig, parse_config
from station.config.toml import dump_toml
from station.report.mounting_files import without_pictures


def _figures(page: str) -> int:
    """The report's figures: its SVGs less the mounting pictures, drawn with or
    without figures (docs/design.md, "Mounting pictures")."""
    return without_pictures(page).count("<svg")


def _run(orthocal, tmp_path: Path, *more: str, figures: bool = False):
    return orthocal("run", "--simulate", "--seed", "5", "--noise", "0.001", "--yes", "--json",
                    "--sim-procedure", '{"cycles": 2, "readings": 3, "settle_s": 0}',
                    "--out", str(tmp_path / "runs"), *more, figures=figures)


def test_a_run_without_figures_then_the_report_command_draws_them(orthocal, tmp_path: Path
                                                                   ) -> None:
    run = _run(orthocal, tmp_path)
    assert run.code in (0, 3), run.err
    page = (run.run_dir / "report.html").read_text(encoding="utf-8")
    assert _figures(page) == 0
    assert page.count('<figure class="mounting">') == 3  # the mountings, all the same
    assert f"orthocal report {run.run_dir}" in page  # says how to draw them
    saved = tomllib.loads((run.run_dir / "config.toml").read_text(encoding="utf-8"))
    assert saved["report"] == {"figures": False}

    drawn = orthocal("report", str(run.run_dir))
    assert drawn.code == 0, drawn.err
    # the run's own report, redrawn: the command's purpose, and it says so
    assert drawn.out.strip() == f"replaced {run.run_dir / 'report.html'}"
    page = (run.run_dir / "report.html").read_text(encoding="utf-8")
    # the error field at the tool, the deviations, the parameters, the loop's rounds
    assert _figures(page) >= 3 and "Figure 1." in page
    assert page.count('<figure class="mounting">') == 3
    assert "orthocal report" not in page

    # without its figures over the report with them: refused, the report kept
    refused = orthocal("report", str(run.run_dir), "--no-figures")
    assert refused.code == 2 and refused.out == ""
    (line,) = refused.err.strip().splitlines()
    assert "--no-figures" in line and "--force" in line and "--out" in line
    assert (run.run_dir / "report.html").read_text(encoding="utf-8") == page
    forced = orthocal("report", str(run.run_dir), "--no-figures", "--force")
    assert forced.code == 0 and forced.out.strip().startswith("replaced ")
    assert _figures((run.run_dir / "report.html").read_text(encoding="utf-8")) == 0


def _golden_run(tmp_path: Path) -> Path:
    """A copy of the golden run directory, its result.json with its times put back."""
    run = tmp_path / "golden"
    shutil.copytree(GOLDEN, run)
    (run / "result.json").write_text(json.dumps(golden_result()), encoding="utf-8")
    return run


def test_report_out_writes_a_new_file_and_never_replaces_one_unasked(tmp_path: Path) -> None:
    run = _golden_run(tmp_path)
    own = (run / "report.html").read_text(encoding="utf-8")
    out = tmp_path / "certificate.html"
    done = cli("report", str(run), "--out", str(out), "--no-figures", cwd=tmp_path)
    assert done.returncode == 0, done.err
    assert done.stdout.strip() == str(out)  # a new file: its name, nothing replaced
    first = out.read_text(encoding="utf-8")
    assert "as found → as left" in first and _figures(first) == 0
    assert (run / "report.html").read_text(encoding="utf-8") == own  # the run's untouched

    again = cli("report", str(run), "--out", str(out), cwd=tmp_path)
    assert again.returncode == 2 and again.stdout == ""
    (line,) = again.stderr.strip().splitlines()
    assert str(out) in line and "exists" in line and "--force" in line
    assert out.read_text(encoding="utf-8") == first

    forced = cli("report", str(run), "--out", str(out), "--force", cwd=tmp_path)
    assert forced.returncode == 0, forced.err
    assert forced.stdout.strip() == f"replaced {out}"
    assert _figures(out.read_text(encoding="utf-8")) >= 3


def test_report_out_into_a_missing_folder_is_one_line(tmp_path: Path) -> None:
    run = _golden_run(tmp_path)
    done = cli("report", str(run), "--out", str(tmp_path / "nowhere" / "r.html"),
               cwd=tmp_path)
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()
    assert "--out" in line and "nowhere" in line


def test_a_run_with_figures_draws_them_and_records_its_operator(orthocal, tmp_path: Path
                                                                   ) -> None:
    run = _run(orthocal, tmp_path, "--operator", "J. Smith", figures=True)
    assert run.code in (0, 3), run.err
    page = (run.run_dir / "report.html").read_text(encoding="utf-8")
    assert _figures(page) >= 3
    result = json.loads((run.run_dir / "result.json").read_text(encoding="utf-8"))
    assert result["operator"] == "J. Smith"
    assert [g["name"] for g in result["gauges"]] == ["A", "B"]
    header = json.loads((run.run_dir / "journal.jsonl").read_text(
        encoding="utf-8").splitlines()[0])
    assert header["config"]["station"]["operator"] == "J. Smith"
    # in the header's list, ahead of the run's story, and on the certificate
    assert page.index("<dt>operator</dt><dd>J. Smith</dd>") < page.index("What was done")
    assert "<th>operator</th><td>J. Smith</td>" in page


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
