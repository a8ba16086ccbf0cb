"""The drive's count (docs/model.md, "The drive's count"): a drive takes a target in whole
counts of its TARGET registers (IAI: 0.01 mm), so a joint commanded ρ stands at

    ρ^c = c·⌊ρ/c⌉                                                              (J15)

(half away from zero), up to c/2 from ρ, the same at every cycle. The test postures'
L·cos α are no whole counts: what (J15) makes of the deviations is systematic, and the
identification takes it out as it does a joint table's, (J14). What the count leaves at
the tool, (J17), is ``orthocal.joint_compensation.count_at_tool``'s.

Pure: numbers in, numbers out. The drivers round a target by the same rule
(``drivers.registers.to_counts``); a test holds the two together.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from orthocal.geometry import AXES


def count_vector(count_mm: Sequence[float] | np.ndarray) -> np.ndarray:
    """Each joint's count (x, y, z, mm; 0: taken as continuous) as an array (3,);
    ValueError unless three finite counts ≥ 0."""
    c = np.asarray(count_mm, dtype=float).reshape(-1)
    if c.shape != (3,) or np.any(~np.isfinite(c)) or np.any(c < 0):
        raise ValueError(f"count_mm must be three counts ≥ 0 (x, y, z), got {count_mm!r}")
    return c


def counted(rho, count_mm: Sequence[float] | np.ndarray) -> np.ndarray:
    """(J15): each joint of ``rho`` (..., 3), mm, as a drive whose count is
    ``count_mm`` (x, y, z; 0: a joint taken as continuous) holds it."""
    rho = np.asarray(rho, dtype=float)
    c = count_vector(count_mm)
    # the drivers' rule (drivers.registers.to_counts), on arrays: the quotient first
    # rounded to 9 decimals so that binary noise (1.0005/0.001 = 1000.4999999999999)
    # rounds as the decimal value does, then half away from zero
    safe = np.where(c > 0, c, 1.0)
    x = np.round(rho / safe, 9)
    whole = np.sign(x) * np.floor(np.abs(x) + 0.5) * safe
    return np.where(c > 0, whole, rho) + 0.0


class JointModel(Protocol):
    """Where the joints stand for the joint inputs a run commands (J1, the zero error
    aside): :class:`orthocal.JointErrors`, :class:`CountedJoints`."""

    def joints(self, rho, direction: str | np.ndarray | Sequence[float] = "mean"
               ) -> np.ndarray: ...


@dataclass(frozen=True)
class CountedJoints:
    """The joints of a drive with the count ``count_mm`` (x, y, z, mm), each commanded
    at (J15) and standing there, or where ``inner`` (the joints' tables, None: exact)
    puts a joint commanded there."""

    count_mm: tuple[float, float, float]
    inner: JointModel | None = None

    def joints(self, rho, direction: str | np.ndarray | Sequence[float] = "mean"
               ) -> np.ndarray:
        c = counted(rho, self.count_mm)
        return c if self.inner is None else self.inner.joints(c, direction)

    @property
    def any(self) -> bool:
        """Whether any joint has a count (False: :meth:`joints` is ρ itself)."""
        return any(v > 0 for v in self.count_mm)


def count_words(count_mm: Sequence[float]) -> str:
    """'x 0.01, y 0.01, z 0.01 mm': each joint's count, for the record's words."""
    return ", ".join(f"{a} {float(v):g}" for a, v in zip(AXES, count_mm, strict=True)) + " mm"

