"""A run's "Since the last calibration" (station.history.compare.since_last and the
report's section): which earlier run it is compared with, when there is none, and
that what the history cannot say never fails the run."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from builders import simulated
from result_builders import make_result
from test_history import TRUE, _with

from station import report
from station.commands import run as cmd_run
from station.history.compare import since_last
from station.history.store import HistoryStore, default_url


def _entry(name: str, started: str, x: float = 0.4, machine: str | None = "OG-1",
           **extra: Any) -> dict[str, Any]:
    frame = {"joint_error_mm": {a: {"value_mm": v, "std_error_mm": 0.0005}
                                for a, v in zip("xyz", (x, -0.3, 0.2), strict=True)},
             "dof": 30.0}
    return {"run_dir": f"/runs/{name}", "machine_id": machine, "started": started,
            "geometry": {"leg_length": 310.25}, "profile": "orthocal-generic",
            "as_found": frame, "as_left": frame, "layout": {}, **extra}


def test_the_last_earlier_run_of_the_machine_is_the_one_compared() -> None:
    now = _entry("now", "2026-03-01T10:00:00+01:00", x=0.41)
    earlier = [_entry("jan", "2026-01-01T10:00:00+00:00", x=0.0),
               _entry("feb", "2026-02-01T10:00:00+00:00"),
               _entry("other", "2026-02-15T10:00:00+00:00", machine="OG-2"),
               _entry("later", "2026-03-01T09:30:00+00:00"),  # after it, in UTC
               _entry("now", "2026-03-01T10:00:00+01:00")]  # its own row (a resume)
    since = since_last(earlier, now)
    assert since is not None and since["previous_run"] == "/runs/feb"
    x = since["joint_error_mm"]["x"]
    assert abs(x["change"] - 0.01) < 1e-12 and x["significant"]
    assert not since["joint_error_mm"]["y"]["significant"]
    assert since_last(earlier[:1], _entry("anon", "2026-03-01T10:00:00+00:00",
                                          machine=None)) is None
    assert since_last([], now) is None
    assert since_last(earlier[4:], now) is None  # only its own earlier row
    moved = since_last(earlier[:2], {**now, "geometry": {"leg_length": 300.0}})
    assert moved is not None and "different geometry" in moved["not_compared"]
    compared = {**make_result(), "since_last": moved}  # a run's record with it
    text = report.summary_text(compared)
    assert "not compared with /runs/feb: different geometry" in text
    assert "Not compared" in report.render_html(compared)


def test_an_earlier_entry_it_cannot_read_never_fails_the_run(tmp_path: Path,
                                                              capsys) -> None:
    out = tmp_path / "runs"

    def one_run() -> tuple[int, dict[str, Any], str]:
        code = cmd_run.run(simulated(out, seed=4, noise=0.001, true_drho=TRUE,
                                     mount_error=0.0, hook=_with("OG-1")))
        captured = capsys.readouterr()
        return code, json.loads(captured.out), captured.err

    one_run()
    with HistoryStore(default_url(out)) as store:  # its row, as this version cannot read
        (row,) = store.entries("OG-1")
        store.record({**row, "as_left": {"joint_error_mm": {"x": "unreadable"}}})
    code, result, said = one_run()
    assert code in (0, 3) and result["status"] == "ok"
    assert "not compared with the machine's last run" in said
    assert "since_last" not in result
    with HistoryStore(default_url(out)) as store:  # and the run is in the history
        assert result["run_dir"] in [e["run_dir"] for e in store.entries("OG-1")]
