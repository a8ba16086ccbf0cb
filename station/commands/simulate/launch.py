"""The in-process virtual station behind ``orthocal run --simulate``: its hidden errors
from the command line, starting it, and restarting it for resume and rollback.

The drive's behaviour (``--motion`` and the ``--drive-*`` options: profile shape,
own acceleration, start delays, one axis after another) goes into the simulated
run's parameters as plain JSON values (the journal header keeps them), and
:func:`drive_motion` rebuilds the same :class:`~drivers.sim.drive_motion.DriveMotion`
from them for ``resume``; a journal from before these existed has none and gets
the plain drive of its ``motion``. So with the legs' form and the gauges' scale
(``--leg-bow``, ``--gauge-scale``): kept in the header, absent from
older journals, whose runs had straight legs and true gauges. And with the axes'
gaps (``--true-gap``, gap_xy, gap_xz, gap_yz in mm): absent from journals of runs
before them, whose machines' axes met; and the joints' screws (``--joint-lead``,
``--joint-pitch``), absent where they were exact."""

from __future__ import annotations

import math
import secrets
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import ValidationError

from station.commands.options import DriveOptions, SimOptions, StationHook
from station.config import StationConfig, parse_config
from station.config.messages import format_validation_error
from station.errors import BadInput
from station.record.run_dir import MAP_NAME, NVRAM_NAME
from station.record.simulated import SimulationParams

if TYPE_CHECKING:
    from drivers.sim.drive_motion import DriveMotion
    from drivers.sim.specs import MachineTruth

# The virtual gauges' noise unless --noise says otherwise: a 1 µm digital indicator
# flickering by about a digit. With such gauges the default procedure's verification
# shows ±converge_mm (2 µm) in one or two passes; at 2 µm it often cannot in three, and
# the run says so ("not-converged").
DEFAULT_NOISE_MM = 0.001
DEFAULT_SIM_DRHO_MM = 2.0  # random hidden Δρ are drawn uniform in ±this
# How far off the leg's middle an operator sets a stand by eye (docs/model.md: 5-10 mm);
# the command line's default, so that a default simulated run shows the closed loop.
DEFAULT_MOUNT_ERROR_MM = 5.0
# Beyond these, the value is a slip of the unit, not an error of a machine: 8 for
# 8 µm is an 8 mm bow; 0.2 for 0.2 % a gauge reading a fifth too much.
MAX_LEG_BOW_MM = 1.0
MAX_GAUGE_SCALE = 0.1
# 10 000 µm/m is 1 %: a screw that far off is a unit slipped (0.1 for 100 µm/m).
MAX_JOINT_LEAD_UM_PER_M = 10_000.0
MAX_JOINT_PITCH_UM = 1_000.0


def sim_params(options: SimOptions) -> dict[str, Any]:
    """The simulated run's parameters as JSON values (the journal header keeps them,
    so resume restarts the same virtual station); BadInput naming the option."""
    seed = options.seed if options.seed is not None else secrets.randbelow(2**31)
    rng = np.random.default_rng(seed)
    drho = list(options.true_drho) if options.true_drho is not None else \
        [round(float(v), 4) for v in rng.uniform(-DEFAULT_SIM_DRHO_MM, DEFAULT_SIM_DRHO_MM, 3)]
    dl = list(options.true_dl) if options.true_dl is not None else [0.0, 0.0, 0.0]
    tilt = list(options.true_tilt or [0.0, 0.0, 0.0])
    gap = gaps_mm(options.true_gap)
    noise = options.noise if options.noise is not None else DEFAULT_NOISE_MM
    if not (math.isfinite(noise) and noise >= 0):
        raise BadInput(f"--noise: must be >= 0 mm, got {noise}")
    mount = DEFAULT_MOUNT_ERROR_MM if options.mount_error is None else options.mount_error
    if not (math.isfinite(mount) and mount >= 0):
        raise BadInput(f"--mount-error: must be >= 0 mm, got {mount}")
    backlash = backlash_mm(options.backlash)
    bow = leg_bow_mm(options.leg_bow)
    scale = gauge_scales(options.gauge_scale, int(options.indicators))
    lead, pitch = joint_lead(options.joint_lead), joint_pitch(options.joint_pitch)
    profile = map_profile(options.profile)
    return {
        "seed": seed,
        # where the gauges' lines end, kept for resume: the same virtual station
        "gauges": gauge_line(options.gauges),
        "true_drho": drho,
        "true_dl": dl,
        "true_tilt": tilt,
        "true_gap": gap,
        "noise_mm": noise,
        "mount_error_mm": mount,
        "backlash_mm": backlash,
        # the legs' form (each one's sagitta, mm) and the gauges' scale errors (one per
        # gauge, in the config's order), kept for resume
        "leg_bow_mm": bow,
        "gauge_scale": scale,
        # the screws: each joint's lead error (µm/m) and one periodic error for all
        # (amplitude µm, period mm), counted from home
        "joint_lead_um_per_m": lead,
        "joint_pitch": pitch,
        # the station's own test of the joints against the virtual gauge blocks
        **({"joint_test": True} if options.joint_test else {}),
        # the register map the virtual drive serves (a built-in name or a file's
        # absolute path), kept for resume
        "profile": profile,
        **drive_params(options.drive, separate_drives=separate_drives(profile)),
        # Not on the command line: the six-indicator style, procedure and write-back
        # overrides, a faster machine (tests)
        "indicators": int(options.indicators),
        "procedure": None if options.procedure is None else dict(options.procedure),
        "writeback": None if options.writeback is None else dict(options.writeback),
        "report": None if options.report is None else dict(options.report),
        "uncertainty": None if options.uncertainty is None else dict(options.uncertainty),
        "speed_mm_s": options.speed_mm_s,
    }


def start_station(params: dict[str, Any], nvram: Path | None) -> Any:
    """The virtual station of a simulated run's parameters (:func:`sim_params`, or a
    journal header), its drive's memory in ``nvram``."""
    from drivers.sim.specs import SIM_ACCEL_MM_S2, SIM_SPEED_MM_S, DriveSpec, GaugeSpec
    from station.commands.simulate.station_setups import SimulatedStation, gauges_for

    try:
        sim = SimulationParams.from_header(params)  # an old journal's gaps, in one place
    except ValidationError as exc:  # a --sim-procedure/--sim-report table's bad value
        raise BadInput(format_validation_error("simulation", exc)) from None
    # A faster virtual machine (tests) keeps the default's speed/acceleration ratio,
    # so its moves stay physical: trapezoids, in-position waits, derived deadlines.
    speed = sim.speed_mm_s or SIM_SPEED_MM_S
    drive = DriveSpec(motion=drive_motion(params), speed_mm_s=speed,
                      accel_mm_s2=SIM_ACCEL_MM_S2 * speed / SIM_SPEED_MM_S,
                      **served_map(params.get("profile")))
    gauges = gauges_for(sim.indicators, GaugeSpec(
        noise_mm=sim.noise_mm, mount_error_mm=sim.mount_error_mm, scale=sim.gauge_scale,
        line=gauge_line(sim.gauges or "pty")))  # a journal without it: its run had ptys
    return SimulatedStation(machine_truth(sim), drive, gauges, seed=sim.seed,
                            nvram_path=nvram)


def gauge_line(given: str | None) -> str:
    """``--gauges``: where the virtual gauges' lines end, "pty" or "tcp" (None: pty
    where the system has pseudo-terminals, else tcp); BadInput for pty where there
    are none."""
    from drivers.sim.gauge_lines import default_line, pseudo_terminals

    if given is None:
        return default_line()
    if given == "pty" and not pseudo_terminals():
        raise BadInput("--gauges pty: this system has no pseudo-terminals; "
                       "give --gauges tcp (the gauges on sockets of 127.0.0.1)")
    return given


def machine_truth(sim: SimulationParams) -> MachineTruth:
    """The hidden machine of a simulated run's parameters."""
    from drivers.sim.specs import MachineTruth

    return MachineTruth(drho=sim.true_drho, dl=sim.true_dl, tilt=sim.true_tilt,
                        gap=sim.true_gap, backlash=sim.backlash_mm, leg_bow=sim.leg_bow_mm,
                        joint_lead=sim.joint_lead_um_per_m, joint_pitch=sim.joint_pitch)


def map_profile(profile: str | None) -> str | None:
    """``--profile``: a built-in map's name, or a map file made an absolute path
    (checked here: BadInput naming the file and the entry)."""
    if profile is None:
        return None
    from drivers.map_files import is_map_file, resolve_map
    from drivers.registers import RegisterMapError

    name = str(Path(profile).resolve()) if is_map_file(profile) else profile
    try:
        resolve_map(name)
    except RegisterMapError as exc:
        raise BadInput(f"--profile: {exc}") from None
    return name


def separate_drives(profile: str | None) -> bool:
    """Whether the map ``profile`` puts the three targets on different unit ids."""
    if profile is None:
        return False
    from drivers.map_files import resolve_map

    targets = resolve_map(profile).axis_registers("TARGET")
    return len({reg.device_id for reg in targets}) > 1


def served_map(profile: str | None) -> dict[str, Any]:
    """The virtual station's register map for ``profile`` (nothing: the generic)."""
    if profile is None:
        return {}
    from drivers.map_files import resolve_map

    return {"register_map": resolve_map(profile), "profile": profile}


def gaps_mm(value: str | Sequence[float] | None) -> list[float]:
    """``--true-gap X,Y,Z``: how far the virtual machine's actuator axes pass each
    other, gap_xy, gap_xz, gap_yz (mm, either sign; docs/model.md, "Axes that do not
    meet"), as the command line's text or three numbers; none given, zeros;
    BadInput naming the option."""
    if value is None:
        return [0.0, 0.0, 0.0]
    if isinstance(value, str):
        values = _floats("--true-gap", value, (3,), "mm")
    else:
        try:
            values = [float(v) for v in value]
        except (TypeError, ValueError):
            raise BadInput(f"--true-gap: expected three numbers (mm), got {value!r}") from None
        if len(values) != 3:
            raise BadInput(f"--true-gap: expected three values x,y,z, got {value!r}")
    if not all(math.isfinite(v) for v in values):
        raise BadInput(f"--true-gap: must be finite (mm), got {value!r}")
    return values


def backlash_mm(text: str | None) -> list[float]:
    """``--backlash X,Y,Z`` (or one value for all joints), mm; BadInput naming it."""
    if text is None:
        return [0.0, 0.0, 0.0]
    return _numbers("--backlash", str(text), (1, 3), "mm", positive=False)


def leg_bow_mm(text: str | None) -> list[float]:
    """``--leg-bow X,Y,Z`` (or one value for all legs), mm, either sign (toward +j
    of each gauge plane or away), each within ±MAX_LEG_BOW_MM; BadInput naming it."""
    return _within("--leg-bow", text, "mm", MAX_LEG_BOW_MM,
                   f"a leg's form error is within ±{MAX_LEG_BOW_MM:g} mm (0.008 is 8 µm)")


def joint_lead(text: str | None) -> list[float]:
    """``--joint-lead X,Y,Z`` (or one value for all joints): each joint's lead error,
    µm per metre of travel from home, either sign, each within
    ±MAX_JOINT_LEAD_UM_PER_M; BadInput naming it."""
    return _within("--joint-lead", text, "µm/m", MAX_JOINT_LEAD_UM_PER_M,
                   "a lead error in µm per metre of travel, within "
                   f"±{MAX_JOINT_LEAD_UM_PER_M:g} (100 is 0.01 %)")


def joint_pitch(text: str | None) -> list[float]:
    """``--joint-pitch AMPLITUDE_UM,PERIOD_MM``: one periodic error for every joint's
    screw (amplitude 0 to MAX_JOINT_PITCH_UM µm, period > 0 mm); BadInput naming it."""
    if text is None:
        return [0.0, 0.0]
    try:
        values = [float(p) for p in str(text).split(",")]
    except ValueError:
        values = []
    if len(values) != 2:
        raise BadInput(f"--joint-pitch: expected AMPLITUDE_UM,PERIOD_MM, got {text!r}")
    amplitude, period = values
    if not 0.0 <= amplitude <= MAX_JOINT_PITCH_UM:  # nan included
        raise BadInput(f"--joint-pitch: the amplitude is 0 to {MAX_JOINT_PITCH_UM:g} µm, "
                       f"got {text!r}")
    if not (math.isfinite(period) and period > 0):
        raise BadInput(f"--joint-pitch: the period must be > 0 mm, got {text!r}")
    return values


def gauge_scales(text: str | None, gauges: int) -> list[float]:
    """``--gauge-scale S`` (one for all gauges, or one per gauge in the order of the
    config's indicators), relative, each within ±MAX_GAUGE_SCALE; one per gauge."""
    if text is None:
        return [0.0] * gauges
    values = _floats("--gauge-scale", str(text), (1, gauges), "relative", per_gauge=True)
    if not all(abs(v) < MAX_GAUGE_SCALE for v in values):  # nan included
        raise BadInput(f"--gauge-scale: a relative error (0.002 = 0.2 %) within "
                       f"±{MAX_GAUGE_SCALE:g}, got {text!r}")
    return values * gauges if len(values) == 1 else values


def _floats(option: str, text: str, counts: tuple[int, ...], unit: str,
            per_gauge: bool = False) -> list[float]:
    """``text`` as comma-separated numbers, as many as one of ``counts``
    (``per_gauge``: the last count is one per gauge, not x,y,z); their range is
    the caller's to check."""
    try:
        values = [float(p) for p in text.split(",")]
    except ValueError:
        raise BadInput(f"{option}: expected numbers ({unit}) separated by commas, "
                       f"got {text!r}") from None
    if len(values) not in counts:
        many = f"{counts[-1]} values, one per gauge" if per_gauge else "three values x,y,z"
        what = " or ".join("one value" if c == 1 else many for c in dict.fromkeys(counts))
        raise BadInput(f"{option}: expected {what}, got {text!r}")
    return values


def _within(option: str, text: str | None, unit: str, limit: float, what: str
            ) -> list[float]:
    """``text`` as x,y,z (or one value for all), either sign, each within ±``limit``
    (``what`` says so in the error); zeros where not given."""
    if text is None:
        return [0.0, 0.0, 0.0]
    values = _floats(option, str(text), (1, 3), unit)
    if not all(abs(v) <= limit for v in values):  # nan included
        raise BadInput(f"{option}: {what}, got {text!r}")
    return values * 3 if len(values) == 1 else values


def _numbers(option: str, text: str, counts: tuple[int, ...], unit: str,
             positive: bool) -> list[float]:
    """``text`` as comma-separated finite numbers, as many as one of ``counts``,
    each > 0 (``positive``) or >= 0; repeated to three."""
    values = _floats(option, text, counts, unit)
    for v in values:
        if not math.isfinite(v) or v < 0 or (positive and v == 0):
            raise BadInput(f"{option}: must be {'>' if positive else '>='} 0 {unit}, "
                           f"got {text!r}")
    return values * 3 if len(values) == 1 else values


def drive_params(drive: DriveOptions, separate_drives: bool = False) -> dict[str, Any]:
    """The virtual drive from ``--motion`` and ``--drive-*`` (BadInput naming the
    option), as JSON values: ``motion`` and ``drive_profile`` (3 shapes),
    ``drive_accel_mm_s2`` (3 values), ``drive_delays_s`` (3), ``drive_sequence``,
    each None when not given. ``separate_drives``: the map puts the axes on
    different unit ids, each taking its target in its own request, so they cannot
    move on one line: independent, and --motion coordinated is refused."""
    from drivers.sim.drive_motion import SHAPES

    profile, accel, delays, sequence = drive.profile, drive.accel, drive.delays, drive.sequence
    shapes: list[str] | None = None
    if profile is not None:
        shapes = [p.strip().lower() for p in str(profile).split(",")]
        if len(shapes) not in (1, 3) or any(sh not in SHAPES for sh in shapes):
            raise BadInput(f"--drive-profile: expected {'|'.join(SHAPES)}, one for all axes "
                           f"or three x,y,z, got {profile!r}")
        shapes = shapes * 3 if len(shapes) == 1 else shapes
    accels = None if accel is None else _numbers("--drive-accel", str(accel), (1, 3),
                                                 "mm/s²", positive=True)
    delay_values = None if delays is None else _numbers("--drive-delays", str(delays), (3,),
                                                        "s", positive=False)
    if sequence is not None:
        given_sequence, sequence = sequence, str(sequence).strip().lower()
        if sorted(sequence) != ["x", "y", "z"]:
            raise BadInput(f"--drive-sequence: expected an order of x, y and z, each once "
                           f"(e.g. zyx), got {given_sequence!r}")
    motion = drive.motion
    timed = delay_values is not None or sequence is not None
    if motion is None:
        # Delays and a sequence exist only on a drive that does not interpolate.
        motion = "independent" if timed or separate_drives else "coordinated"
    elif motion == "coordinated" and separate_drives:
        raise BadInput("--motion coordinated: the register map puts the axes on separate "
                       "drives (unit ids), which take their targets one request after "
                       "another and cannot move on one line; leave --motion out")
    if motion == "coordinated":
        for option, given in (("--drive-delays", delay_values is not None),
                              ("--drive-sequence", sequence is not None)):
            if given:
                raise BadInput(f"{option}: a coordinated drive has none; give "
                               f"--motion independent (or leave --motion out)")
        for option, values in (("--drive-profile", shapes), ("--drive-accel", accels)):
            if values is not None and len(set(values)) > 1:
                raise BadInput(f"{option}: a coordinated drive has one for all axes; give "
                               f"one value, or --motion independent")
    params = {"motion": motion, "drive_profile": shapes, "drive_accel_mm_s2": accels,
              "drive_delays_s": delay_values, "drive_sequence": sequence}
    drive_motion(params)  # anything left that the drive refuses, said now
    return params


def drive_motion(params: dict[str, Any]) -> DriveMotion:
    """The :class:`~drivers.sim.drive_motion.DriveMotion` of a simulated run's
    parameters (from :func:`drive_params`, or a journal header: keys
    missing in older ones mean the plain drive of ``motion``)."""
    from drivers.sim.drive_motion import DriveMotion

    motion = params.get("motion") or "coordinated"
    shapes, accels = params.get("drive_profile"), params.get("drive_accel_mm_s2")
    delays, sequence = params.get("drive_delays_s"), params.get("drive_sequence")
    try:
        if motion not in ("coordinated", "independent"):
            raise ValueError(f"motion must be coordinated or independent, got {motion!r}")
        return DriveMotion(
            coordinated=motion == "coordinated",
            shape=tuple(shapes) if shapes else "trapezoid",
            accel_mm_s2=tuple(accels) if accels else None,
            start_delay_s=tuple(delays) if delays else (0.0, 0.0, 0.0),
            sequence=sequence or None)
    except (ValueError, TypeError) as exc:
        raise BadInput(f"--motion/--drive-*: {exc}") from None


def rebind(config: StationConfig, ports: dict[str, Any]) -> StationConfig:
    """The saved config of a simulated run, pointed at the restarted station's new ports."""
    data = config.model_dump(exclude_none=True)
    data["controller"]["port"] = ports["controller"]
    for ind in data["indicators"]:
        ind["port"] = ports["indicators"][ind["name"]]
    return parse_config(data, "virtual station config")


#: The procedure a simulated run uses unless told otherwise: the config's defaults,
#: with a short settle (the virtual machine has no vibration to wait out).
SIM_PROCEDURE: dict[str, Any] = {
    "cycles": 3, "readings": 5, "settle_s": 0.02, "repeatability_mm": 0.02,
    "max_repeats": 1, "model": "auto", "method": "nonlinear", "verify": True,
}


#: The virtual station's length reference, as its config states it ([joints.reference]):
#: gauge blocks at 20 °C, calibrated to 0.5 µm (the virtual ones are exact), the
#: station's gauge A on the carriage pointing toward lower ρ.
SIM_REFERENCE: dict[str, Any] = {"kind": "gauge blocks", "u_mm": 0.0005,
                                 "temperature_c": 20.0, "plunger": "-"}


def station_config(station: Any, params: dict[str, Any]) -> dict[str, Any]:
    """The config a simulated run uses (station.toml's shape): the virtual station's
    hardware as it describes itself, the procedure (SIM_PROCEDURE, then the
    simulation's ``procedure``) and the write-back (``max_abs_offset_mm`` 3 mm, then
    the simulation's ``writeback``), the simulation's ``report``, what the station
    states of its inputs (its hardware's, then the simulation's ``uncertainty``), and
    with its ``joint_test`` the station's own test of the joints against the virtual
    gauge blocks (SIM_REFERENCE). What a test hook put in the station's own description
    wins: it stands for what a user writes in the file."""
    hardware = station.config()
    joints = {**({"station_test": ["x", "y", "z"], "reference": SIM_REFERENCE}
                 if params.get("joint_test") else {}), **hardware.get("joints", {})}
    stated = {**hardware.get("uncertainty", {}), **(params.get("uncertainty") or {})}
    return {**hardware, "uncertainty": stated,
            **({"joints": joints} if joints else {}),
            "procedure": {**SIM_PROCEDURE, **(params.get("procedure") or {}),
                          **hardware.get("procedure", {})},
            "writeback": {"max_abs_offset_mm": 3.0, **(params.get("writeback") or {}),
                          **hardware.get("writeback", {})},
            "report": {**(params.get("report") or {}), **hardware.get("report", {})}}


def restart_station(
    stack: ExitStack,
    hook: StationHook | None,
    sim: dict[str, Any] | None,
    run_dir: Path,
    config: StationConfig,
) -> tuple[Any, StationConfig]:
    """For a simulated run (``sim`` from the journal header), the virtual station
    again — same hidden errors, offsets from its saved memory — and the config
    rebound to its new ports; for a real one, nothing to start."""
    if sim is None:
        return None, config
    from drivers.map_files import is_map_file

    copy = run_dir / MAP_NAME
    if sim.get("profile") and is_map_file(sim["profile"]) and copy.exists():
        sim = {**sim, "profile": str(copy)}  # the run's own copy of its map file
    station = start_station(sim, run_dir / NVRAM_NAME)
    stack.callback(station.close)
    if hook is not None:
        hook(station)
    return station, rebind(config, station.ports())
