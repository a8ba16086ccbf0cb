"""The controller's soft limits a compensated program is checked against, from the
run directory: plan.json's ``soft_limits`` {lower, upper} (joint ρ, mm: what the
controller reported, narrowed by the config, when the run was planned) where it
holds them, else config.toml's ``[controller] soft_min``/``soft_max``. A bound that
is not a finite number is no bound; none at all is said in the program's header."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from station.gcode.subdivide import JointLimits


class LimitsError(ValueError):
    """A run directory's limits that cannot be read, in one line naming the file."""


def run_limits(run_dir: Path) -> JointLimits:
    """The soft limits of the run in ``run_dir`` (±inf where there are none)."""
    plan = run_dir / "plan.json"
    if plan.exists():
        soft = _load_json(plan).get("soft_limits")
        if isinstance(soft, dict):
            lower = _bounds(soft.get("lower"), plan, "soft_limits.lower", -math.inf)
            upper = _bounds(soft.get("upper"), plan, "soft_limits.upper", math.inf)
            if np.isfinite(lower).any() or np.isfinite(upper).any():
                return JointLimits(lower, upper, "plan.json")
    config = run_dir / "config.toml"
    if config.exists():
        controller = _load_toml(config).get("controller") or {}
        lower = _bounds(controller.get("soft_min"), config, "controller.soft_min", -math.inf)
        upper = _bounds(controller.get("soft_max"), config, "controller.soft_max", math.inf)
        if np.isfinite(lower).any() or np.isfinite(upper).any():
            return JointLimits(lower, upper, "config.toml [controller]")
    return JointLimits(np.full(3, -math.inf), np.full(3, math.inf),
                  "neither plan.json nor config.toml of the run holds any")


def _bounds(value: Any, path: Path, key: str, missing: float) -> np.ndarray:
    if value is None:
        return np.full(3, missing)
    try:
        out = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise LimitsError(f"{path}: {key}: not three numbers (mm)") from None
    if out.shape != (3,):
        raise LimitsError(f"{path}: {key}: not three numbers (mm)")
    return np.where(np.isfinite(out), out, missing)


def _load_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise LimitsError(f"{path}: cannot read ({exc})") from None
    if not isinstance(data, dict):
        raise LimitsError(f"{path}: not a plan")
    return data


def _load_toml(path: Path) -> dict[str, Any]:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise LimitsError(f"{path}: cannot read ({exc})") from None
