"""model.json as a pydantic model (docs/design.md, "Accuracy at the tool" and "The
run record"): the identified machine, for a controller or a tool that compensates
kinematics. Every field is declared: one the engine adds and this model does not
know fails the test that validates real runs against it."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from station.record.result_base import Closed

AxisValues = dict[str, float]  # {"x": …, "y": …, "z": …}, mm


class ModelGeometry(Closed):
    leg_length_mm: float
    rho_min_mm: float
    rho_max_mm: float


class Conventions(Closed):
    model: str = Field(description="the kinematic model the parameters belong to")
    axes: str = Field(description="how the tilts set the axis directions")
    gaps: str = Field(description="where each axis's line runs: the gaps' convention")
    drho: str = Field(description="what a joint zero error is and how it is written back")
    parameters: str = Field(description="when the parameters hold: before or after writing")


class Units(Closed):
    drho: Literal["mm"]
    dL: Literal["mm"]
    tilt: Literal["mrad"]
    gap: Literal["mm"]


class Covariance(Closed):
    names: list[str]
    matrix: list[list[float]]


class MachineModel(Closed):
    """model.json, the identified machine (PARAM_NAMES: Δρ, ΔL, tilts, gaps)."""

    format: Literal["orthocal machine model 1"]
    geometry: ModelGeometry
    conventions: Conventions
    units: Units
    model: str = Field(description="the model the run kept (docs/design.md, \"Models\")")
    parameters: dict[str, float] = Field(description="all twelve, at the run's start")
    estimated: list[str]
    not_estimated: dict[str, str] = Field(description="name → why it is taken as 0")
    std_errors: dict[str, float]
    covariance: Covariance
    std_errors_dof: float | None
    drho_now: dict[str, float] = Field(description="Δρ once offsets_written act, mm")
    offsets_before: AxisValues | None
    offsets_written: AxisValues | None
