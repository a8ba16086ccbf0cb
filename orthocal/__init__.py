"""orthocal: the mathematics of leg-parallelism calibration of Orthoglide-type
parallel machines (Pashkevich & Gomolitsky). Pure functions, no I/O."""

from orthocal.calibration import coefficients, jacobian, linear_deviations, statistical_floor
from orthocal.geometry import AXES, MODELS, PARAM_NAMES, Geometry
from orthocal.identification import (
    Identification,
    IdentificationError,
    exact_jacobian,
    identify,
)
from orthocal.kinematics import forward, inverse
from orthocal.measurement import deviation, deviations, leg_reading
from orthocal.postures import posture, posture_point

__all__ = [
    "AXES",
    "MODELS",
    "PARAM_NAMES",
    "Geometry",
    "Identification",
    "IdentificationError",
    "coefficients",
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
    "statistical_floor",
]
