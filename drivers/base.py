"""What a device can do, as typed Protocols (ophyd-async style).

The station depends only on these; real and simulated devices both satisfy
them. Units at this boundary are millimetres and seconds; register scaling and
serial framing stay inside the drivers.

The axes' motion is split by what a caller does with it (:class:`AxisReadout`,
:class:`Moves`, :class:`Arrivals`, :class:`Homing`, :class:`Alarms`), so that
each part of the station asks for the least it uses; :class:`Motion`,
:class:`ZeroOffsets` and :class:`AxisController` are their compositions, what
a driver implements.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

# Three values (x, y, z), mm, as callers hold them: a sequence of floats or a float array.
Vec3 = Sequence[float] | NDArray[np.float64]

# Who keeps the joints' zero offsets: the drive, in its own registers, or the
# station, which commands ρ + o (drivers.held_offsets). result.json's offsets_held_by.
HeldBy = Literal["controller", "station"]


@dataclass(frozen=True)
class AxisStatus:
    """Decoded STATUS/ALARM_CODE of the controller."""

    homed: bool
    moving: bool
    in_position: bool
    alarm: bool
    estop: bool
    alarm_code: int = 0


class AxisReadout(Protocol):
    """What the drive reports of its three axes (joint coordinates ρ_x, ρ_y, ρ_z in
    mm); reading it moves nothing."""

    def read_status(self) -> AxisStatus: ...

    def read_positions(self) -> np.ndarray:
        """Actual joint positions ρ (mm, shape (3,)) as the controller counts them."""
        ...

    def soft_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) joint limits in mm, each shape (3,)."""
        ...


class Moves(Protocol):
    """Commands the drive takes and carries out on its own: a move, a stop."""

    def move(self, targets: Vec3, speed_mm_s: float | None = None) -> None:
        """Set the three targets and command the move; returns once the command is taken."""
        ...

    def stop(self) -> None: ...


class Arrivals(Protocol):
    """Moves waited for: until the drive reports the axes in position."""

    def wait_in_position(
        self, targets: Vec3, timeout_s: float, tolerance_mm: float = 0.002
    ) -> np.ndarray:
        """Wait until the drive reports in position and every axis is within
        tolerance of its target; raise MoveTimeout / AlarmError / EStopError.
        Returns the actual positions."""
        ...

    def move_and_wait(
        self,
        targets: Vec3,
        speed_mm_s: float | None = None,
        timeout_s: float | None = None,
        start: Vec3 | None = None,
        watch: Callable[[], None] | None = None,
    ) -> np.ndarray:
        """move() then wait_in_position() with a timeout derived from distance and speed
        unless one is given; ``start``: positions the caller has just read; ``watch``:
        called between polls while the axes move, may raise to end the wait."""
        ...


class Homing(Protocol):
    """Finding the axes' reference again (after a power cut)."""

    def home(self, timeout_s: float = 60.0) -> None: ...


class Alarms(Protocol):
    """Clearing the drive's alarm."""

    def reset_alarm(self) -> None: ...


@runtime_checkable
class Motion(AxisReadout, Moves, Arrivals, Homing, Alarms, Protocol):
    """Three linear axes moved together: everything the station asks of their motion
    (the sequencer, the mover, the plunger guard, the resume's homing)."""


class OffsetResolution(Protocol):
    """The step of the drive's zero offsets: what a verification is sized by."""

    def offset_resolution_mm(self) -> float:
        """The step in which an offset takes effect (mm): the controller's count.
        A correction is rounded to it, so no verification can show the joint zero
        closer than half of it."""
        ...


class TargetResolution(Protocol):
    """The step of the drive's targets: where a stop commanded ρ stands (J15)."""

    def target_resolution_mm(self) -> np.ndarray:
        """Each axis's target count (mm, shape (3,); 0: taken as continuous). A target
        is rounded to it, so a test posture's joints stand up to half of it off, the
        same at every cycle: the identification takes that out (docs/model.md, "The
        drive's count")."""
        ...


@runtime_checkable
class ZeroOffsets(OffsetResolution, Protocol):
    """The joints' zero offsets o, where the drive keeps them or the station holds
    them (drivers.held_offsets): what write-back, rollback and the result use."""

    @property
    def name(self) -> str:
        """The controller's, as a backup of its offsets records it."""
        ...

    @property
    def held_by(self) -> HeldBy:
        """Who keeps the offsets: the write-back's question and the result say so."""
        ...

    def read_offsets(self) -> np.ndarray:
        """Joint zero offsets o (mm, shape (3,))."""
        ...

    def write_offsets(self, offsets: Vec3) -> np.ndarray:
        """Write o, read it back, raise ReadbackMismatch unless equal to the register
        resolution. Returns what was read back."""
        ...


@runtime_checkable
class AxisController(Motion, ZeroOffsets, TargetResolution, Protocol):
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


class GaugeReadings(Protocol):
    """The station's indicators read together, by name: what the sequencer, the mover
    and the resume's reference check read."""

    def read(self, n: int = 1, names: Sequence[str] | None = None) -> dict[str, list[float]]:
        """``n`` readings (mm) of each indicator in ``names`` (None: all)."""
        ...


class Gauges(GaugeReadings, Protocol):
    """The station's indicators as a run opens them (drivers.indicators.IndicatorGroup):
    read together, closed together."""

    def close(self) -> None: ...
