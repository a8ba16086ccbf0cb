"""A pass's phase, the one place its name is read (docs/design.md, "Run JSON":
``iterations[].phase``): "m" the first measurement, "v" the verification of the first
write-back, "v2", "v3"… those of later ones; "+n" a further pass of the same round
("v+1", "v2+1", and "m+1" for a first measurement measured again: a recheck). The
journal and the record keep the name; everything that interprets it parses it here."""

from __future__ import annotations

import re
from dataclasses import dataclass

_PHASE = re.compile(r"^(?:(m)|v(\d*))(?:\+(\d+))?$")


@dataclass(frozen=True, order=True)
class Phase:
    """Round ``round`` (0: the first measurement, n: the verification of write-back n)
    and its pass ``extra`` (0: the round's first, n: its n-th further pass)."""

    round: int
    extra: int = 0

    def __post_init__(self) -> None:
        if self.round < 0 or self.extra < 0:
            raise ValueError(f"a phase's round and pass are ≥ 0, got {self!r}")

    @staticmethod
    def parse(text: str) -> Phase:
        """"m", "v", "v2", "v+1", "v2+1", "m+1"; ValueError otherwise."""
        match = _PHASE.match(text)
        if match is None:
            raise ValueError(f"not a phase: {text!r}")
        first, number, extra = match.groups()
        rnd = 0 if first else (int(number) if number else 1)
        if not first and rnd < 1:
            raise ValueError(f"not a phase: {text!r}")
        return Phase(rnd, int(extra) if extra else 0)

    def __str__(self) -> str:
        base = "m" if self.round == 0 else ("v" if self.round == 1 else f"v{self.round}")
        return base if self.extra == 0 else f"{base}+{self.extra}"

    @property
    def first_pass(self) -> Phase:
        """The round's first pass ("v2+1" → "v2")."""
        return Phase(self.round)

    @property
    def verifies(self) -> bool:
        """A verification (after a write-back), not the first measurement."""
        return self.round > 0

    @property
    def sized_like_verification(self) -> bool:
        """Whether its mountings take the cycles a verdict needs (station.engine.sizing):
        every verification, and a first measurement's further pass (it found nothing to
        write, so it must now show the machine converged)."""
        return self.round > 0 or self.extra > 0

    @property
    def kind(self) -> str:
        """"measurement" or "verification", as the operator is told."""
        return "verification" if self.verifies else "measurement"

    @property
    def label(self) -> str:
        """The progress line's: "measure", "verify", "verify 2", with ", again (n)"."""
        base = "measure" if self.round == 0 else (
            "verify" if self.round == 1 else f"verify {self.round}")
        return base + (f", again ({self.extra})" if self.extra else "")


def phase_of(measurement: int, extra: int = 0) -> str:
    """The name of the ``measurement``-th round's (0-based) pass ``extra``."""
    return str(Phase(measurement, extra))
