"""What a resumed run does not do again: every journaled step's record, found by the
step's identity (docs/design.md, "Run directory").

A run is small journaled steps; each step's record is fsynced before the next step
starts. Resuming replays the journal: a step whose record is there is not taken
again, its record stands for it. One index serves every kind of step:

- a cycle's :class:`~station.plan.steps.Checkpoint` (its ``cycle`` record: the
  cycle's deviations), by (phase, setup, cycle);
- a setup's end (``setup_done``), by (phase, setup);
- a round's identification (``identification`` for the measurement, round 0;
  ``verification`` for verification round n), by round, with the passes it pooled;
- a write-back round's stages (backup, intent, done, …), by round and stage.

The records a ``setup-redo`` voided (station.engine.recovery.drop_redone) are not
in it: a setup measured again is measured from its first cycle.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from station.engine.documents import JsonObject

Record = JsonObject  # one journal record


@dataclass
class Replay:
    """The journal's step records by step identity (module docstring)."""

    cycles: dict[tuple[str, int, int], Record] = field(default_factory=dict)
    setups: set[tuple[str, int]] = field(default_factory=set)
    writebacks: dict[int, dict[str, Record]] = field(default_factory=dict)
    identifications: dict[int, Record] = field(default_factory=dict)

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
            elif kind == "identification":
                replay.identifications[0] = r
            elif kind == "verification":
                replay.identifications[int(r.get("round", 1))] = r
        return replay

    def cycle(self, phase: str, setup: int, cycle: int) -> Record | None:
        """The cycle's checkpoint record, or None: the cycle is still to measure."""
        return self.cycles.get((phase, setup, cycle))

    def setup_done(self, phase: str, setup: int) -> bool:
        return (phase, setup) in self.setups

    def identified(self, round: int, passes: list[str]) -> bool:
        """Whether round ``round``'s identification (0: the measurement's) is journaled
        with ``passes`` pooled (a record of fewer passes is the round before a further
        pass was measured: the pooled one is journaled again)."""
        journaled = self.identifications.get(round)
        return journaled is not None and len(journaled.get("passes", ["one"])) >= len(passes)

    def note_identified(self, round: int, passes: list[str]) -> None:
        """Round ``round``'s identification of ``passes`` is journaled now."""
        self.identifications[round] = {"passes": list(passes)}

    def stages(self, round: int) -> dict[str, Record]:
        """Write-back round ``round``'s journaled stages, stage → record."""
        return self.writebacks.get(round, {})
