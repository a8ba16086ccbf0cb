"""Machine geometry and parameter names (model.md, "Machine and parameters")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

AXES: tuple[str, str, str] = ("x", "y", "z")
AXIS_INDEX = {a: i for i, a in enumerate(AXES)}
PARAM_NAMES: tuple[str, ...] = ("drho_x", "drho_y", "drho_z", "dL_x", "dL_y", "dL_z")
MODELS: dict[str, tuple[int, ...]] = {"rho": (0, 1, 2), "L": (3, 4, 5), "full": (0, 1, 2, 3, 4, 5)}


@dataclass(frozen=True)
class Geometry:
    """Nominal Orthoglide: leg length L and the joint strokes of the test postures.

    ``rho_min`` (< 0) and ``rho_max`` (> 0) are the end-point excursions of the
    test postures Π_i^− and Π_i^+ along axis i (the paper's machine: L = 310.25,
    ρmin = −100, ρmax = 60, in mm).
    """

    leg_length: float = 310.25
    rho_min: float = -100.0
    rho_max: float = 60.0

    def __post_init__(self) -> None:
        if not np.isfinite(self.leg_length) or self.leg_length <= 0:
            raise ValueError(f"leg_length must be > 0, got {self.leg_length}")
        if not (-self.leg_length < self.rho_min < 0):
            raise ValueError(f"rho_min must lie in (-leg_length, 0), got {self.rho_min}")
        if not (0 < self.rho_max < self.leg_length):
            raise ValueError(f"rho_max must lie in (0, leg_length), got {self.rho_max}")

    @property
    def mount_plane(self) -> float:
        """x_i of the indicator plane: the middle of leg i at Π0 (nominal L/2)."""
        return self.leg_length / 2.0


def split_params(params: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(Δρ, ΔL) from a 6-vector ordered as PARAM_NAMES (None: all zero)."""
    if params is None:
        return np.zeros(3), np.zeros(3)
    params = np.asarray(params, dtype=float)
    if params.shape != (6,):
        raise ValueError(f"expected 6 parameters {PARAM_NAMES}, got shape {params.shape}")
    return params[:3], params[3:]


def params_vector(values: dict[str, float]) -> np.ndarray:
    """6-vector from a dict by PARAM_NAMES; missing names are zero."""
    unknown = set(values) - set(PARAM_NAMES)
    if unknown:
        raise ValueError(f"unknown parameter name(s): {sorted(unknown)}")
    return np.array([float(values.get(n, 0.0)) for n in PARAM_NAMES])
