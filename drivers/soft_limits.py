"""Soft limits as a controller reports them (docs/design.md, "Register map"): read
from SOFT_MIN/SOFT_MAX where the map has them and the controller answers, or
marked unknown, with the reason, where it does not.

Most drives answer exception 2 (illegal data address) outside their map and
many keep their limits in parameters that Modbus cannot read; a drive that was
never set up may report all zeros. None of these is a fault of the link: the
station then takes the limits from its config (station.plan.steps.effective_limits),
and refuses to move when neither source has them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from drivers.device_errors import ExceptionResponse

#: where the limits came from
READ, GIVEN, ABSENT, NONSENSE = "registers", "given", "absent", "nonsense"


class SoftLimits(tuple):
    """``(lower, upper)`` joint limits in mm (arrays of shape (3,)), plus where they
    came from (``source``: "registers", "given", "absent" or "nonsense") and, when
    they are unusable, why (``reason``). A plain 2-tuple to its users, so
    ``lo, hi = controller.soft_limits()`` keeps working; unknown limits are NaN
    so that no comparison with them can pass unnoticed."""

    source: str
    reason: str

    def __new__(cls, lower: Any, upper: Any, source: str = READ,
                reason: str = "") -> SoftLimits:
        self = super().__new__(cls, (np.asarray(lower, dtype=float).reshape(3),
                                     np.asarray(upper, dtype=float).reshape(3)))
        self.source = source
        self.reason = reason
        return self

    @classmethod
    def unknown(cls, source: str, reason: str) -> SoftLimits:
        return cls(np.full(3, np.nan), np.full(3, np.nan), source, reason)

    @property
    def usable(self) -> bool:
        return self.source in (READ, GIVEN)


def nonsense(lower: np.ndarray, upper: np.ndarray) -> str:
    """Why a reported range cannot be a drive's limits ('' when it can be)."""
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
        return "not finite"
    if not np.any(lower) and not np.any(upper):
        return "all zero (limits not set up in the drive?)"
    bad = [a for a, lo, hi in zip("xyz", lower, upper, strict=True) if lo >= hi]
    if bad:
        return "lower ≥ upper on axis " + ", ".join(bad)
    return ""


def read_soft_limits(read_mm: Any, has_registers: bool, given: tuple | None,
                     unsupported: str) -> SoftLimits:
    """The controller's soft limits.

    ``read_mm()`` reads SOFT_MIN_X..Z then SOFT_MAX_X..Z (mm, shape (6,));
    ``has_registers``: the map has them; ``given``: limits supplied to the driver
    (from the machine's documentation) for a map that cannot read them;
    ``unsupported``: the map's reason when it has none. Exception 2 on the read
    means the drive does not have them; any other failure is a real fault and
    propagates.
    """
    if has_registers:
        try:
            both = np.asarray(read_mm(), dtype=float)
        except ExceptionResponse as exc:
            if exc.code != 2:
                raise
            absent = SoftLimits.unknown(
                ABSENT, "the controller has no soft-limit registers "
                "(SOFT_MIN/SOFT_MAX answer Modbus exception 2, illegal data address)")
        else:
            lo, hi = both[:3], both[3:]
            why = nonsense(lo, hi)
            if not why:
                return SoftLimits(lo, hi, READ)
            shown = ", ".join(f"[{a:.3f}, {b:.3f}]" for a, b in zip(lo, hi, strict=True))
            absent = SoftLimits.unknown(
                NONSENSE, f"the controller reports soft limits that are no range: "
                f"{shown} mm for x, y, z ({why})")
    else:
        absent = SoftLimits.unknown(ABSENT, unsupported)
    if given is not None:
        return SoftLimits(given[0], given[1], GIVEN)
    return absent
