"""A simulated run's parameters (the journal header's ``simulation``), typed: what
``run --simulate`` drew or was given (station.commands.simulate.launch.sim_params), kept so
that ``resume`` restarts the same virtual station. Journals from before a parameter
existed lack it; what such a run had is said once, here, in the defaults.

Every key the header holds is declared: the hidden machine and gauges read here, the
virtual drive's motion (read by station.commands.simulate.launch.drive_motion) and the
config overrides the run was given (station.config.overrides)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, JsonValue, field_validator

from station.config.overrides import (
    ProcedureOverrides,
    ReportOverrides,
    UncertaintyOverrides,
    WritebackOverrides,
)

Triple = tuple[float, float, float]
_ZERO: Triple = (0.0, 0.0, 0.0)


class SimulationParams(BaseModel):
    """The hidden machine, its gauges and its drive. A null or missing field of an
    old journal is what that run had: no tilts, axes that meet, perfect stands, no
    lost motion, straight legs, true gauges, exact screws, the plain coordinated drive."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    seed: int
    true_drho: Triple
    true_dl: Triple
    true_tilt: Triple = Field(_ZERO, description="mrad: tilt_yx, tilt_zx, tilt_zy")
    true_gap: Triple = Field(_ZERO, description="mm: gap_xy, gap_xz, gap_yz")
    noise_mm: float
    mount_error_mm: float = Field(0.0, description="stands placed by eye, up to this off")
    backlash_mm: Triple = Field(_ZERO, description="each joint's reversal value, mm")
    leg_bow_mm: Triple = Field(_ZERO, description="each leg's sagitta at its middle, mm")
    gauge_scale: list[float] | float = Field(0.0, description="each gauge's scale error")
    joint_lead_um_per_m: Triple = Field(
        _ZERO, description="each joint's lead error, µm per metre of travel from home")
    joint_pitch: tuple[float, float] = Field(
        (0.0, 0.0), description="one periodic error for all joints: amplitude µm, period mm")
    joint_test: bool = Field(False, description="the station tested its joints itself "
                                                "against the virtual gauge blocks")
    indicators: int = 2
    profile: str | None = Field(None, description="the map the drive serves: a name or a file")
    gauges: Literal["pty", "tcp"] | None = Field(
        None, description="where the gauges' lines end: pseudo-terminals or TCP; absent: pty")
    speed_mm_s: float | None = None
    # the virtual drive (station.commands.simulate.launch.drive_params); absent: the plain
    # drive of ``motion``, coordinated where that is absent too
    motion: Literal["coordinated", "independent"] | None = None
    drive_profile: list[str] | None = Field(None, description="each axis's profile shape")
    drive_accel_mm_s2: list[float] | None = None
    drive_delays_s: list[float] | None = None
    drive_sequence: str | None = Field(None, description="one axis after another: zyx")
    # what the run was told to override of the config's sections
    procedure: ProcedureOverrides | None = None
    writeback: WritebackOverrides | None = None
    report: ReportOverrides | None = None
    uncertainty: UncertaintyOverrides | None = None

    @field_validator("true_tilt", "true_gap", "backlash_mm", "leg_bow_mm", "gauge_scale",
                     "mount_error_mm", "joint_lead_um_per_m", "joint_pitch", mode="before")
    @classmethod
    def _old_journal(cls, value: Any, info: Any) -> Any:
        # a header written before the field existed holds null (or nothing)
        return cls.model_fields[info.field_name].default if value is None else value

    @classmethod
    def from_header(cls, params: Mapping[str, Any]) -> SimulationParams:
        """The parameters of a journal header's ``simulation`` (or sim_params')."""
        return cls.model_validate(dict(params))

    def as_json(self) -> dict[str, JsonValue]:
        """The parameters as sim_params gives them: the keys the header holds (an old
        journal's nulls read as what that run had)."""
        return self.model_dump(mode="json", exclude_unset=True)

    def gauge_scales(self, count: int) -> list[float]:
        """One scale error per gauge (an old journal's none: true gauges)."""
        scale = self.gauge_scale
        return [float(scale)] * count if isinstance(scale, int | float) else list(scale)
