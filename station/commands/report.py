"""``orthocal report RUN_DIR``: draw a run's report.html again from its result.json,
with its figures (docs/design.md, "Command line"): after a run whose config said
``[report] figures = false``, or after an upgrade of orthocal."""

from __future__ import annotations

import argparse

from pydantic import ValidationError

from station.commands.history import read_result
from station.errors import BadInput, RunFailed


def main(args: argparse.Namespace) -> int:
    from station import report

    path, doc = read_result(args.run_dir)
    try:
        result = report.as_result(doc)
    except ValidationError as exc:  # edited by hand, or another version's
        raise BadInput(f"{path}: not a result document ({_first(exc)})") from None
    try:
        written = report.write_html(result, path.parent, figures=not args.no_figures)
    except OSError as exc:
        raise RunFailed(f"{path.parent / 'report.html'}: not written ({exc.strerror})") from None
    print(written)
    return 0


def _first(exc: ValidationError) -> str:
    """The first of the record's complaints, in one line ("timing.wall_s: Field
    required, and 2 more")."""
    errors = exc.errors()
    first = errors[0]
    where = ".".join(str(p) for p in first["loc"])
    more = f", and {len(errors) - 1} more" if len(errors) > 1 else ""
    return f"{where}: {first['msg']}{more}"
