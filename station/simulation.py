"""The in-process virtual station behind ``orthocal run --simulate``: its hidden errors
from the command line, starting it, and restarting it for resume and rollback."""

from __future__ import annotations

import argparse
import math
import secrets
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import numpy as np

from station.config import StationConfig, parse_config
from station.errors import BadInput
from station.rundir import NVRAM_NAME

DEFAULT_NOISE_MM = 0.002
DEFAULT_SIM_DRHO_MM = 2.0  # random hidden Δρ are drawn uniform in ±this


def sim_params_from_args(args: argparse.Namespace) -> dict[str, Any]:
    seed = args.seed if args.seed is not None else secrets.randbelow(2**31)
    rng = np.random.default_rng(seed)
    drho = list(args.true_drho) if args.true_drho is not None else \
        [round(float(v), 4) for v in rng.uniform(-DEFAULT_SIM_DRHO_MM, DEFAULT_SIM_DRHO_MM, 3)]
    dl = list(args.true_dl) if args.true_dl is not None else [0.0, 0.0, 0.0]
    tilt = list(getattr(args, "true_tilt", None) or [0.0, 0.0, 0.0])
    noise = args.noise if args.noise is not None else DEFAULT_NOISE_MM
    if not (math.isfinite(noise) and noise >= 0):
        raise BadInput(f"--noise: must be >= 0 mm, got {noise}")
    from drivers.sim.station import DEFAULT_MOUNT_ERROR_MM

    mount = getattr(args, "mount_error", None)
    mount = DEFAULT_MOUNT_ERROR_MM if mount is None else mount
    if not (math.isfinite(mount) and mount >= 0):
        raise BadInput(f"--mount-error: must be >= 0 mm, got {mount}")
    return {
        "seed": seed,
        "true_drho": drho,
        "true_dl": dl,
        "true_tilt": tilt,
        "noise_mm": noise,
        "mount_error_mm": mount,
        "motion": getattr(args, "motion", None) or "coordinated",
        # Test hooks (not on the command line): the six-indicator style, a procedure.
        "indicators": int(getattr(args, "sim_indicators", 2) or 2),
        "procedure": getattr(args, "sim_procedure", None),
        "writeback": getattr(args, "sim_writeback", None),
        "speed_mm_s": getattr(args, "sim_speed", None),
    }


def start_station(params: dict[str, Any], nvram: Path | None) -> Any:
    from drivers.sim.station import SIM_ACCEL_MM_S2, SIM_SPEED_MM_S, VirtualStation

    # A faster virtual machine (tests) keeps the default's speed/acceleration ratio,
    # so its moves stay physical: trapezoids, in-position waits, derived deadlines.
    speed = params.get("speed_mm_s") or SIM_SPEED_MM_S
    return VirtualStation(
        true_drho=params["true_drho"], true_dl=params["true_dl"],
        # journals of runs before the tilts existed have none: an orthogonal machine
        true_tilt=params.get("true_tilt") or (0.0, 0.0, 0.0),
        noise_mm=params["noise_mm"], seed=params["seed"],
        indicator_count=params["indicators"], nvram_path=nvram,
        procedure=params.get("procedure"), writeback=params.get("writeback"),
        speed_mm_s=speed, accel_mm_s2=SIM_ACCEL_MM_S2 * speed / SIM_SPEED_MM_S,
        # Journals from before stand misplacement existed ran with perfect stands.
        mount_error_mm=params.get("mount_error_mm", 0.0),
        motion=params.get("motion") or "coordinated",
    )


def station_hook(args: argparse.Namespace, station: Any) -> None:
    """Tests reach the running virtual station (to inject its faults) through
    ``args.sim_station_hook``; the command line never sets it."""
    hook = getattr(args, "sim_station_hook", None)
    if hook is not None:
        hook(station)


def rebind(config: StationConfig, ports: dict[str, Any]) -> StationConfig:
    """The saved config of a simulated run, pointed at the restarted station's new ports."""
    data = config.model_dump(exclude_none=True)
    data["controller"]["port"] = ports["controller"]
    for ind in data["indicators"]:
        ind["port"] = ports["indicators"][ind["name"]]
    return parse_config(data, "virtual station config")


def restart_station(
    stack: ExitStack,
    args: argparse.Namespace,
    sim: dict[str, Any] | None,
    run_dir: Path,
    config: StationConfig,
) -> tuple[Any, StationConfig]:
    """For a simulated run (``sim`` from the journal header), the virtual station
    again — same hidden errors, offsets from its saved memory — and the config
    rebound to its new ports; for a real one, nothing to start."""
    if sim is None:
        return None, config
    station = start_station(sim, run_dir / NVRAM_NAME)
    stack.callback(station.close)
    station_hook(args, station)
    return station, rebind(config, station.ports())
