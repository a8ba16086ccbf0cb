"""How well the after-figures of accuracy at the tool are known (docs/model.md,
"Accuracy at the tool" and "Intervals at the tool"): the RMS and max of the field
left once offsets are written, with 95 % intervals by Monte Carlo over the inputs'
joint distribution (orthocal.field_mc), and the words that say what such a figure
takes as known (``assumes``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from orthocal.accuracy import (
    DIFF_STEP,
    FRAMES,
    ErrorField,
    covariance_matrix,
    error_field,
    fitted_field,
    offset_vector,
    parameter_vector,
    tool_error,
)
from orthocal.field_mc import (
    Bounded,
    active_columns,
    field_inputs,
    figures,
    parameter_inputs,
)
from orthocal.geometry import MODELS, PARAM_NAMES, TILT_NAMES, Geometry
from orthocal.joint_error import Direction, JointErrors

# --- uncertainty of the after-field --------------------------------------------------


@dataclass(frozen=True, eq=False)
class AfterInterval:
    """The after-field: ``field`` the plug-in at the estimate, ``rms_mm`` and
    ``max_mm`` the figures stated for the true machine and their 95 % intervals
    (mm; see :func:`after_interval`)."""

    field: ErrorField
    rms_mm: float
    max_mm: float
    rms_interval_mm: tuple[float, float]
    max_interval_mm: tuple[float, float]
    level: float
    dof: float | None
    method: str

    def to_dict(self) -> dict[str, object]:
        """docs/design.md's ``"after"`` object."""
        return {"rms_mm": self.rms_mm, "max_mm": self.max_mm,
                "rms_interval_95_mm": list(self.rms_interval_mm),
                "max_interval_95_mm": list(self.max_interval_mm)}


def field_jacobian(points, geometry: Geometry, params, offsets, frame: str,
                   columns: Sequence[int], joint_errors: JointErrors | None = None,
                   direction: Direction = "mean") -> np.ndarray:
    """∂ fit_frame(E)/∂θ_c (3n × len(columns), mm per mm or mrad), central
    differences (h = 1e-4) of the exact model at ``params``, offsets fixed;
    ``joint_errors`` and ``direction`` as for orthocal.accuracy.tool_error."""
    p = np.asarray(points, dtype=float)
    theta = parameter_vector(params)
    o = offset_vector(offsets)
    G = np.empty((p.size, len(columns)))
    for k, c in enumerate(columns):
        step = np.zeros(len(PARAM_NAMES))
        step[c] = DIFF_STEP
        plus = fitted_field(p, geometry, theta + step, o, frame, joint_errors, direction)
        minus = fitted_field(p, geometry, theta - step, o, frame, joint_errors, direction)
        G[:, k] = (plus - minus).ravel() / (2 * DIFF_STEP)
    return G


def joint_jacobian(points, geometry: Geometry, params, offsets,
                   joint_errors: JointErrors | None = None,
                   direction: Direction = "mean") -> np.ndarray:
    """∂E_k/∂q_k (n, 3, 3): the tool's raw error (before the frame) at each point per
    error of its counted joints (a joint off by e at that point moves the carriage as
    Δρ does there), central differences of the exact model at ``params``
    (``joint_errors`` and ``direction`` as for orthocal.accuracy.tool_error)."""
    p = np.asarray(points, dtype=float)
    theta = parameter_vector(params)
    o = offset_vector(offsets)
    J = np.empty((len(p), 3, 3))
    for i in range(3):
        step = np.zeros(len(PARAM_NAMES))
        step[i] = DIFF_STEP
        J[:, :, i] = (tool_error(p, geometry, theta + step, o, joint_errors, direction)
                      - tool_error(p, geometry, theta - step, o, joint_errors, direction)
                      ) / (2 * DIFF_STEP)
    return J


def _law(dof: float | None) -> str:
    return "normal" if dof is None or not np.isfinite(dof) else f"Student t, {dof:g} dof"


def after_interval(params, covariance, dof: float | None, offsets, points,
                   geometry: Geometry | None = None, frame: str = "translation",
                   names: Sequence[str] | None = None, level: float = 0.95,
                   draws: int = 4000, seed: int = 0, *, systematic=None,
                   bounded: Bounded | Sequence[Bounded] = (), field_draws=None,
                   joint_draws=None, in_truth: Sequence[str] = (),
                   joint_errors: JointErrors | None = None,
                   direction: Direction = "mean") -> AfterInterval:
    """RMS and max of |E| of the field of the TRUE machine θ with ``offsets`` o
    written, over ``points``, after ``frame``, and their ``level`` (95 %) intervals,
    from the estimate θ̂ = ``params`` and the joint distribution of its error δ =
    θ̂ − θ (docs/model.md, "Intervals at the tool"; orthocal.field_mc):

    - ``covariance`` Σ (9×9 or 12×12 with zeros where not estimated, a dict by name,
      or k×k with ``names``: :func:`covariance_matrix`) with ``dof`` (Student t, one
      χ² per draw; None: normal): the statistical part;
    - ``systematic``: a systematic part known by its covariance alone (any form
      :func:`covariance_matrix` takes; normal, infinite dof);
    - ``bounded``: bounded systematic inputs over the parameters (a :class:`Bounded`
      or several; each input uniform in ±its bound), e.g. the legs' form through
      the fit's sensitivity (orthocal.budget.form_columns);
    - ``field_draws``, ``joint_draws``: errors of the true machine the estimate does
      not hold, drawn per draw: the tool's raw error (before the frame), and the
      counted joints' positioning error ε at each point's joints (through
      :func:`joint_jacobian`); each a callable ``(rng, draws) -> (draws, n, 3)`` mm, a
      :class:`Bounded` over the 3n values (x, y, z of each point), or a list of them.
      A draw of joint tables (orthocal.joint_error.JointErrors, one per draw) is
      ``lambda rng, d: np.stack([draw(rng).error(x, direction) for _ in range(d)])``
      with x the points' joint inputs IK_nominal(p) + o;
    - ``joint_errors``, ``direction``: the joints' tables as known, in the plug-in and
      the Jacobians (orthocal.accuracy.tool_error; None: exact joints);
    - ``in_truth``: the parameters (names) whose error is the true machine's, not the
      plug-in's: their value in ``params`` is an aim this estimate was used to reach
      (offsets written from it, no verification since: Δρ's names). The others'
      error is in the plug-in, whose norm it biases upward, and the interval inverts
      the plug-in's noncentral distribution there (orthocal.field_mc).

    The field is linear in δ over the draws' size (F(θ̂ − δ) = F(θ̂) − G·δ, G =
    :func:`field_jacobian`; docs/model.md states the tolerance against the exact
    model). The same call states the before-figures: θ̂ at the start, o = 0.

    A parameter no input moves is taken as exactly the value in ``params``;
    :func:`assumes` says so. When the model test kept 'rho', the tilts it could not
    see can be carried by giving the rho+tilt fit's tilt block of Σ with the tilts at
    0 in ``params``."""
    geometry = geometry or Geometry()
    theta = parameter_vector(params)
    cov = covariance_matrix(covariance, names)
    sys_cov = None if systematic is None else covariance_matrix(systematic)
    kept = [bounded] if isinstance(bounded, Bounded) else list(bounded)
    for c in (cov, sys_cov):
        if c is not None and not np.all(np.isfinite(c)):
            raise ValueError("covariance has non-finite entries")
    p = np.asarray(points, dtype=float)
    o = offset_vector(offsets)
    fld = error_field(p, geometry, theta, o, frame, joint_errors, direction)
    columns = active_columns(cov, sys_cov, kept)
    G = field_jacobian(p, geometry, theta, o, frame, columns, joint_errors, direction)
    fields = field_inputs(p, frame, field_draws, joint_draws, lambda: joint_jacobian(
        p, geometry, theta, o, joint_errors, direction))
    unknown = set(in_truth) - set(PARAM_NAMES)
    if unknown:
        raise ValueError(f"in_truth: unknown parameter name(s) {sorted(unknown)}")
    inputs = parameter_inputs(G, columns, cov, dof, systematic=sys_cov, bounded=kept,
                              fields=fields,
                              observed=[n not in in_truth for n in PARAM_NAMES])
    fig = figures(fld.field, inputs, level, draws, seed)
    return AfterInterval(
        field=fld, rms_mm=fig.rms_mm, max_mm=fig.max_mm,
        rms_interval_mm=fig.rms_interval_mm, max_interval_mm=fig.max_interval_mm,
        level=level, dof=None if dof is None or not np.isfinite(dof) else float(dof),
        method=("Monte Carlo over the inputs' joint distribution (GUM Supplement 1), the "
                f"field linearised ({_law(dof)}; bounded inputs rectangular; {draws} draws); "
                "the interval inverts the plug-in's noncentral distribution, so it reaches "
                "a field near zero"))


# --- what the figure takes as known ---------------------------------------------------


def assumes(model: str, frame: str = "translation", tilt_interval: Mapping | None = None,
            postures_per_leg: int = 2, dof: float | None = None,
            tilts_in_interval: bool = False) -> list[str]:
    """In words, what an accuracy figure computed from a fit of ``model`` (a key
    of MODELS) takes as known (docs/model.md, "Accuracy at the tool": "what the figure
    cannot know must be said with it"). ``tilt_interval``: {tilt name: (lo, hi)
    mrad}, the 95 % intervals of a rho+tilt fit when the model selection kept a
    model without tilts; ``postures_per_leg``: test stops per leg (ΔL beside the
    tilts needs more than two); ``dof``: of the covariance behind the interval;
    ``tilts_in_interval``: the caller gave :func:`after_interval` the rho+tilt fit's
    tilt covariance (tilts at 0 in the estimate), so the intervals include them."""
    if model not in MODELS:
        raise ValueError(f"model must be one of {sorted(MODELS)}, got {model!r}")
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    cols = set(MODELS[model])
    out: list[str] = []
    if not cols & {0, 1, 2}:
        out.append(f"Δρ = 0 (joint zero errors not in model {model!r})")
    if not cols & {3, 4, 5}:
        if cols & {6, 7, 8} and postures_per_leg <= 2:
            why = "not identifiable beside the tilts from two postures per leg"
        elif cols & {6, 7, 8}:
            why = f"not in model {model!r}"
        else:
            why = f"not in model {model!r}; beside Δρ it is nearly inseparable (model 'full')"
        out.append(f"ΔL = 0 (leg lengths nominal; {why}); a leg 0.1 mm long changes the field")
    if not cols & {6, 7, 8}:
        if tilt_interval:
            spans = ", ".join(f"{nm} [{float(tilt_interval[nm][0]):.3g}, "
                              f"{float(tilt_interval[nm][1]):.3g}]"
                              for nm in TILT_NAMES if nm in tilt_interval)
            tail = ("the intervals include that uncertainty" if tilts_in_interval
                    else "which the figure leaves out")
            out.append(f"tilts = 0 (axes square; model {model!r} was kept): the rho+tilt fit "
                       f"puts them within {spans} mrad (95 %), {tail}")
        else:
            out.append(f"tilts = 0 (actuator axes square; not in model {model!r})")
    out.append("otherwise the machine of model (1'): rigid links, ideal joints and "
               "parallelograms, encoders exact up to their zero")
    if frame == "translation":
        out.append("frame 'translation': the tool offset is set by touching off "
                   "(the mean error is removed)")
    else:
        out.append("frame 'rigid': parts are aligned by probing "
                   "(the least-squares rigid motion is removed)")
    law = f"Student t with {dof:g} dof" if dof is not None and np.isfinite(dof) else "normal"
    out.append(f"the 95 % intervals propagate the fit's covariance ({law}) through the exact "
               "model, linearised, by Monte Carlo, and hold only under the assumptions above")
    return out
