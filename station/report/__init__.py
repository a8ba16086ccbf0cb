"""The run report: result.json, a self-contained report.html and the short summary.

The input is the run's result document (station.engine.results). Every section may
be missing (a run that failed halfway, no verification, write-back refused), so
everything reads with ``.get`` and shows "—" rather than raising: a report
that crashes on the failed run is the one report the operator needed most.

Split by job: io.py (result.json), format.py (names and formatting), text.py (the
text summary), tool.py (accuracy at the tool: the headline's clause, the summary's
lines, the page's section, where the stands were), rounds.py (the closed loop's
rounds), since.py (what changed since the machine's last run), plots.py (figures),
html.py (the page). The report reads the result document only, never the engine.
"""

from __future__ import annotations

from station.report.format import (
    AXES,
    DEVIATION_KEYS,
    PARAM_NAMES,
    STATUS_TEXT,
    fmt,
    not_converged,
    param_plain,
)
from station.report.html import render_html, write_html
from station.report.io import jsonable, jsonable_value, write_result
from station.report.text import mountings_line, summary_text

__all__ = [
    "AXES",
    "DEVIATION_KEYS",
    "PARAM_NAMES",
    "STATUS_TEXT",
    "fmt",
    "jsonable",
    "jsonable_value",
    "mountings_line",
    "not_converged",
    "param_plain",
    "render_html",
    "summary_text",
    "write_html",
    "write_result",
]
