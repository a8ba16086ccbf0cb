"""Offsets the drive cannot hold, held by the station (docs/design.md, "Offsets held by
the station").

Most drives have no Modbus-writable zero offset (their home offset is a
parameter set from their own software or panel). The station then holds the
offsets o itself: :class:`HeldOffsets` wraps the drive's controller and commands
ρ + o where the station asks for ρ, and reports positions and soft limits less o,
so the carriage goes where a drive holding o would put it ("commanded ρ puts the
carriage at ρ + o") and every other part of the station (plan, soft limits,
plunger check, write-back, read-back, verification, closed loop, resume,
rollback) works as with a drive that holds them. The offsets live in the
station's run: write them into the drive's own parameter at the end, or start
the next run from them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from drivers.base import AxisStatus, HeldBy, Vec3
from drivers.soft_limits import SoftLimits

if TYPE_CHECKING:
    from drivers.axes import ModbusAxisController

HELD_BY_STATION: Final = "station"
HELD_BY_CONTROLLER: Final = "controller"


class HeldOffsets:
    """``inner`` (an axis controller without offset registers) with offsets held
    here, starting at ``offsets`` (mm); written offsets are rounded to the drive's
    target count (the resolution a target reaches it with)."""

    held_by: HeldBy = HELD_BY_STATION

    def __init__(self, inner: ModbusAxisController,
                 offsets: Sequence[float] | None = None) -> None:
        self.inner = inner
        self._o = np.zeros(3) if offsets is None else _vec3(offsets, "offsets")

    # what a drive holding o would report and accept ----------------------------------

    def read_positions(self) -> np.ndarray:
        return np.asarray(self.inner.read_positions(), dtype=float) - self._o

    def soft_limits(self) -> SoftLimits:
        lim = self.inner.soft_limits()
        lo, hi = lim
        return SoftLimits(np.asarray(lo) - self._o, np.asarray(hi) - self._o,
                          getattr(lim, "source", "registers"), getattr(lim, "reason", ""))

    def move(self, targets: Vec3, speed_mm_s: float | None = None) -> None:
        self.inner.move(_vec3(targets, "targets") + self._o, speed_mm_s)

    def wait_in_position(self, targets: Vec3, timeout_s: float,
                         tolerance_mm: float = 0.002, expected_s: float | None = None,
                         watch: Callable[[], None] | None = None) -> np.ndarray:
        return np.asarray(self.inner.wait_in_position(
            _vec3(targets, "targets") + self._o, timeout_s, tolerance_mm, expected_s,
            watch), dtype=float) - self._o

    def move_and_wait(self, targets: Vec3, speed_mm_s: float | None = None,
                      timeout_s: float | None = None, start: Vec3 | None = None,
                      watch: Callable[[], None] | None = None) -> np.ndarray:
        here = None if start is None else _vec3(start, "start") + self._o
        return np.asarray(self.inner.move_and_wait(
            _vec3(targets, "targets") + self._o, speed_mm_s, timeout_s, here, watch),
            dtype=float) - self._o

    def read_offsets(self) -> np.ndarray:
        return self._o.copy()

    def write_offsets(self, offsets: Vec3) -> np.ndarray:
        """Hold ``offsets`` from now on (rounded to the drive's target count); what is
        held is returned, as a drive's read-back would be."""
        step = self.offset_resolution_mm()
        self._o = np.round(_vec3(offsets, "offsets") / step) * step + 0.0
        return self._o.copy()

    def offset_resolution_mm(self) -> float:
        return float(self.inner.offset_resolution_mm())

    def target_resolution_mm(self) -> np.ndarray:
        # The offsets held are whole counts of the targets (write_offsets): ρ + o
        # rounds as ρ does, so the stops stand where the drive's own count puts them.
        return np.asarray(self.inner.target_resolution_mm(), dtype=float)

    # everything else is the drive's (what it gives back, given back) -----------------

    @property
    def name(self) -> str:
        return self.inner.name

    def read_status(self) -> AxisStatus:
        return self.inner.read_status()

    def stop(self) -> None:
        return self.inner.stop()

    def home(self, timeout_s: float = 60.0) -> None:
        return self.inner.home(timeout_s)

    def reset_alarm(self) -> None:
        return self.inner.reset_alarm()

    def close(self) -> None:
        return self.inner.close()

    if not TYPE_CHECKING:
        # The driver's own extras (its register map, for the result's note on where
        # to enter the offsets) by name. Hidden from mypy: a __getattr__ it saw would
        # stand in for any AxisController member missing above.
        def __getattr__(self, name: str) -> Any:
            return getattr(self.inner, name)


def _vec3(values: Vec3, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be three finite numbers (x, y, z), got {values!r}")
    return arr
