"""Writing the identified offsets back to the controller (docs/design.md, "Write-back").

Order, each step journaled before the next: back up the controller's offsets
to the run directory (fsynced) → refuse any |Δρ_i| > max_abs_offset_mm (nothing
written) → ask the operator → journal the intent → write o_i ← o_i − Δρ_i and
read back → journal done. If a write or its read-back fails, the backup is
written back and the outcome says so. Writes are absolute values computed from
the backup, so redoing an interrupted write-back after a resume is harmless and
never applies Δρ twice.

Closed loop: write-back round k > 1 (records carry ``"round": k``) journals the
offsets it starts from as its own ``backup`` stage but leaves offsets_backup.json
alone, so rollback always restores the offsets from before the first round; it
also refuses a total correction (from ``offsets_at_start``, the offsets before
the run) beyond max_abs_offset_mm.

Resume: a round, and its backup and intent stages, are steps of
station.engine.replay; each one the journal holds is not taken again, its record
stands for it (a round whose final stage is journaled gives the outcome it gave).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.base import ZeroOffsets
from drivers.device_errors import DeviceError
from drivers.files import write_atomic
from orthocal import AXES
from station.console.operator import Operator
from station.engine.replay import Steps, WritebackRound, WritebackStage
from station.errors import RunFailed
from station.record.journal import (
    WritebackBackup,
    WritebackDone,
    WritebackFailed,
    WritebackIntent,
    WritebackRecord,
    WritebackSkipped,
    WritebackUnchanged,
)
from station.record.journal_file import Journal

BACKUP_NAME = "offsets_backup.json"


@dataclass
class WritebackOutcome:
    status: str  # written | refused | declined | skipped | failed-restored
    reason: str | None
    before: dict[str, float] | None
    written: dict[str, float] | None


def _axes(values: Iterable[float]) -> dict[str, float]:
    return {a: float(v) for a, v in zip(AXES, values, strict=True)}


def save_backup(run_dir: Path, offsets: dict[str, float], controller_name: str) -> Path:
    path = run_dir / BACKUP_NAME
    write_atomic(path, json.dumps({"controller": controller_name, "offsets_mm": offsets},
                                   indent=2) + "\n")
    return path


def load_backup(run_dir: Path) -> dict[str, float] | None:
    path = run_dir / BACKUP_NAME
    if not path.exists():
        return None
    return {a: float(v) for a, v in json.loads(path.read_text())["offsets_mm"].items()}


@dataclass
class _Stages:
    """One write-back round's stages: how each is journaled, and taken once."""

    steps: Steps
    round: int

    def log(self, record: dict[str, object]) -> None:
        self.steps.journal.append({"type": "writeback", "round": self.round, **record})

    def take(self, stage: str, act: Callable[[], object]) -> WritebackRecord | None:
        """The stage's record (station.engine.replay.Steps.take)."""
        return self.steps.take(WritebackStage(self.round, stage), act)


def _outcome(final: WritebackRecord) -> WritebackOutcome:
    """What a round's final stage says of it, taken now or journaled before."""
    match final:
        case WritebackDone():
            return WritebackOutcome("written", None, dict(final.before), dict(final.written))
        case WritebackUnchanged() | WritebackFailed():
            return WritebackOutcome(final.stage, final.reason, dict(final.before), None)
        case WritebackSkipped():
            return WritebackOutcome(final.stage, final.reason, None, None)
    raise AssertionError(f"write-back stage {final.stage!r} ends no round")


def write_back(
    *,
    controller: ZeroOffsets,
    identified: dict[str, float],
    max_abs_offset_mm: float,
    run_dir: Path,
    journal: Journal,
    operator: Operator,
    round: int = 1,
    offsets_at_start: dict[str, float] | None = None,
    note: str | None = None,
) -> WritebackOutcome:
    """Write-back round ``round`` as its journaled stages (module docstring); the
    outcome is its final stage's, journaled now or by an earlier session."""
    stages = _Stages(Steps(journal), round)
    final = stages.steps.take(WritebackRound(round), lambda: _round(
        stages, controller, identified, max_abs_offset_mm, run_dir, operator,
        offsets_at_start, note))
    assert final is not None, "every way through a round journals its final stage"
    return _outcome(final)


def _round(stages: _Stages, controller: ZeroOffsets, identified: dict[str, float],
           max_abs_offset_mm: float, run_dir: Path, operator: Operator,
           offsets_at_start: dict[str, float] | None, note: str | None) -> None:
    """The round's stages up to the final one it journals (or a fault it raises)."""
    drho = {a: identified.get(f"drho_{a}") for a in AXES}
    if all(v is None for v in drho.values()):
        reason = "the model identifies no joint offsets (model 'L'): nothing to write"
        stages.log({"stage": "skipped", "reason": reason})
        return
    delta = np.array([drho[a] or 0.0 for a in AXES])
    before = _backup(stages, controller, run_dir)
    new = _axes(np.array([before[a] for a in AXES]) - delta)
    refusal = _refusal(delta, new, max_abs_offset_mm, offsets_at_start)
    if refusal is not None:
        stages.log({"stage": "refused", "reason": refusal, "before": before})
        return
    intended = _intent(stages, controller, operator, before, new, note)
    if intended is None:
        reason = "declined by the operator; offsets unchanged"
        stages.log({"stage": "declined", "reason": reason, "before": before})
        return
    _write(stages, controller, run_dir, before, intended)


def _backup(stages: _Stages, controller: ZeroOffsets, run_dir: Path) -> dict[str, float]:
    """The offsets the round starts from: journaled (round 1 also to the backup file,
    which keeps the offsets from before the first round, for rollback)."""
    def backup() -> None:
        before = _axes(controller.read_offsets())
        if stages.round == 1:
            save_backup(run_dir, before, controller.name)
            stages.log({"stage": "backup", "before": before, "file": BACKUP_NAME})
        else:
            stages.log({"stage": "backup", "before": before})

    record = stages.take("backup", backup)
    assert isinstance(record, WritebackBackup)
    return {a: float(v) for a, v in record.before.items()}


def _refusal(delta: np.ndarray, new: dict[str, float], max_abs_offset_mm: float,
             offsets_at_start: dict[str, float] | None) -> str | None:
    """Why the correction is refused (None: it is not): a round's |Δρ_i|, or the total
    since the run started, beyond max_abs_offset_mm."""
    too_big = [f"Δρ_{a} = {d:+.4f} mm" for a, d in zip(AXES, delta, strict=True)
               if abs(d) > max_abs_offset_mm]
    if offsets_at_start is not None:
        too_big += [f"total Δρ_{a} = {offsets_at_start[a] - new[a]:+.4f} mm since the run "
                    "started" for a in AXES
                    if abs(offsets_at_start[a] - new[a]) > max_abs_offset_mm
                    and abs(delta[AXES.index(a)]) <= max_abs_offset_mm]
    if not too_big:
        return None
    return (f"refused: {', '.join(too_big)} beyond max_abs_offset_mm = "
            f"{max_abs_offset_mm:g}; nothing written")


def _intent(stages: _Stages, controller: ZeroOffsets, operator: Operator,
            before: dict[str, float], new: dict[str, float], note: str | None
            ) -> dict[str, float] | None:
    """The offsets to write, asked of the operator and journaled before any write (a
    journaled intent is written again as it was); None: declined."""
    record = stages.take("intent", lambda: _ask(stages, controller, operator, before, new,
                                                note))
    if record is None:
        return None
    assert isinstance(record, WritebackIntent)
    return {a: float(v) for a, v in record.written.items()}


def _ask(stages: _Stages, controller: ZeroOffsets, operator: Operator,
         before: dict[str, float], new: dict[str, float], note: str | None) -> None:
    """Ask the operator; journal the intent if they confirm."""
    # A drive with no OFFSET register: the station holds the offsets, nothing
    # reaches the drive, and the question must not say otherwise.
    held = controller.held_by == "station"
    verb = "hold" if held else "write"
    what = f"{verb.capitalize()} offsets " if stages.round == 1 else \
        f"Closed loop, round {stages.round}: {verb} offsets "
    where = (" in the station? (the drive takes no zero offset over Modbus: the station "
             "holds them, and the report says where to enter them in the drive)"
             if held else " to the controller?")
    question = what + ", ".join(
        f"o_{a} {before[a]:+.4f} → {new[a]:+.4f}" for a in AXES) + where \
        + (f" ({note})" if note else "")
    if operator.confirm(question):
        stages.log({"stage": "intent", "before": before, "written": new})


def _write(stages: _Stages, controller: ZeroOffsets, run_dir: Path,
           before: dict[str, float], new: dict[str, float]) -> None:
    """Write ``new`` and read it back; on a fault, the backup is written back."""
    try:
        readback = _axes(controller.write_offsets([new[a] for a in AXES]))
    except KeyboardInterrupt:
        # Ctrl-C may land between the writes of a map whose offset registers are
        # not contiguous: put the backup back (milliseconds) so the controller is
        # never left half-corrected, then stop. The intent stays journaled, so
        # `orthocal resume` writes the whole correction again.
        try:
            controller.write_offsets([before[a] for a in AXES])
            stages.log({"stage": "interrupted-restored", "before": before})
        except DeviceError as exc2:
            stages.log({"stage": "failed", "reason": f"interrupted; restore failed: {exc2}",
                        "before": before})
        raise
    except DeviceError as exc:
        try:
            controller.write_offsets([before[a] for a in AXES])
        except DeviceError as exc2:
            stages.log({"stage": "failed", "reason": f"{exc}; restore failed: {exc2}",
                        "before": before})
            raise RunFailed(
                f"write-back failed ({exc}) and restoring the backup failed too ({exc2}); "
                f"the controller's offsets are uncertain: run `orthocal rollback {run_dir}`"
            ) from exc2
        reason = f"write-back failed ({exc}); the backed-up offsets were restored"
        stages.log({"stage": "failed-restored", "reason": reason, "before": before})
        return
    stages.log({"stage": "done", "before": before, "written": readback})


def rollback_values(controller: ZeroOffsets, run_dir: Path
                    ) -> tuple[dict[str, float], dict[str, float]]:
    """(the offsets the controller holds now, the backed-up ones a rollback restores):
    what the operator is asked to confirm. BadInput where the run saved none."""
    from station.errors import BadInput

    backup = load_backup(run_dir)
    if backup is None:
        raise BadInput(f"{run_dir}: no {BACKUP_NAME} (the run never reached write-back)")
    return _axes(controller.read_offsets()), backup


def rollback(controller: ZeroOffsets, run_dir: Path, journal: Journal) -> dict[str, float]:
    """Write the backed-up offsets back; returns them (as read back)."""
    current, backup = rollback_values(controller, run_dir)
    journal.append({"type": "rollback", "stage": "intent", "current": current,
                    "restore": backup})
    readback = _axes(controller.write_offsets([backup[a] for a in AXES]))
    journal.append({"type": "rollback", "stage": "done", "restored": readback})
    return readback
