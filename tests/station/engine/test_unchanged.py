"""Behaviour unchanged unless changed on purpose: a seeded simulated run (noise 0,
so every reading is deterministic) gives the same result.json, journal, report.html
and plan.txt as the golden files in tests/data/golden_run/. Those are that same run's
files with what cannot repeat taken out (below), written by ``python
tests/helpers/make_golden.py`` with this module's :func:`seeded_run` and normalisations, and
by nothing else: they are made again only when a change of the result, the journal,
the report or the plan is intended, and the diff of the files is the review of it.

"The same" on any machine: floats within close.py's tolerance (relative 1e-6,
absolute 1e-7, far below any figure printed, far above what another CPU's SIMD
path or BLAS kernel changes), printed numbers within a unit of their last digit,
everything else exactly. The run is also made once with numpy's CPU dispatch
narrowed to its baseline and OpenBLAS on another kernel family, in a process of its
own, and compared with the same files: a user's clone on another CPU.

Only what cannot repeat is taken out before comparing: times, the run
directory, the virtual station's ephemeral ports and pty paths, the wall time
and the operator's time at each mounting,
what the plunger guard's polls saw while the axes moved (how many polls fit
into a move depends on the machine's load), and the names matplotlib gives the
markers and clip paths of its figures."""

from __future__ import annotations

import contextlib
import io
import json
import os
import platform
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from builders import FAST, simulated
from close import assert_same, assert_same_text

from station.commands import run as cmd_run

GOLDEN = Path(__file__).parents[2] / "data" / "golden_run"
# Records and fields that depend on time or on the machine's load.
VOLATILE_RESULT = ("run_dir", "started", "finished", "duration_s")
VOLATILE_GUARD = ("polls", "min_slack_mm", "predicted_mm")


def normal_result(result: dict[str, Any]) -> dict[str, Any]:
    out = {k: v for k, v in result.items() if k not in VOLATILE_RESULT}
    out["timing"] = {k: v for k, v in result.get("timing", {}).items()
                     if k not in ("wall_s", "operator_s")}
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
        if record["type"] == "setup":
            record.pop("operator_s", None)  # the (virtual) operator's time
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
    page = re.sub(r", in [^(<]* \(its last session\)", ", in WALL (its last session)", page)
    page = re.sub(r"\d[\d.]*( min \d+)? s at the machine", "OPERATOR at the machine", page)
    page = re.sub(r"the whole run [^<]*", "the whole run WALL", page)
    page = re.sub(r"(duration</dt><dd>)[^<]*", r"\1DURATION", page)
    # matplotlib names an SVG's markers and clip paths after object ids
    page = re.sub(r"\b([mp])[0-9a-f]{10}\b", r"\1ID", page)
    # a figure's coordinates to a thousandth of a point: an axis autoscaled to a fit
    # near zero (the tilts of a square machine) turns another CPU's last bits of the
    # fit into 1e-5 of a point, which no one sees; the comparison then allows one
    # unit of the last digit, as for every printed number
    return _SVG.sub(lambda svg: _FINE.sub(lambda n: f"{float(n.group(0)):.3f}",
                                          svg.group(0)), page)


_SVG = re.compile(r"<svg\b.*?</svg>", re.S)
_FINE = re.compile(r"-?\d+\.\d{4,}")


def seeded_run(out: Path) -> Path:
    options = simulated(out, seed=21, true_drho=(1.1, -0.7, 0.4), noise=0.0, procedure=FAST,
                        figures=True)
    with contextlib.redirect_stdout(io.StringIO()):
        assert cmd_run.run(options) == 0
    (run_dir,) = list(out.glob("run-*"))
    return run_dir


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return seeded_run(tmp_path_factory.mktemp("seeded"))


def assert_result_unchanged(run_dir: Path) -> None:
    now = normal_result(json.loads((run_dir / "result.json").read_text()))
    before = json.loads((GOLDEN / "result.json").read_text())
    assert_same(now, before, "result.json")


def assert_journal_unchanged(run_dir: Path) -> None:
    now = normal_journal((run_dir / "journal.jsonl").read_text())
    before = [json.loads(line) for line in (GOLDEN / "journal.jsonl").read_text().splitlines()]
    assert [r["type"] for r in now] == [r["type"] for r in before]
    for i, (a, b) in enumerate(zip(now, before, strict=True)):
        assert_same(a, b, f"journal record {i} ({a['type']})")


def test_the_result_document_is_unchanged(run_dir: Path) -> None:
    assert_result_unchanged(run_dir)


def test_the_journal_is_unchanged(run_dir: Path) -> None:
    assert_journal_unchanged(run_dir)


def test_the_report_is_unchanged(run_dir: Path) -> None:
    now = normal_html((run_dir / "report.html").read_text(), str(run_dir))
    assert_same_text(now, (GOLDEN / "report.html").read_text(), "report.html")


def test_the_plan_is_unchanged(run_dir: Path) -> None:
    assert_same_text((run_dir / "plan.txt").read_text(), (GOLDEN / "plan.txt").read_text(),
                     "plan.txt")


#: OpenBLAS kernels another CPU would take (OPENBLAS_CORETYPE): on x86-64 the SSE4.2
#: family that every x86-64-v2 CPU runs; on 64-bit ARM the plain ARMv8 one.
OTHER_BLAS_CORE = {"x86_64": "Nehalem", "AMD64": "Nehalem", "aarch64": "ARMV8",
                   "arm64": "ARMV8"}

_NARROWED_RUN = """
import json, sys
from pathlib import Path
from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
sys.path.insert(0, sys.argv[1])
sys.path.insert(0, str(Path(sys.argv[1]).parents[1] / "helpers"))
from test_unchanged import seeded_run
print(json.dumps({"dispatch_on": [f for f in __cpu_dispatch__ if __cpu_features__.get(f)],
                  "run_dir": str(seeded_run(Path(sys.argv[2])))}))
"""


def test_the_run_is_unchanged_on_a_narrower_numerical_path(tmp_path: Path) -> None:
    """The same seeded run with numpy's SIMD dispatch cut to its baseline and OpenBLAS
    on another kernel family (another summation order, no FMA): within the tolerance
    of the golden files, as on a user's clone on another CPU."""
    from numpy._core._multiarray_umath import __cpu_dispatch__

    env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": " ".join(__cpu_dispatch__)}
    core = OTHER_BLAS_CORE.get(platform.machine())
    if core is not None:
        env["OPENBLAS_CORETYPE"] = core
    proc = subprocess.run(
        [sys.executable, "-c", _NARROWED_RUN, str(Path(__file__).parent), str(tmp_path)],
        env=env, capture_output=True, text=True, timeout=110)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["dispatch_on"] == []  # numpy took its baseline path only
    run_dir = Path(out["run_dir"])
    assert_result_unchanged(run_dir)
    assert_journal_unchanged(run_dir)
    assert_same_text(normal_html((run_dir / "report.html").read_text(), str(run_dir)),
                     (GOLDEN / "report.html").read_text(), "report.html")
