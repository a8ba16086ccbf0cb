"""A rollback as a state of the run (docs/design.md, "Command line", ``orthocal
rollback``): once the backed-up offsets are restored, the run's own record says so,
so that result.json, report.html, the history and ``resume`` never show offsets the
controller no longer holds as the run's outcome."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from orthocal import AXES
from station import report
from station.errors import say
from station.record import io
from station.record.result import RolledBack, RunResult
from station.record.run_dir import now_iso


def change_text(before: Mapping[str, float], after: Mapping[str, float]) -> str:
    """Per joint, the offset now → the one it becomes ("x +1.8170 → +0.0000, …
    mm"): what a rollback is about to do, said before it is done."""
    return ", ".join(f"{a} {before[a]:+.4f} → {after[a]:+.4f}" for a in AXES) + " mm"


def record_rollback(run_dir: Path, replaced: Mapping[str, float],
                    restored: Mapping[str, float], figures: bool = True
                    ) -> RunResult | None:
    """The run's result.json and report.html after a rollback: ``rolled_back`` (when,
    the offsets replaced, those restored) and ``offsets_final`` the restored ones.
    The updated record, or None where the run has none (it stopped before its end:
    the journal's rollback record is then what resume reads). A record that cannot
    be read or written is said in one line; the offsets stay restored."""
    path = Path(run_dir) / "result.json"
    if not path.exists():
        return None
    try:
        record = io.read_result(path)
    except io.UnreadableResult as exc:  # torn, edited, or of a later version
        say(f"orthocal: the rollback is not recorded in result.json: {exc}")
        return None
    record.rolled_back = RolledBack(at=now_iso(), replaced=dict(replaced),
                                    restored=dict(restored))
    record.offsets_final = dict(restored)
    # validated once for the report, the history and the caller (write_result still
    # validates what it writes)
    record = io.validated(record)
    try:
        io.write_result(record, run_dir)
    except OSError as exc:
        say(f"orthocal: {path} does not record the rollback ({exc.strerror})")
        return None
    try:
        report.write_html(record, run_dir, figures=figures)
    except OSError as exc:
        say(f"orthocal: {Path(run_dir) / 'report.html'} not redrawn ({exc.strerror}); "
            f"orthocal report {run_dir} draws it from result.json")
    return record
