"""What a device can do, as typed Protocols (ophyd-async style).

The station depends only on these; real and simulated devices both satisfy
them. Units at this boundary are millimetres and seconds; register scaling and
serial framing stay inside the drivers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class AxisStatus:
    """Decoded STATUS/ALARM_CODE of the controller."""

    homed: bool
    moving: bool
    in_position: bool
    alarm: bool
    estop: bool
    alarm_code: int = 0


@runtime_checkable
class Motion(Protocol):
    """Three linear axes moved together (joint coordinates ρ_x, ρ_y, ρ_z in mm): what
    the sequencer, the mover and the plunger guard use."""

    def read_status(self) -> AxisStatus: ...

    def read_positions(self) -> np.ndarray:
        """Actual joint positions ρ (mm, shape (3,)) as the controller counts them."""
        ...

    def soft_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) joint limits in mm, each shape (3,)."""
        ...

    def move(self, targets: Sequence[float], speed_mm_s: float | None = None) -> None:
        """Set the three targets and command the move; returns once the command is taken."""
        ...

    def wait_in_position(
        self, targets: Sequence[float], timeout_s: float, tolerance_mm: float = 0.002
    ) -> np.ndarray:
        """Wait until the drive reports in position and every axis is within
        tolerance of its target; raise MoveTimeout / AlarmError / EStopError.
        Returns the actual positions."""
        ...

    def move_and_wait(
        self,
        targets: Sequence[float],
        speed_mm_s: float | None = None,
        timeout_s: float | None = None,
        start: Sequence[float] | None = None,
        watch: Callable[[], None] | None = None,
    ) -> np.ndarray:
        """move() then wait_in_position() with a timeout derived from distance and speed
        unless one is given; ``start``: positions the caller has just read; ``watch``:
        called between polls while the axes move, may raise to end the wait."""
        ...

    def stop(self) -> None: ...

    def home(self, timeout_s: float = 60.0) -> None: ...

    def reset_alarm(self) -> None: ...


@runtime_checkable
class ZeroOffsets(Protocol):
    """The joints' zero offsets o, where the drive keeps them or the station holds
    them (drivers.held_offsets): what write-back, rollback and the result use.
    ``name``: the controller's, as a backup of its offsets records it."""

    name: str

    def read_offsets(self) -> np.ndarray:
        """Joint zero offsets o (mm, shape (3,))."""
        ...

    def write_offsets(self, offsets: Sequence[float]) -> np.ndarray:
        """Write o, read it back, raise ReadbackMismatch unless equal to the register
        resolution. Returns what was read back."""
        ...

    def offset_resolution_mm(self) -> float:
        """The step in which an offset takes effect (mm): the controller's count.
        A correction is rounded to it, so no verification can show the joint zero
        closer than half of it."""
        ...


@runtime_checkable
class AxisController(Motion, ZeroOffsets, Protocol):
    """A controller of the three axes as a run opens it: its motion, its zero
    offsets, and close()."""

    def close(self) -> None: ...


@runtime_checkable
class Indicator(Protocol):
    """A digital dial indicator on its own serial line."""

    name: str

    def read(self) -> float:
        """One reading in mm (bounded retries; raises IndicatorError)."""
        ...

    def read_n(self, n: int) -> list[float]:
        """n consecutive readings in mm."""
        ...

    def close(self) -> None: ...
