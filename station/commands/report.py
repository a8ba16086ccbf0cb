"""``orthocal report RUN_DIR``: draw a run's report.html again from its result.json,
with its figures (docs/design.md, "Command line"): after a run whose config said
``[report] figures = false``, or after an upgrade of orthocal."""

from __future__ import annotations

import argparse

from station.commands.history import read_result
from station.errors import RunFailed


def main(args: argparse.Namespace) -> int:
    from station import report

    path, result = read_result(args.run_dir)
    try:
        written = report.write_html(result, path.parent, figures=not args.no_figures)
    except OSError as exc:
        raise RunFailed(f"{path.parent / 'report.html'}: not written ({exc.strerror})") from None
    print(written)
    return 0
