"""orthocal: the mathematics of leg-parallelism calibration of Orthoglide-type
parallel machines (Pashkevich & Gomolitsky). Pure functions, no I/O."""

from orthocal.calibration import (
    coefficients,
    jacobian,
    linear_deviations,
    statistical_floor,
    tilt_coefficient,
)
from orthocal.geometry import AXES, MODELS, PARAM_NAMES, TILT_NAMES, Geometry
from orthocal.identification import (
    Identification,
    IdentificationError,
    cannot_identify,
    exact_jacobian,
    identify,
)
from orthocal.kinematics import axis_directions, forward, inverse
from orthocal.measurement import deviation, deviations, leg_reading
from orthocal.postures import posture, posture_point
from orthocal.selection import ModelSelection, coverage_factor, select_model

__all__ = [
    "AXES",
    "MODELS",
    "PARAM_NAMES",
    "TILT_NAMES",
    "Geometry",
    "Identification",
    "IdentificationError",
    "ModelSelection",
    "axis_directions",
    "cannot_identify",
    "coefficients",
    "coverage_factor",
    "deviation",
    "deviations",
    "exact_jacobian",
    "forward",
    "identify",
    "inverse",
    "jacobian",
    "leg_reading",
    "linear_deviations",
    "posture",
    "posture_point",
    "select_model",
    "statistical_floor",
    "tilt_coefficient",
]
