"""A rollback as an event of the run (docs/design.md, "Command line", ``orthocal
rollback``): once the backed-up offsets are restored, the run's own record says so,
so that result.json, report.html, the history and ``resume`` never show offsets the
controller no longer holds as the run's outcome. Each rollback is kept (the journal's
``rollback`` records, result.json's ``rollbacks``), none overwrites the one before;
a rollback with nothing to undo is refused."""

from __future__ import annotations

from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path

from orthocal import AXES
from station import report
from station.engine.run_record import rolled_back
from station.errors import say
from station.record import io
from station.record.result import RolledBack, RunResult
from station.record.state import RunState


def change_text(before: Mapping[str, float], after: Mapping[str, float]) -> str:
    """Per joint, the offset now → the one it becomes ("x +1.8170 → +0.0000, …
    mm"): what a rollback is about to do, said before it is done."""
    return ", ".join(f"{a} {before[a]:+.4f} → {after[a]:+.4f}" for a in AXES) + " mm"


def when_rolled_back(state: RunState) -> str | None:
    """When the run was last rolled back (ISO 8601, as result.json's ``at``), from its
    journal; None where it never was."""
    if not state.rollbacks:
        return None
    return datetime.fromtimestamp(state.rollbacks[-1].t, UTC).astimezone().isoformat(
        timespec="seconds")


def nothing_to_undo(run_dir: Path, state: RunState, current: Mapping[str, float],
                    backup: Mapping[str, float], resolution_mm: float) -> str | None:
    """Why a rollback of ``run_dir`` is refused (one line), or None: the controller
    already holds the backed-up offsets (to half a count of the drive's offsets), so
    writing them again would undo nothing and would record a rollback that did nothing
    over the one that did."""
    tolerance = max(resolution_mm / 2.0, 1e-9)
    if any(abs(current[a] - backup[a]) > tolerance for a in AXES):
        return None
    held = ", ".join(f"{a} {backup[a]:+.4f}" for a in AXES) + " mm"
    when = when_rolled_back(state)
    if when is not None:
        return (f"{run_dir} was already rolled back on {when}: the controller holds the "
                f"offsets saved before its write-back ({held}), nothing to undo")
    return (f"{run_dir}: the controller already holds the offsets saved before its "
            f"write-back ({held}): nothing to undo")


def record_rollback(run_dir: Path, replaced: Mapping[str, float],
                    restored: Mapping[str, float], at: str, figures: bool = True
                    ) -> RunResult | None:
    """The run's result.json and report.html after a rollback: the rollback appended
    to ``rollbacks`` (``at``: when, as the journal's record of it says, so that a
    later refusal names the same second; the offsets replaced, those restored),
    ``rolled_back`` this one, and ``offsets_final`` the restored offsets. The updated
    record, or None where the run has none (it stopped before its end: the journal's
    rollback records are then what resume reads). A record that cannot be read or
    written is said in one line; the offsets stay restored."""
    path = Path(run_dir) / "result.json"
    if not path.exists():
        return None
    try:
        record = io.read_result(path)
    except io.UnreadableResult as exc:  # torn, edited, or of a later version
        say(f"orthocal: the rollback is not recorded in result.json: {exc}")
        return None
    back = RolledBack(at=at, replaced=dict(replaced), restored=dict(restored))
    record = rolled_back(record, back)
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
