"""What a virtual station is made of, as values: the machine's hidden truth
(:class:`MachineTruth`), its drive (:class:`DriveSpec`), its gauges and their
stands (:class:`GaugeSpec`) and the devices' faults from the start
(:class:`DeviceFaults`). :class:`~drivers.sim.station.VirtualStation` is built
from them; each has the defaults of a plain virtual station (a perfect machine,
the generic drive, two gauges A and B), so a caller names only what differs.

Hardware only: which gauges a calibration moves where, and how whoever uses the
virtual station is told about it, are that user's business.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from drivers.registers import RegisterMap
from drivers.sim.drive_motion import DriveMotion
from drivers.sim.faults import Faults, IndicatorFaults
from drivers.sim.gauge_lines import LINES
from orthocal import Geometry

# Fast but physical: moves still take time, so in-position waits are real.
SIM_SPEED_MM_S = 1000.0
SIM_ACCEL_MM_S2 = 20000.0
# A common digital indicator: 12.5 mm of stroke, set pushed in by half so that the
# leg may move either way from where it was zeroed.
STANDARD_STROKE_MM = 12.5
STANDARD_PRELOAD_MM = STANDARD_STROKE_MM / 2

ZERO3 = (0.0, 0.0, 0.0)
#: A gauge mounted from the start: (its name, the leg, the direction, "-y" reversed).
Mounting = tuple[str, str, str]


def _floats(values: Sequence[float]) -> tuple[float, ...]:
    # tuples of floats: a spec is a value, not a view of a caller's list
    return tuple(float(v) for v in values)


@dataclass(frozen=True)
class MachineTruth:
    """The virtual Orthoglide's hidden errors (docs/model.md): what a calibration
    is to find or cope with, never told to the station.

    ``drho``: the joints' zero errors Δρ (mm); ``dl``: the legs' length errors ΔL
    (mm); ``tilt``: the actuator axes' tilts (mrad); ``gap``: how far the axes pass
    each other, gap_xy, gap_xz, gap_yz (mm); ``backlash``: each joint's lost motion
    (mm); ``leg_bow``: each leg's sagitta at its middle (mm, :mod:`drivers.sim.bowed_legs`),
    the same in both its gauge planes; ``plane_bow``: each gauge plane's own sagitta on
    top (mm, in the order xy, xz, yx, yz, zx, zy: leg, then the direction gauged);
    ``joint_lead``: each joint's lead error (µm per metre of travel from home) and
    ``joint_pitch``: one periodic error for all joints, (amplitude µm, period mm)
    (:mod:`drivers.sim.screws`); ``geometry``: the nominal machine they are errors of."""

    drho: Sequence[float] = ZERO3
    dl: Sequence[float] = ZERO3
    tilt: Sequence[float] = ZERO3
    gap: Sequence[float] = ZERO3
    backlash: Sequence[float] = ZERO3
    leg_bow: Sequence[float] = ZERO3
    plane_bow: Sequence[float] = (0.0,) * 6
    joint_lead: Sequence[float] = ZERO3
    joint_pitch: Sequence[float] = (0.0, 0.0)
    geometry: Geometry = field(default_factory=Geometry)

    def __post_init__(self) -> None:
        for name in ("drho", "dl", "tilt", "gap", "backlash", "leg_bow", "plane_bow",
                     "joint_lead", "joint_pitch"):
            object.__setattr__(self, name, _floats(getattr(self, name)))


@dataclass(frozen=True)
class DriveSpec:
    """The virtual drive: how it moves (``motion``: a
    :class:`~drivers.sim.drive_motion.DriveMotion` or its name), the speed and
    acceleration it is set up with (``speed_mm_s``, ``accel_mm_s2``: what its
    integrator knows), the acceleration it really uses where that differs
    (``actual_accel_mm_s2``: what a drive does without telling anyone), the
    register map it serves (``register_map``, None: the generic one) and the name
    that map goes by (``profile``, None: the map's own), its TCP ``port`` (0: any
    free one) and further :class:`~drivers.sim.controller.SimController` keywords
    (``controller_options``: transport, soft_limit_registers, ...)."""

    motion: str | DriveMotion = "coordinated"
    speed_mm_s: float = SIM_SPEED_MM_S
    accel_mm_s2: float = SIM_ACCEL_MM_S2
    actual_accel_mm_s2: float | None = None
    register_map: RegisterMap | None = None
    profile: str | None = None
    port: int = 0
    controller_options: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        a = self.actual_accel_mm_s2
        if a is not None and not (math.isfinite(a) and a > 0):
            raise ValueError(f"actual_accel_mm_s2 must be > 0, got {a}")

    @property
    def moving_accel_mm_s2(self) -> float:
        """The acceleration the axes move with."""
        return self.accel_mm_s2 if self.actual_accel_mm_s2 is None else self.actual_accel_mm_s2


@dataclass(frozen=True)
class GaugeSpec:
    """The dial indicators and their stands.

    ``names``: the gauges, in the order their seeds, a ``scale`` list and
    :attr:`~drivers.sim.station.VirtualStation.indicators` follow; ``protocol``:
    what they speak, at ``baud`` (None: the protocol's) and taking a line's time on
    the wire unless ``line_time`` is False;
    ``noise_mm``: their reading noise (σ); ``scale``: their relative scale errors
    (one for all, one per name in order, or by name; each shows (1 + S) times its
    plunger's travel); ``strokes``: (stroke, preload) by name, the others
    :data:`STANDARD_STROKE_MM` pushed in by half.

    Stands: placed by eye, each mounting off its plane by a hidden error drawn
    uniform in ±``mount_error_mm`` unless ``mount_errors`` fixes it (name -> mm);
    ``mounted``: the gauges on the machine from the start (name, leg, direction),
    for a station in another process that cannot be told where they are put.

    ``line``: where their serial lines end (:data:`drivers.sim.gauge_lines.LINES`):
    pseudo-terminals ("pty"), or sockets on 127.0.0.1 that pyserial opens as
    ``socket://`` URLs ("tcp", where there are no pseudo-terminals)."""

    names: tuple[str, ...] = ("A", "B")
    protocol: str = "mitutoyo"
    baud: int | None = None
    line_time: bool = True
    noise_mm: float = 0.002
    scale: float | Sequence[float] | Mapping[str, float] = 0.0
    strokes: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    mount_error_mm: float = 0.0
    mount_errors: Mapping[str, float] = field(default_factory=dict)
    mounted: tuple[Mounting, ...] = ()
    line: str = "pty"

    def __post_init__(self) -> None:
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "mounted", tuple(tuple(m) for m in self.mounted))
        if not self.names or len(set(self.names)) != len(self.names):
            raise ValueError(f"gauge names must be distinct and at least one, got {self.names}")
        if not (math.isfinite(self.mount_error_mm) and self.mount_error_mm >= 0):
            raise ValueError(f"mount_error_mm must be >= 0, got {self.mount_error_mm}")
        if self.line not in LINES:
            raise ValueError(f"line must be one of {', '.join(LINES)}, got {self.line!r}")
        # What is given by name is checked against the names when a station is built
        # (per_gauge_scale): a spec may be made first and named after (dataclasses.replace).

    def per_gauge_scale(self) -> dict[str, float]:
        """Each gauge's relative scale error (name -> S) from ``scale``; ValueError
        if anything given by name (strokes, stands, mountings, scales) names no gauge."""
        unknown = sorted({*self.strokes, *self.mount_errors, *(m[0] for m in self.mounted)}
                         - set(self.names))
        if unknown:
            raise ValueError(f"no gauge {', '.join(unknown)} (have {', '.join(self.names)})")
        return _per_gauge(self.scale, list(self.names))

    def stroke_of(self, name: str) -> tuple[float, float]:
        """(stroke, preload) of gauge ``name``, mm."""
        stroke, preload = self.strokes.get(name, (STANDARD_STROKE_MM, STANDARD_PRELOAD_MM))
        return float(stroke), float(preload)


@dataclass(frozen=True)
class DeviceFaults:
    """Faults the devices have from the moment they start: the controller's
    (``controller``) and each gauge's by name (``gauges``). Both stay the knobs
    they are: change their fields while the station runs."""

    controller: Faults | None = None
    gauges: Mapping[str, IndicatorFaults] = field(default_factory=dict)


def _per_gauge(values: float | Sequence[float] | Mapping[str, float],
               names: list[str]) -> dict[str, float]:
    """One value per gauge of ``names`` from one for all, one per name in order, or
    a mapping by name (those it leaves out: 0)."""
    if isinstance(values, Mapping):
        unknown = sorted(set(values) - set(names))
        if unknown:
            raise ValueError(f"no gauge {', '.join(unknown)} (have {', '.join(names)})")
        return {n: float(values.get(n, 0.0)) for n in names}
    if isinstance(values, (int, float)):
        return {n: float(values) for n in names}
    listed = [float(v) for v in values]
    if len(listed) == 1:
        listed *= len(names)
    if len(listed) != len(names):
        raise ValueError(f"expected one value or {len(names)} (one per gauge, "
                         f"{', '.join(names)}), got {len(listed)}")
    return dict(zip(names, listed, strict=True))
