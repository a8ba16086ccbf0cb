"""orthocal: the mathematics of leg-parallelism calibration of Orthoglide-type
parallel machines (Pashkevich & Gomolitsky). Pure functions, no I/O."""

from orthocal.accuracy import (
    FRAMES,
    ErrorField,
    Grid,
    OptimalOffsets,
    Squareness,
    covariance_matrix,
    error_field,
    field_stats,
    fit_frame,
    optimal_offsets,
    rigid_fit,
    squareness,
    tool_error,
    workspace_grid,
)
from orthocal.budget import (
    ExpectedLackOfFit,
    Source,
    budget_sources,
    combine,
    expected_lack_of_fit,
    form_vector,
    propagation,
)
from orthocal.calibration import (
    coefficients,
    jacobian,
    linear_deviations,
    statistical_floor,
    tilt_coefficient,
)
from orthocal.geometry import (
    AXES,
    BOW_NAMES,
    FIT_NAMES,
    FORM,
    GAP_NAMES,
    MODELS,
    PARAM_NAMES,
    TILT_NAMES,
    Geometry,
)
from orthocal.identification import Identification, cannot_identify, exact_jacobian, identify
from orthocal.inputs import IdentificationError
from orthocal.kinematics import axis_directions, axis_origins, forward, inverse
from orthocal.measurement import bow_at, contact_fraction, deviation, deviations, leg_reading
from orthocal.misfit import Allowance
from orthocal.noise import coverage_factor
from orthocal.postures import plane_at, posture, posture_point
from orthocal.selection import ModelSelection, select_model
from orthocal.sensitivities import key_sensitivity, sensitivity
from orthocal.stands import StandEstimate, Stands
from orthocal.tool_interval import AfterInterval, after_interval, assumes, field_jacobian

__all__ = [
    "AXES",
    "BOW_NAMES",
    "FIT_NAMES",
    "FORM",
    "FRAMES",
    "GAP_NAMES",
    "MODELS",
    "PARAM_NAMES",
    "TILT_NAMES",
    "AfterInterval",
    "Allowance",
    "ErrorField",
    "ExpectedLackOfFit",
    "Geometry",
    "Grid",
    "Identification",
    "IdentificationError",
    "ModelSelection",
    "OptimalOffsets",
    "Source",
    "Squareness",
    "StandEstimate",
    "Stands",
    "after_interval",
    "assumes",
    "axis_directions",
    "axis_origins",
    "bow_at",
    "budget_sources",
    "cannot_identify",
    "coefficients",
    "combine",
    "contact_fraction",
    "covariance_matrix",
    "coverage_factor",
    "deviation",
    "deviations",
    "error_field",
    "exact_jacobian",
    "expected_lack_of_fit",
    "field_jacobian",
    "field_stats",
    "fit_frame",
    "form_vector",
    "forward",
    "identify",
    "inverse",
    "jacobian",
    "key_sensitivity",
    "leg_reading",
    "linear_deviations",
    "optimal_offsets",
    "plane_at",
    "posture",
    "posture_point",
    "propagation",
    "rigid_fit",
    "select_model",
    "sensitivity",
    "squareness",
    "statistical_floor",
    "tilt_coefficient",
    "tool_error",
    "workspace_grid",
]
