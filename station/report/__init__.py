"""The run report: result.json, a self-contained report.html and the short summary.

The input is the result dict of /work/briefs/result_schema.md. Every section may
be missing (a run that failed halfway, no verification, write-back refused), so
everything reads with ``.get`` and shows "—" rather than raising: a report
that crashes on the failed run is the one report the operator needed most.

Split by job: station/report_io.py (result.json), report_text.py (names,
formatting, the text summary), report_plots.py (figures), report_html.py (the page).
"""

from __future__ import annotations

import html  # the module offered html.escape as report.html; kept for callers

from station.report_html import render_html, write_html
from station.report_io import _jsonable, jsonable, write_result
from station.report_text import (
    _STATUS_TEXT,
    AXES,
    DEVIATION_KEYS,
    PARAM_NAMES,
    _fmt,
    _param_plain,
    summary_text,
)

__all__ = [
    "AXES",
    "DEVIATION_KEYS",
    "PARAM_NAMES",
    "_STATUS_TEXT",
    "_fmt",
    "_jsonable",
    "_param_plain",
    "html",
    "jsonable",
    "render_html",
    "summary_text",
    "write_html",
    "write_result",
]
