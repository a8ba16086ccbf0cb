"""Station configuration: a TOML file validated by pydantic (docs/design.md, "Station config").

Every table forbids unknown keys, so a typo is an error naming its field instead
of a silently ignored setting. ``load_config`` turns every failure into one
``BadInput`` line: ``station.toml: indicators[1].stroke_mm: must be > 0``.
"""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from station.config.joint_tests import JointsConfig, resolved
from station.config.messages import format_validation_error
from station.errors import BadInput, read_input

AxisName = Literal["x", "y", "z"]
Direction = Literal["x", "y", "z", "-x", "-y", "-z"]
PROTOCOLS = ("mitutoyo", "sylvac", "mahr", "generic")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_default=True)


class MachineConfig(_Strict):
    # The machine's serial: recorded in every run, its history and its certificate,
    # and what `orthocal compare` checks before it compares two runs.
    id: str | None = Field(None, min_length=1, max_length=100)
    leg_length: float = Field(310.25, gt=0, allow_inf_nan=False)
    rho_min: float = Field(-100.0, lt=0, allow_inf_nan=False)
    rho_max: float = Field(60.0, gt=0, allow_inf_nan=False)
    # The box [[xmin, xmax], [ymin, ymax], [zmin, zmax]] (mm, tool points) over which
    # accuracy at the tool is stated; default the cube the test postures span.
    workspace: list[list[float]] | None = Field(None, min_length=3, max_length=3)

    @model_validator(mode="after")
    def _within_leg(self) -> MachineConfig:
        if self.rho_min <= -self.leg_length:
            raise ValueError("rho_min: must be > -leg_length")
        if self.rho_max >= self.leg_length:
            raise ValueError("rho_max: must be < leg_length")
        for axis, pair in zip("xyz", self.workspace or [], strict=False):
            if len(pair) != 2 or not all(math.isfinite(v) for v in pair) \
                    or not pair[0] < pair[1]:
                raise ValueError(f"workspace: the {axis} range must be [min, max] with "
                                 f"min < max, got {pair}")
        return self

    def workspace_box(self) -> list[list[float]]:
        """The workspace box of accuracy at the tool (mm)."""
        return [list(map(float, pair)) for pair in self.workspace] if self.workspace \
            else [[self.rho_min, self.rho_max] for _ in range(3)]

    def geometry(self):  # -> orthocal.Geometry (imported lazily: config loads without numpy)
        from orthocal import Geometry

        return Geometry(leg_length=self.leg_length, rho_min=self.rho_min, rho_max=self.rho_max)


class ControllerConfig(_Strict):
    transport: Literal["tcp", "rtu"] = "tcp"
    host: str = "127.0.0.1"
    # A TCP port number, or the serial device of an RTU link.
    port: int | str = 502
    device_id: int = Field(1, ge=0, le=247)
    # A built-in register map, or a map file (docs/design.md, "Register-map files"), a path
    # relative to the config's folder (made absolute when the config is loaded).
    profile: str = "orthocal-generic"
    # The zero offsets the station holds where the drive has no Modbus-writable ones
    # (the map's unsupported.offsets), mm: what the last run ended with (its
    # result.json offsets_final). Absent: none (or --offsets-from RUN_DIR).
    offsets: list[float] | None = Field(None, min_length=3, max_length=3)
    # Single register entries overriding the profile's map: name -> address.
    registers: dict[str, int] = Field(default_factory=dict)
    timeout_s: float = Field(2.0, gt=0, le=60)
    #: how long a lost connection is retried (a drive that lost power boots in seconds)
    reconnect_s: float = Field(10.0, ge=0, le=600)
    #: deadline of homing (COMMAND 3) when resume homes the machine
    home_timeout_s: float = Field(120.0, gt=0, le=3600)
    # Axis speed of the test moves (written before each move) and the acceleration
    # the station assumes when it derives each move's deadline (never its safety).
    speed_mm_s: float = Field(50.0, gt=0, le=65535)
    accel_mm_s2: float = Field(500.0, gt=0)
    baudrate: int = Field(19200, gt=0)
    # What COMMAND 1 promises: "coordinated" (the joints on the straight line) or
    # "independent" (each axis monotone to its target, any pace, any order: the plan
    # holds over the move's joint-space box); default: what the profile says.
    motion: Literal["coordinated", "independent"] | None = None
    # Narrow the controller's own soft limits (joint mm, x/y/z); never widen them.
    soft_min: list[float] | None = Field(None, min_length=3, max_length=3)
    soft_max: list[float] | None = Field(None, min_length=3, max_length=3)

    @field_validator("port", mode="before")
    @classmethod
    def _port_kind(cls, value: Any) -> Any:
        if isinstance(value, bool) or not isinstance(value, int | str):
            raise ValueError("must be a TCP port number or a serial device path")
        return value

    @field_validator("registers")
    @classmethod
    def _addresses(cls, value: dict[str, int]) -> dict[str, int]:
        for name, addr in value.items():
            if not 0 <= addr <= 0xFFFF:
                raise ValueError(f"{name}: address must be within 0..65535")
        return value

    @model_validator(mode="after")
    def _port_matches_transport(self) -> ControllerConfig:
        if self.transport == "tcp":
            if not isinstance(self.port, int):
                raise ValueError("port: must be a TCP port number for transport 'tcp'")
            if not 1 <= self.port <= 65535:
                raise ValueError("port: must be within 1..65535")
        elif not isinstance(self.port, str) or not self.port:
            raise ValueError("port: must be a serial device path for transport 'rtu'")
        if self.soft_min is not None and self.soft_max is not None:
            if any(lo >= hi for lo, hi in zip(self.soft_min, self.soft_max, strict=True)):
                raise ValueError("soft_min: must be below soft_max on every axis")
        return self

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}" if self.transport == "tcp" else str(self.port)


def _groups(pattern: str) -> int:
    try:
        return re.compile(pattern).groups
    except re.error as exc:
        raise ValueError(f"not a valid regular expression ({exc})") from None


class IndicatorConfig(_Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9_.-]{1,32}$")
    port: str = Field(min_length=1)
    protocol: Literal["mitutoyo", "sylvac", "mahr", "generic"] = "mitutoyo"
    stroke_mm: float = Field(12.5, gt=0, le=1000)
    # How far the plunger is pushed in at mounting; default: half the stroke.
    preload_mm: float | None = Field(None, ge=0)
    resolution_mm: float = Field(0.001, gt=0)
    timeout_s: float = Field(1.0, gt=0, le=60)
    #: how long a vanished port is reopened by its path (an adapter plugged back)
    reopen_s: float = Field(10.0, ge=0, le=600)
    # Line settings: the protocol's own unless given (generic needs them).
    baudrate: int | None = Field(None, gt=0)
    bytesize: Literal[7, 8] | None = None
    parity: Literal["N", "E", "O"] | None = None
    stopbits: Literal[1, 2] | None = None
    request: str | None = None
    terminator: str | None = None
    pattern: str | None = None
    # A gauge's error reply (at most one group: its error code), so that an error
    # is reported as the gauge's own rather than as a garbled reply.
    error_pattern: str | None = None
    # What the reply's number means: value_mm = number × scale × (1, 0.001, 25.4)
    # for unit mm, um, in. A negative scale suits a gauge that counts the other way.
    unit: Literal["mm", "um", "in"] | None = None
    scale: float | None = None
    # The gauge's maximum permissible error over a deviation's span (its data sheet or
    # calibration certificate; docs/design.md "Uncertainty budget"). Absent: the budget
    # takes its family's typical figure and says so.
    mpe_mm: float | None = Field(None, gt=0, le=1)
    # For the certificate: the instrument's serial number.
    serial: str | None = Field(None, min_length=1, max_length=64)

    @field_validator("pattern")
    @classmethod
    def _one_group(cls, value: str | None) -> str | None:
        if value is None:
            return value
        if _groups(value) != 1:
            raise ValueError("must have exactly one group (the value)")
        return value

    @field_validator("error_pattern")
    @classmethod
    def _at_most_one_group(cls, value: str | None) -> str | None:
        if value is not None and _groups(value) > 1:
            raise ValueError("must have at most one group (the error code)")
        return value

    @field_validator("scale")
    @classmethod
    def _non_zero(cls, value: float | None) -> float | None:
        if value is not None and (value == 0 or not math.isfinite(value)):
            raise ValueError("must be a finite number other than 0")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> IndicatorConfig:
        if self.preload_mm is None:
            self.preload_mm = self.stroke_mm / 2.0
        elif self.preload_mm > self.stroke_mm:
            raise ValueError("preload_mm: must be <= stroke_mm")
        if self.protocol == "generic":
            for key in ("pattern", "request", "baudrate"):
                if getattr(self, key) is None:
                    raise ValueError(f"{key}: required with protocol 'generic'")
        return self

    @property
    def preload(self) -> float:
        assert self.preload_mm is not None  # filled in by the validator
        return self.preload_mm


class SetupConfig(_Strict):
    leg: AxisName
    indicators: dict[str, Direction] = Field(min_length=1)
    # Where along the leg the gauges touch it, as the fraction of its length from
    # the carriage's joint at Π0: the middle (0.5), or a second gauge plane (0.25,
    # 0.75) that tells the legs' bow from the axes' tilts (docs/model.md, "Leg form
    # against tilts and gaps").
    at: float = Field(0.5, gt=0.05, lt=0.95)

    @model_validator(mode="after")
    def _directions(self) -> SetupConfig:
        seen: set[str] = set()
        for name, direction in self.indicators.items():
            axis = direction.lstrip("-")
            if axis == self.leg:
                raise ValueError(f"indicators.{name}: direction must differ from the leg")
            if axis in seen:
                raise ValueError(f"indicators.{name}: two indicators measure along {axis}")
            seen.add(axis)
        return self


class ProcedureConfig(_Strict):
    cycles: int = Field(3, ge=1, le=100)
    readings: int = Field(5, ge=1, le=100)
    settle_s: float = Field(0.3, ge=0, le=60)
    repeatability_mm: float = Field(0.02, gt=0)
    max_repeats: int = Field(1, ge=0, le=10)
    # Adaptive cycles: stop a setup once every deviation's standard error is below this.
    target_std_error_mm: float | None = Field(None, gt=0)
    # Outlier rule at a stop: |r - median| > k * 1.4826 * MAD (floored at the resolution).
    outlier_k: float = Field(5.0, gt=0)
    # The plunger guard: during a mounting's first cycle the gauges are watched while
    # the axes move, and the axes stopped before a plunger comes this close to
    # either end of its stroke; later cycles are refused if predicted that close.
    plunger_guard: bool = True
    plunger_margin_mm: float = Field(0.2, ge=0, le=10)
    # auto: the smallest model the run's own noise supports (orthocal.select_model);
    # the default, because on a square machine it keeps rho (≥ 99 % of runs) and on
    # one 0.2 mrad off square it finds the tilts rho alone turns into Δρ errors.
    model: Literal["rho", "L", "full", "rho+tilt", "full+tilt", "rho+gap", "rho+tilt+gap",
                   "full+tilt+gap", "auto"] = "auto"
    method: Literal["linear", "nonlinear"] = "nonlinear"
    verify: bool = True
    # Closed loop (docs/design.md): write-backs at most, each verified; 1 = one round, no loop.
    max_iterations: int = Field(3, ge=1, le=10)
    # "Converged" means the remaining Δρ is shown within ±converge_mm at 95 % on every
    # axis (mm); a significant correction smaller than this is not worth another round.
    converge_mm: float = Field(0.002, ge=0)
    # Where a verification's noise cannot show that yet, it is measured again (a
    # further pass of every setup, pooled with it) at most this many times; then the
    # loop ends "not-converged", saying why.
    max_extra_passes: int = Field(2, ge=0, le=10)
    # A verification whose setup cannot yet show its verdict measures more cycles on
    # the gauges already mounted, up to this many per mounting (None: cycles × (1 +
    # max_extra_passes), the cycles its extra passes would take, without mounting
    # again; at most cycles turns it off). The first measurement does not: there a
    # new mounting is what averages the stands' placement.
    max_cycles_in_mounting: int | None = Field(None, ge=1, le=100)
    # The stops Π_i(s) of each cycle, mm (docs/model.md "Test postures"); absent: the
    # paper's two, ρmax and ρmin, and every plan, journal and JSON exactly as before.
    strokes: list[float] | None = Field(None, min_length=1, max_length=20)
    # Lost motion (ISO 230-2): every stop whose readings enter an identification is
    # approached by every joint from this side, its last short leg after an overrun
    # of approach_overrun_mm (more than any real joint's reversal, with margin), so
    # that a joint's dead band shifts every stop alike and is stated, not taken for
    # tilt or offset; "as-planned": the paper's order, joints arriving from either
    # side. Each cycle also reads Π0 approached from the other side: the reversal.
    approach: Literal["below", "above", "as-planned"] = "below"
    approach_overrun_mm: float = Field(0.05, gt=0, le=5)
    # The reversal stop of every cycle; false for joints with none to measure (a
    # linear scale on the carriage): the run then states no reversal, assumes none.
    measure_reversal: bool = True
    # How far off the leg's middle an indicator stand may be set by eye (mm, uniform
    # ±): misplaced stands are modelled (orthocal.Stands) so that they are not taken
    # for tilted axes; 0: the stands are placed exactly, not modelled.
    stand_tolerance_mm: float = Field(5.0, ge=0, le=50)

    @field_validator("strokes")
    @classmethod
    def _strokes(cls, value: list[float] | None) -> list[float] | None:
        if value is None:
            return value
        for s in value:
            if not math.isfinite(s) or s == 0:
                raise ValueError(f"must be finite and nonzero, got {s:g}")
        if len(set(value)) != len(value):
            raise ValueError("must be unique")
        return value


class WritebackConfig(_Strict):
    max_abs_offset_mm: float = Field(3.0, gt=0)
    # What the offsets aim at: "joints", the paper's Δρ (legs parallel); "tool", the
    # offsets that leave the least RMS tool-point error over the workspace in
    # ``frame`` (docs/design.md, "Accuracy at the tool").
    objective: Literal["joints", "tool"] = "joints"
    # How the tool-point error is stated: after fitting away a translation (the tool
    # offset is set by touching off) or a rigid motion (parts aligned by probing).
    frame: Literal["translation", "rigid"] = "translation"


class UncertaintyConfig(_Strict):
    """Type B inputs of the uncertainty budget (docs/design.md "Uncertainty budget"); each
    absent one is taken at the default the budget names (station.analysis.run_budget),
    never silently as zero."""

    # The legs' straightness over the length the plunger slides along them: the
    # largest sagitta of their surface (one value, or [x, y, z]), mm.
    leg_straightness_mm: float | list[float] | None = None
    # The temperature change during the run (K).
    temperature_change_c: float | None = Field(None, ge=0, le=50)
    # How far a plunger may be set off the leg's normal (degrees).
    plunger_angle_deg: float | None = Field(None, ge=0, le=30)
    # Each joint's positioning error where no test of it is given ([joints] tests): a
    # bound per metre of travel from home, rectangular (µm/m; station.analysis.joints).
    joint_positioning_um_per_m: float | None = Field(None, ge=0, le=10_000)

    @field_validator("leg_straightness_mm")
    @classmethod
    def _straightness(cls, value: float | list[float] | None) -> float | list[float] | None:
        values = [value] if isinstance(value, (int, float)) else value
        if values is None:
            return value
        if len(values) not in (1, 3):
            raise ValueError("one value, or three: [x, y, z]")
        if any(not (0 <= v <= 1) for v in values):
            raise ValueError("must be between 0 and 1 mm")
        return value


class HistoryConfig(_Strict):
    # Every finished run is recorded here (station.history): a database URL
    # (sqlite:///…, postgresql://…), or None for history.sqlite beside the run
    # directories (--out). A store that cannot be written never fails a run.
    url: str | None = None
    enabled: bool = True


class ReportConfig(_Strict):
    # report.html's figures cost a second or more of CPU at the end of every run on a
    # small station PC; false writes the report without them (`orthocal report` draws them).
    figures: bool = True


class AcceptanceConfig(_Strict):
    """A shop's acceptance limit on the tool's error after calibration, µm (docs/
    design.md, "Acceptance"): the run says PASS only where the whole 95 % interval
    of the figure lies within its limit (station.analysis.acceptance). Absent: no
    acceptance is judged."""

    tool_rms_um: float | None = Field(None, gt=0, allow_inf_nan=False)
    tool_max_um: float | None = Field(None, gt=0, allow_inf_nan=False)


class StationTable(_Strict):
    # Who calibrates: recorded in the run's result and journal and printed in the
    # report's header and certificate (`orthocal run --operator NAME` overrides it).
    operator: str | None = Field(None, min_length=1, max_length=100)


class StationConfig(_Strict):
    station: StationTable = Field(default_factory=StationTable)
    machine: MachineConfig = Field(default_factory=MachineConfig)
    controller: ControllerConfig = Field(default_factory=ControllerConfig)
    indicators: list[IndicatorConfig] = Field(min_length=1)
    setups: list[SetupConfig] = Field(min_length=1)
    procedure: ProcedureConfig = Field(default_factory=ProcedureConfig)
    writeback: WritebackConfig = Field(default_factory=WritebackConfig)
    uncertainty: UncertaintyConfig = Field(default_factory=UncertaintyConfig)
    joints: JointsConfig = Field(default_factory=JointsConfig)
    history: HistoryConfig = Field(default_factory=HistoryConfig)
    report: ReportConfig = Field(default_factory=ReportConfig)
    acceptance: AcceptanceConfig = Field(default_factory=AcceptanceConfig)

    @model_validator(mode="after")
    def _references(self) -> StationConfig:
        m = self.machine
        for s in self.procedure.strokes or ():
            if not m.rho_min <= s <= m.rho_max:
                raise ValueError(
                    f"procedure.strokes: {s:g} is outside [rho_min, rho_max] = "
                    f"[{m.rho_min:g}, {m.rho_max:g}] of [machine]")
        names = [ind.name for ind in self.indicators]
        for idx, name in enumerate(names):
            if name in names[:idx]:
                raise ValueError(f"indicators[{idx}].name: duplicate name {name!r}")
        for idx, setup in enumerate(self.setups):
            for name in setup.indicators:
                if name not in names:
                    raise ValueError(
                        f"setups[{idx}].indicators.{name}: no indicator of that name "
                        f"(have {', '.join(names)})"
                    )
        self._planes()
        self.joints.check_station_test(names)  # its reference and gauges
        return self

    def _planes(self) -> None:
        """A gauge read off the middle must be read in two planes: only then does
        the fit tell its leg's bow from the axes' tilts (the bows are fitted where
        any setup has a second plane)."""
        planes: dict[tuple[str, str], set[float]] = {}
        for setup in self.setups:
            for direction in setup.indicators.values():
                planes.setdefault((setup.leg, direction.lstrip("-")), set()).add(setup.at)
        if all(at == 0.5 for seen in planes.values() for at in seen):
            return
        for (leg, along), seen in planes.items():
            if len(seen) < 2:
                idx = next(n for n, s in enumerate(self.setups) if s.leg == leg)
                raise ValueError(
                    f"setups[{idx}]: the gauge of leg {leg} along {along} is read in one "
                    f"plane (at = {min(seen):g}) while other setups have a second one: give "
                    "every gauge a setup at 0.5 and one at a second plane (0.25 or 0.75), "
                    "or leave every setup at the middle")

    def indicator(self, name: str) -> IndicatorConfig:
        return next(ind for ind in self.indicators if ind.name == name)


# --- loading -------------------------------------------------------------------------


def parse_config(data: dict[str, Any], source: str = "config") -> StationConfig:
    try:
        return StationConfig.model_validate(data)
    except ValidationError as exc:
        raise BadInput(format_validation_error(source, exc)) from None


def load_config(path: str | Path) -> StationConfig:
    """The config file at ``path``; a register-map file its profile names and the
    joints' test files are read from the config's folder (and checked here: their
    errors exit 2 before anything moves, naming the file and the entry or line)."""
    path = Path(path)
    source = str(path)
    text = read_input(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        # tomllib's message carries "(at line N, column M)".
        raise BadInput(f"{source}: not valid TOML: {exc}") from None
    config = with_map_file(parse_config(data, source), path.parent, source)
    joints = resolved(config.joints, path.parent)  # each test read: a bad row exits 2
    return config if joints is config.joints else config.model_copy(update={"joints": joints})


def with_map_file(config: StationConfig, base_dir: Path, source: str = "config"
                  ) -> StationConfig:
    """``config`` with a map file its profile names made an absolute path (relative
    paths are the config's folder's), the map checked: BadInput naming the file and
    the entry."""
    from drivers.map_files import is_map_file, load_map
    from drivers.registers import RegisterMapError

    c = config.controller
    profile = c.profile
    if is_map_file(profile) and not Path(profile).is_absolute():
        profile = str((base_dir / profile).resolve())
    try:
        load_map(profile, {k: {"address": v} for k, v in c.registers.items()})
    except RegisterMapError as exc:
        raise BadInput(f"{source}: controller.profile: {exc}") from None
    if profile == c.profile:
        return config
    return config.model_copy(update={"controller": c.model_copy(update={"profile": profile})})
