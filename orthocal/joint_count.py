"""The drive's count (docs/model.md, "The drive's count"): a drive takes a target in whole
counts of its TARGET registers (IAI: 0.01 mm), so a joint commanded ρ stands at

    ρ^c = c·⌊ρ/c⌉                                                              (J15)

(half away from zero), up to c/2 from ρ, the same at every cycle. The test postures'
L·cos α are no whole counts: what (J15) makes of the deviations is systematic, and the
identification takes it out as it does a joint table's, (J14).

Pure: numbers in, numbers out. The drivers round a target by the same rule
(``drivers.registers.to_counts``); a test holds the two together.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from orthocal.geometry import AXES, Geometry


def counted(rho, count_mm: Sequence[float] | np.ndarray) -> np.ndarray:
    """(J15): each joint of ``rho`` (..., 3), mm, as a drive whose count is
    ``count_mm`` (x, y, z; 0: a joint taken as continuous) holds it."""
    rho = np.asarray(rho, dtype=float)
    c = np.asarray(count_mm, dtype=float).reshape(-1)
    if c.shape != (3,) or np.any(~np.isfinite(c)) or np.any(c < 0):
        raise ValueError(f"count_mm must be three counts ≥ 0 (x, y, z), got {count_mm!r}")
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


def count_at_tool(points, geometry: Geometry, count_mm: Sequence[float] | np.ndarray
                  ) -> tuple[float, float]:
    """What the count does at the tool of the nominal machine over ``points`` (N, 3),
    mm: a point between counts is reached with each joint up to c_j/2 off (J15), so
    the tool stands δP = J·δρ off, J = ∂P/∂ρ. Returns (RMS, max) over the points, mm,
    (J17): the RMS with each δρ_j uniform on ±c_j/2, E|δP|² = Σ_j |J_j|²·c_j²/12; the
    max over the corners of that box, max |J·(±c/2)|. At P = 0, J = I: c/2 and
    c·√3/2 for three equal counts."""
    p = np.atleast_2d(np.asarray(points, dtype=float))
    c = np.asarray(count_mm, dtype=float).reshape(-1)
    if c.shape != (3,) or np.any(~np.isfinite(c)) or np.any(c < 0):
        raise ValueError(f"count_mm must be three counts ≥ 0 (x, y, z), got {count_mm!r}")
    L2 = geometry.leg_length ** 2
    # ∂ρ_i/∂p of ρ_i = p_i + sqrt(L² − p_j² − p_k²) (the nominal inverse kinematics)
    m = np.empty((len(p), 3, 3))
    for i in range(3):
        j, k = [n for n in range(3) if n != i]
        root = np.sqrt(L2 - p[:, j] ** 2 - p[:, k] ** 2)
        m[:, i, i] = 1.0
        m[:, i, j] = -p[:, j] / root
        m[:, i, k] = -p[:, k] / root
    jac = np.linalg.inv(m)  # ∂P/∂ρ
    rms = np.sqrt(np.mean(np.sum(jac ** 2 * (c ** 2 / 12.0)[None, None, :], axis=(1, 2))))
    corners = np.array(np.meshgrid(*[(-0.5, 0.5)] * 3, indexing="ij")).reshape(3, -1)
    reach = np.linalg.norm(jac @ (c[:, None] * corners), axis=1)  # (N, 8)
    return float(rms), float(np.max(reach))
