"""The snapshot of a run's rounds the statement is built from (:class:`Rounds`):
everything the end of a run reads, taken once, and what follows from it computed
once (the pooled layout, the workspace grid, the tool's target)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from orthocal import Identification
from orthocal.lost_motion import Reversal
from station.analysis import accuracy_statement as accuracy
from station.analysis.joints import JointKnowledge
from station.analysis.verdict import JoinedRounds
from station.config import StationConfig
from station.record.result import Iteration


@dataclass(frozen=True)
class Written:
    """One write-back: its status, why, the offsets before it and those written
    (read back; None where nothing was written)."""

    status: str
    reason: str | None
    before: Mapping[str, float] | None
    written: Mapping[str, float] | None


@dataclass(frozen=True)
class Rounds:
    """What the run measured and did, round by round: each round's identification
    (``idents``, carried and moved to the middle of the joints' bands), its Δρ joined
    with the rounds before (``joined``), its record entry (``iterations``), the axes'
    layout each round fitted (``layout_rounds``, and the fit each came from,
    ``layout_fits``), the write-backs (``writes``), the Δρ the last offsets aim at
    (``target``), the joints' lost motion (``reversal``), the offsets before the run,
    the drive's offset count, the soft limits (``limits``), why the loop stopped
    (``stopped``), and each joint's positioning error as the run took it (``joints``:
    station.analysis.joints; None: every joint exact, as before the joints were
    modelled), and the drive's count of each joint's target (``target_count_mm``)."""

    config: StationConfig
    idents: tuple[Identification, ...]
    joined: tuple[JoinedRounds, ...]
    iterations: tuple[Iteration, ...]
    layout_rounds: tuple[accuracy.RoundLayout, ...]
    layout_fits: Mapping[str, Identification]
    writes: tuple[Written, ...]
    target: Mapping[str, float]
    reversal: Reversal | None
    offsets_before: Mapping[str, float] | None
    offset_count_mm: float
    limits: accuracy.Limits | None
    stopped: str
    joints: JointKnowledge | None = None
    #: each joint's target count (the drive's, mm; 0: continuous): model.md (J15), (J17)
    target_count_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @cached_property
    def layout(self) -> accuracy.Layout | None:
        """The axes' layout pooled over the rounds (accuracy_statement.pool_layout), once."""
        return accuracy.pool_layout(list(self.layout_rounds))

    @cached_property
    def points(self) -> np.ndarray:
        """The workspace grid the tool is stated over (soft limits excluded)."""
        return accuracy.grid(self.config, self.limits).points

    @cached_property
    def layout_fit(self) -> Identification | None:
        """The fit the pooled layout's latest round came from: what the Type B inputs
        do to the layout is read off it."""
        lay = self.layout
        return None if lay is None or not lay.rounds else self.layout_fits.get(lay.rounds[-1])

    @property
    def last(self) -> Identification:
        return self.idents[-1]

    @property
    def written(self) -> tuple[Written, ...]:
        """The write-backs that wrote."""
        return tuple(w for w in self.writes if w.written is not None)

    @property
    def verified(self) -> bool:
        """Whether the last round measured the machine after the last write (else the
        last correction was written and nothing measured after it)."""
        return not self.iterations or self.iterations[-1].offsets_written is None

    @cached_property
    def tool_target(self) -> dict[str, float]:
        """Objective tool's Δρ for the pooled layout, as far as the last round's model
        holds it (accuracy_statement.tool_target), once."""
        names = () if not self.idents else self.last.names
        return accuracy.tool_target(self.config, self.layout, self.points, names)
