"""Machine geometry and parameter names (docs/model.md, "Machine and parameters")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

AXES: tuple[str, str, str] = ("x", "y", "z")
AXIS_INDEX = {a: i for i, a in enumerate(AXES)}
PARAM_NAMES: tuple[str, ...] = (
    "drho_x", "drho_y", "drho_z", "dL_x", "dL_y", "dL_z", "tilt_yx", "tilt_zx", "tilt_zy",
    "gap_xy", "gap_xz", "gap_yz",
)  # fmt: skip
TILT_NAMES: tuple[str, str, str] = ("tilt_yx", "tilt_zx", "tilt_zy")
# How far the actuator axes pass each other (mm; docs/model.md, "Axes that do not meet").
GAP_NAMES: tuple[str, str, str] = ("gap_xy", "gap_xz", "gap_yz")
# The legs' form as the gauges see it (docs/model.md, "Leg form against tilts and
# gaps"): the sagitta h (mm) of leg i's surface along j, a bow w(t) = 4·h·t·(1 − t)
# over the leg. Not geometry (the joints' line is straight; the tool never sees
# it), but a nuisance the fit takes where a second gauge plane tells it from the
# tilts: models ending in FORM.
BOW_NAMES: tuple[str, ...] = ("bow_xy", "bow_xz", "bow_yx", "bow_yz", "bow_zx", "bow_zy")
#: Everything a fit may name: the machine's geometry, then the legs' bows.
FIT_NAMES: tuple[str, ...] = PARAM_NAMES + BOW_NAMES
#: The suffix of a model that fits the legs' bows beside its parameters.
FORM = "+form"
# The tilts are named and reported in mrad (docs/model.md, "Extended model"); the
# kinematics works in radians.
MRAD = 1e-3
# Columns of PARAM_NAMES each model identifies (docs/design.md, "Models").
MODELS: dict[str, tuple[int, ...]] = {
    "rho": (0, 1, 2),
    "L": (3, 4, 5),
    "full": (0, 1, 2, 3, 4, 5),
    "rho+tilt": (0, 1, 2, 6, 7, 8),
    "full+tilt": (0, 1, 2, 3, 4, 5, 6, 7, 8),
    "rho+gap": (0, 1, 2, 9, 10, 11),
    "rho+tilt+gap": (0, 1, 2, 6, 7, 8, 9, 10, 11),
    # the whole rigid geometry: needs more than two stops per leg
    "full+tilt+gap": tuple(range(12)),
}
# Each model with the legs' bows (FIT_NAMES columns 12–17) as nuisance parameters.
MODELS |= {m + FORM: (*cols, *range(12, 18)) for m, cols in list(MODELS.items())}
# The pair of axes {i, j} whose angle each tilt changes: tilt_yx leans y toward x, etc.
TILT_PAIRS: dict[frozenset[str], int] = {
    frozenset("xy"): 6, frozenset("xz"): 7, frozenset("yz"): 8,
}  # fmt: skip


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


def full_params(params) -> np.ndarray:
    """The 12-vector of PARAM_NAMES, the machine's geometry, from ``params``: None
    (all zero), an 18-vector of FIT_NAMES (its bows are not geometry and are left
    out), a 12-vector, a 9-vector (Δρ, ΔL, tilts: axes that meet) or a 6-vector
    (Δρ, ΔL) of the paper's model, whose tilts and gaps are zero."""
    return fit_params(params)[:len(PARAM_NAMES)]


def fit_params(params) -> np.ndarray:
    """The 18-vector of FIT_NAMES from ``params`` (as for :func:`full_params`; the
    legs' bows are zero unless an 18-vector names them)."""
    n = len(FIT_NAMES)
    if params is None:
        return np.zeros(n)
    params = np.asarray(params, dtype=float)
    if params.shape in ((6,), (9,), (12,)):
        return np.concatenate([params, np.zeros(n - params.shape[0])])
    if params.shape != (n,):
        raise ValueError(f"expected 6, 9, 12 or 18 parameters {FIT_NAMES}, got shape "
                         f"{params.shape}")
    return params


def bow_params(params) -> np.ndarray:
    """The legs' bows (BOW_NAMES order, mm) of ``params`` (as for :func:`fit_params`):
    zero unless an 18-vector names them."""
    return fit_params(params)[len(PARAM_NAMES):]


def split_params(params) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(Δρ, ΔL, tilts in mrad, gaps in mm) from an 18-, 12-, 9- or 6-vector ordered
    as FIT_NAMES (None: all zero)."""
    v = full_params(params)
    return v[:3], v[3:6], v[6:9], v[9:]


def params_vector(values: dict[str, float]) -> np.ndarray:
    """12-vector from a dict by PARAM_NAMES, or the 18-vector of FIT_NAMES when it
    names the legs' bows too; missing names are zero."""
    unknown = set(values) - set(FIT_NAMES)
    if unknown:
        raise ValueError(f"unknown parameter name(s): {sorted(unknown)}")
    names = FIT_NAMES if set(values) & set(BOW_NAMES) else PARAM_NAMES
    return np.array([float(values.get(n, 0.0)) for n in names])
