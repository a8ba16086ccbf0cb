"""orthocal: the mathematics of leg-parallelism calibration of Orthoglide-type
parallel machines (Pashkevich & Gomolitsky). Pure functions, no I/O."""

from orthocal.geometry import AXES, MODELS, PARAM_NAMES, Geometry
from orthocal.kinematics import forward, inverse
from orthocal.measurement import deviation, deviations, leg_reading
from orthocal.postures import posture, posture_point

__all__ = [
    "AXES",
    "MODELS",
    "PARAM_NAMES",
    "Geometry",
    "deviation",
    "deviations",
    "forward",
    "inverse",
    "leg_reading",
    "posture",
    "posture_point",
]
