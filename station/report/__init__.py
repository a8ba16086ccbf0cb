"""The run report: result.json, a self-contained report.html and the short summary.

The input is the run's record, station.record.result.RunResult: each public entry
point (summary_text, render_html, write_html, write_result, jsonable, not_converged)
also takes a mapping (a result.json of any version) and makes it the record once,
in boundary.as_result; everything behind reads the typed record. Its sections may
be absent (a run that failed halfway, no verification, write-back refused): a
section that is absent is not said, a figure that is not stated shows "—", and
nothing raises on a record that validated: a report that crashes on the failed run
is the one report the operator needed most.

Split by job: boundary.py (the record from what the caller hands in; result.json
is written by the record, station.record.io), format.py (names and formatting),
first_screen.py (the summary's and the page's first screen: verdict, joints, tool,
what to do), text.py (the text summary), tool.py (accuracy at the tool: the
headline's clause, the summary's lines, the page's section, where the stands were),
rounds.py (the closed loop's rounds), since.py (what changed since the machine's last
run), plots.py (figures), tables.py (the measurement's tables), html.py (the page).
The report reads the record only, never the engine.
"""

from __future__ import annotations

from station.record.io import jsonable_value
from station.report.boundary import ResultLike, as_result, jsonable, write_result
from station.report.format import (
    AXES,
    DEVIATION_KEYS,
    PARAM_NAMES,
    STATUS_TEXT,
    fmt,
    not_accepted,
    not_converged,
    param_plain,
)
from station.report.html import render_html, write_html
from station.report.text import mountings_line, summary_text

__all__ = [
    "AXES",
    "DEVIATION_KEYS",
    "PARAM_NAMES",
    "STATUS_TEXT",
    "ResultLike",
    "as_result",
    "fmt",
    "jsonable",
    "jsonable_value",
    "mountings_line",
    "not_accepted",
    "not_converged",
    "param_plain",
    "render_html",
    "summary_text",
    "write_html",
    "write_result",
]
