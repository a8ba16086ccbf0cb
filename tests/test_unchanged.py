"""Behaviour unchanged by the restructure of the house (issue 16): a seeded
simulated run (noise 0, so every reading is deterministic) gives the same
result.json, the same journal and the same report.html as the code gave before
station/ moved into its rooms (tests/data/golden_run/, made by that code).

Only what cannot repeat is taken out before comparing: times, the run
directory, the virtual station's ephemeral ports and pty paths, the wall time,
what the plunger guard's polls saw while the axes moved (how many polls fit
into a move depends on the machine's load), and the names matplotlib gives the
markers and clip paths of its figures."""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path
from typing import Any

import pytest
from builders import FAST, simulated

from station.commands import run as cmd_run

GOLDEN = Path(__file__).parent / "data" / "golden_run"
# Records and fields that depend on time or on the machine's load.
VOLATILE_RESULT = ("run_dir", "started", "finished", "duration_s")
VOLATILE_GUARD = ("polls", "min_slack_mm", "predicted_mm")


def normal_result(result: dict[str, Any]) -> dict[str, Any]:
    out = {k: v for k, v in result.items() if k not in VOLATILE_RESULT}
    out["timing"] = {k: v for k, v in result.get("timing", {}).items() if k != "wall_s"}
    return out


def normal_config(config: dict[str, Any]) -> dict[str, Any]:
    config = json.loads(json.dumps(config))
    config["controller"].pop("port", None)
    for ind in config["indicators"]:
        ind.pop("port", None)
    return config


def normal_journal(text: str) -> list[dict[str, Any]]:
    out = []
    for line in text.splitlines():
        record = json.loads(line)
        record.pop("t", None)
        if record["type"] == "header":
            for key in ("started", "version", "argv"):
                record.pop(key, None)
            record["config"] = normal_config(record["config"])
        if record["type"] == "event" and record["event"].get("event") == \
                "plunger-guard-learned":
            record["event"] = {k: v for k, v in record["event"].items()
                               if k not in VOLATILE_GUARD}
        out.append(record)
    return out


def normal_html(page: str, run_dir: str) -> str:
    page = page.replace(run_dir, "RUN_DIR")
    page = re.sub(r"\d{4}-\d\d-\d\d[ T]\d\d:\d\d(:\d\d)?([+-]\d\d:?\d\d)?", "WHEN", page)
    page = re.sub(r"\d{1,2} \w{3} \d{4},? \d\d:\d\d(:\d\d)?", "WHEN", page)
    page = re.sub(r"wall [^,<]*,", "wall WALL,", page)
    page = re.sub(r"(duration</dt><dd>)[^<]*", r"\1DURATION", page)
    # matplotlib names an SVG's markers and clip paths after object ids
    page = re.sub(r"\b([mp])[0-9a-f]{10}\b", r"\1ID", page)
    return page


def seeded_run(out: Path) -> Path:
    options = simulated(out, seed=21, true_drho=(1.1, -0.7, 0.4), noise=0.0, procedure=FAST)
    with contextlib.redirect_stdout(io.StringIO()):
        assert cmd_run.run(options) == 0
    (run_dir,) = list(out.iterdir())
    return run_dir


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return seeded_run(tmp_path_factory.mktemp("seeded"))


def test_the_result_document_is_unchanged(run_dir: Path) -> None:
    now = normal_result(json.loads((run_dir / "result.json").read_text()))
    before = json.loads((GOLDEN / "result.json").read_text())
    assert now == before


def test_the_journal_is_unchanged(run_dir: Path) -> None:
    now = normal_journal((run_dir / "journal.jsonl").read_text())
    before = [json.loads(line) for line in (GOLDEN / "journal.jsonl").read_text().splitlines()]
    assert [r["type"] for r in now] == [r["type"] for r in before]
    for a, b in zip(now, before, strict=True):
        assert a == b, (a["type"], a, b)


def test_the_report_is_unchanged(run_dir: Path) -> None:
    now = normal_html((run_dir / "report.html").read_text(), str(run_dir))
    assert now == (GOLDEN / "report.html").read_text()


def test_the_plan_is_unchanged(run_dir: Path) -> None:
    assert (run_dir / "plan.txt").read_text() == (GOLDEN / "plan.txt").read_text()
