"""What a resumed run does not do again: every journaled step's record, found by the
step's identity (docs/design.md, "Run directory").

A run is small journaled steps; each step's record is fsynced before the next step
starts. Resuming replays the journal: a step whose record is there is not taken
again, its record stands for it. One index serves every kind of step:

- a cycle's :class:`~station.plan.steps.Checkpoint` (its ``cycle`` record: the
  cycle's deviations), by (phase, setup, cycle);
- a setup's end (``setup_done``), by (phase, setup);
- a write-back round's stages (backup, intent, done, …), by round and stage.

The records a ``setup-redo`` voided (station.engine.recovery.drop_redone) are not
in it: a setup measured again is measured from its first cycle.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

Record = dict[str, Any]


@dataclass
class Replay:
    """The journal's step records by step identity (module docstring)."""

    cycles: dict[tuple[str, int, int], Record] = field(default_factory=dict)
    setups: set[tuple[str, int]] = field(default_factory=set)
    writebacks: dict[int, dict[str, Record]] = field(default_factory=dict)

    @classmethod
    def of(cls, records: Iterable[Record]) -> Replay:
        """The index of ``records`` (those a redo voided already left out)."""
        replay = cls()
        for r in records:
            kind = r.get("type")
            if kind == "cycle":
                replay.cycles[(r["phase"], int(r["setup"]), int(r["cycle"]))] = r
            elif kind == "setup_done":
                replay.setups.add((r["phase"], int(r["setup"])))
            elif kind == "writeback":
                # records from before the closed loop carry no round: round 1
                replay.writebacks.setdefault(int(r.get("round", 1)), {})[r["stage"]] = r
        return replay

    def cycle(self, phase: str, setup: int, cycle: int) -> Record | None:
        """The cycle's checkpoint record, or None: the cycle is still to measure."""
        return self.cycles.get((phase, setup, cycle))

    def setup_done(self, phase: str, setup: int) -> bool:
        return (phase, setup) in self.setups

    def stages(self, round: int) -> dict[str, Record]:
        """Write-back round ``round``'s journaled stages, stage → record."""
        return self.writebacks.get(round, {})
