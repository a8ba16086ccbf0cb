"""``orthocal report RUN_DIR``: draw a run's report.html again from its result.json,
with its figures (docs/design.md, "Command line"): after a run whose config said
``[report] figures = false``, or after an upgrade of orthocal.

It never replaces a file without saying so: ``--out FILE`` refuses a FILE that
exists (one line, exit 2) unless ``--force``; the run's own report.html, which is
what the command redraws, is replaced with "replaced FILE" on stdout, except that
``--no-figures`` refuses to replace a report that has its figures (they would be
lost) unless ``--force``."""

from __future__ import annotations

import argparse
from pathlib import Path

from drivers.files import write_atomic
from station.commands.given_paths import file_to_write
from station.commands.history import read_result
from station.errors import BadInput, why_not


def main(args: argparse.Namespace) -> int:
    from station import report
    from station.report.mounting_files import pictures_in

    path, result = read_result(args.run_dir)  # validated, or one line naming the file
    figures = not args.no_figures
    target = _target(args, path.parent, figures)
    existed = target.exists()
    try:
        write_atomic(target, report.render_html(result, figures, pictures_in(path.parent)))
    except OSError as exc:  # a path the user named (RUN_DIR, --out): bad input, exit 2
        raise BadInput(f"{target}: not written: {why_not(exc)}") from None
    print(f"replaced {target}" if existed else target)
    return 0


def _target(args: argparse.Namespace, run_dir: Path, figures: bool) -> Path:
    """Where the report goes, or BadInput (one line) where writing there would
    replace a file unasked: ``--out`` over any file, ``--no-figures`` over the run's
    report with figures."""
    force = bool(getattr(args, "force", False))
    out = getattr(args, "out", None)
    if out is not None:
        target = Path(out)
        if target.is_dir():
            raise BadInput(f"--out {target}: a folder; give the report's file name")
        if not target.parent.is_dir():
            raise BadInput(f"--out {target}: no folder {target.parent}")
        if target.exists() and not force:
            raise BadInput(f"--out {target}: the file exists; give --force to replace it")
        # a device or a pipe is never replaced, --force or not; a folder that takes no
        # file is said now, before the report is drawn
        file_to_write("--out", target, replace=True)
        return target
    target = run_dir / "report.html"
    if not figures and not force and _has_figures(target):
        raise BadInput(f"{target} has its figures and --no-figures would drop them: give "
                       "--out FILE for a copy without them, or --force to replace it")
    return target


def _has_figures(page: Path) -> bool:
    try:
        text = page.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return False  # none to lose
    # the mounting pictures are drawn with or without figures: not figures to lose
    from station.report.mounting_files import without_pictures

    return "<svg" in without_pictures(text)
