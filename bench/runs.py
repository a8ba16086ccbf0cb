"""A whole simulated calibration in this process, for the benches that judge its
result against the hidden machine."""

from __future__ import annotations

import contextlib
import io
import json
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
