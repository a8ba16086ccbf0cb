"""A rehearsal's virtual machine as a file: ``orthocal run --simulate SIM.toml``.

The file holds a ``[simulation]`` table (the hidden errors of the virtual machine,
its gauges' noise and stands, the register map its drive serves) with a
``[simulation.drive]`` table (how that drive moves, never told to the station),
and may hold the station's own ``[procedure]``, ``[writeback]``, ``[report]`` and
``[uncertainty]`` (what the shop states of its inputs, over the virtual station's own)
tables for the run. Every key is the long option of ``run --simulate`` without its dashes
(``--true-drho`` is ``true_drho``, ``--drive-profile`` is ``drive.profile``);
an option given on the command line wins over the file. Values are TOML's own:
``true_drho = [0.7, -1.1, 0.35]``, ``backlash = 0.01`` or ``[0.01, 0, 0.02]``,
``joint_lead = [100, -80, 60]`` (µm/m), ``joint_pitch = [2.0, 5.0]`` (µm, mm),
``joint_test = true``.

Loading checks the whole of it (the same checks as the options): a wrong key or
value is one line naming the file and the key, exit 2, before anything starts.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from station.config import format_validation_error
from station.config.overrides import (
    ProcedureOverrides,
    ReportOverrides,
    UncertaintyOverrides,
    WritebackOverrides,
)
from station.errors import BadInput, read_input
from station.record.simulated import Triple


class _FileTable(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class DriveTable(_FileTable):
    """``[simulation.drive]``: how the virtual controller moves its axes."""

    motion: Literal["coordinated", "independent"] | None = None
    profile: str | list[str] | None = Field(
        None, description="trapezoid, scurve or cosine; one, or one per axis x, y, z")
    accel: float | list[float] | None = Field(None, description="mm/s², one or x, y, z")
    delays: list[float] | None = Field(None, description="start delay per axis, s")
    sequence: str | None = Field(None, description="one axis after another, e.g. zyx")


class SimulationTable(_FileTable):
    """``[simulation]``: the virtual machine (mm, tilts in mrad)."""

    seed: int | None = None
    true_drho: Triple | None = None
    true_dl: Triple | None = None
    true_tilt: Triple | None = None
    true_gap: Triple | None = None
    noise: float | None = Field(None, ge=0)
    mount_error: float | None = Field(None, ge=0)
    backlash: float | Triple | None = None
    leg_bow: float | Triple | None = None
    gauge_scale: float | list[float] | None = None
    joint_lead: float | Triple | None = Field(
        None, description="each joint's lead error, µm/m from home; one, or x, y, z")
    joint_pitch: tuple[float, float] | None = Field(
        None, description="one periodic error for all joints: [amplitude µm, period mm]")
    joint_test: bool | None = Field(
        None, description="the station tests its joints itself against the virtual "
                          "gauge blocks before the calibration")
    profile: str | None = Field(
        None, description="a built-in map name, or a map file (relative to this file)")
    gauges: Literal["pty", "tcp"] | None = Field(
        None, description="the gauges' lines: pseudo-terminals or TCP (default: the system's)")
    drive: DriveTable = DriveTable()


class SimulationFile(_FileTable):
    """The whole file: the virtual machine, and the station's procedure, write-back
    and report overrides for the run (each key of its table's type; the station config
    then checks them together)."""

    simulation: SimulationTable = SimulationTable()
    procedure: ProcedureOverrides | None = None
    writeback: WritebackOverrides | None = None
    report: ReportOverrides | None = None
    uncertainty: UncertaintyOverrides | None = None


def read_simulation(path: Path) -> SimulationFile:
    """The file at ``path``, checked whole; BadInput naming the file and the key."""
    source = str(path)
    try:
        data = tomllib.loads(read_input(path))
    except tomllib.TOMLDecodeError as exc:
        raise BadInput(f"{source}: not valid TOML: {exc}") from None
    try:
        return SimulationFile.model_validate(data)
    except ValidationError as exc:
        raise BadInput(format_validation_error(source, exc)) from None


def as_text(value: Any) -> str | None:
    """A list or a number as the command line's text ("a,b,c"): one parser for both."""
    if value is None:
        return None
    if isinstance(value, list | tuple):
        return ",".join(v if isinstance(v, str) else format(float(v), "g") for v in value)
    return format(value, "g") if isinstance(value, float | int) else str(value)
