"""What a plan assumes of the controller before anything moves: the soft limits it
uses (the controller's, narrowed by the config) and where they come from, and the
path model of its moves (docs/design.md, "Register map"; station.plan.motion)."""

from __future__ import annotations

import numpy as np

from drivers.base import Vec3
from station.config import StationConfig
from station.errors import BadInput


def effective_limits(
    config: StationConfig, controller_limits: tuple[Vec3, Vec3]
) -> tuple[np.ndarray, np.ndarray]:
    """The controller's soft limits, narrowed (never widened) by the config.

    Where the controller cannot tell its limits (``controller_limits.source`` is
    "absent" or "nonsense", drivers.soft_limits.SoftLimits) they come from
    ``[controller] soft_min`` / ``soft_max`` alone; with neither, BadInput names both
    ways to provide them, before anything moves (docs/design.md, "Register map").
    """
    c = config.controller
    if getattr(controller_limits, "source", "registers") in ("absent", "nonsense"):
        missing = [k for k in ("soft_min", "soft_max") if getattr(c, k) is None]
        if missing:
            reason = getattr(controller_limits, "reason", "") or "the controller has none"
            raise BadInput(
                f"soft limits: {reason}; give them as [controller] "
                f"{' and '.join(missing)} (joint mm, x, y, z) in the config, or map the "
                "controller's soft-limit registers in [controller.registers] (SOFT_MIN_X.. "
                "SOFT_MAX_Z = address); nothing has moved")
        return (np.asarray(c.soft_min, dtype=float).copy(),
                np.asarray(c.soft_max, dtype=float).copy())
    lo = np.asarray(controller_limits[0], dtype=float).copy()
    hi = np.asarray(controller_limits[1], dtype=float).copy()
    if c.soft_min is not None:
        lo = np.maximum(lo, c.soft_min)
    if c.soft_max is not None:
        hi = np.minimum(hi, c.soft_max)
    return lo, hi


def limits_source(config: StationConfig, controller_limits: object) -> str:
    """Where the limits the plan uses come from, in words for the listing."""
    c = config.controller
    if getattr(controller_limits, "source", "registers") in ("absent", "nonsense"):
        return "from the config ([controller] soft_min/soft_max)"
    if c.soft_min is not None or c.soft_max is not None:
        return "the controller's, narrowed by the config"
    return "the controller's"


def motion_model(config: StationConfig) -> str:
    """The path model of the controller: the config's ``[controller] motion``, else
    what the register-map profile promises (docs/design.md: COMMAND 1 promises no
    interpolation unless the profile says the axes are coordinated). "coordinated"
    is refused for a map whose axes are separate drives (unit ids): each takes its
    target in its own request, so nothing moves them on one line, and a plan
    checked for that line could push a plunger past its stroke."""
    from drivers.map_files import resolve_map
    from drivers.registers import RegisterMapError

    try:
        the_map = resolve_map(config.controller.profile)
    except RegisterMapError as exc:
        raise BadInput(f"controller.profile: {exc}") from None
    motion = config.controller.motion or the_map.motion
    units = sorted({str(reg.device_id) for reg in the_map.axis_registers("TARGET")})
    if motion == "coordinated" and len(units) > 1:
        raise BadInput(f"controller.motion: coordinated, but the register map "
                       f"{the_map.name!r} puts the axes on separate drives (unit ids "
                       f"{', '.join(units)}), which take their targets one request after "
                       "another; leave motion out (the plan is then safe for any axis "
                       "timing); nothing has moved")
    return motion
