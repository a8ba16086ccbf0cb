"""A whole simulated calibration in this process, for the benches that judge its
result against the hidden machine."""

from __future__ import annotations

import contextlib
import io
import json
import os
import tempfile
from typing import Any

from station.commands import run as cmd_run
from station.commands.options import RunOptions


def run_json(options: RunOptions) -> tuple[int, dict[str, Any]]:
    """``orthocal run`` with ``options`` (``json=True``), its output kept off the
    terminal: (exit status, the result document)."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
        code = cmd_run.run(options)
    return code, json.loads(buf.getvalue())


def cli_json(argv: list[str], scale: str) -> dict[str, Any]:
    """``orthocal ARGV --yes --json --out TMP`` in this process, the virtual station
    ``scale`` times faster than real time (the readings at the stops, the counts and
    the journal do not depend on it), its output kept off the terminal: the result
    document."""
    os.environ.setdefault("ORTHOCAL_SIM_TIME_SCALE", scale)
    from station.commands.cli import main

    with tempfile.TemporaryDirectory(prefix="orthocal-bench-") as tmp:
        out = io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
            main([*argv, "--yes", "--json", "--out", tmp])
    result: dict[str, Any] = json.loads(out.getvalue())
    return result
