"""Each joint's positioning error compensated (docs/model.md, "Joint errors compensated"):
the count that puts a joint where it is wanted, the trims a controller adds to its
counts, the tool where a controller compensates with a table, and what it leaves.

A joint counted to c stands at c + ε(c, dir) (J1, with the zero error in the
kinematics). To stand at q it must be counted to

    c = q − ε(c, dir)                                                           (J5)

solved per point by fixed-point iteration (ε' is 1e-4 for a lead of 100 µm/m: each
step gains four digits). A controller that compensates a joint adds a trim
t(c) = c(q) − q to the joint it commands, per direction of motion; between a table's
targets it interpolates t linearly, as ε is between them. The direction is the joint's
own: forward while its count rises, reverse while it falls, and a joint that stands
keeps the side it came from.

Which errors each route out of the station takes into account (:data:`ROUTES`): offsets
only; the offsets and the joint tables; the kinematics and the joint tables; a
compensated program. What a route that compensates a table leaves at the tool
(:func:`joint_residual`): the table's own uncertainty, the reversal where the route does
not compensate it, and the bound of a joint that has no table. Pure: numpy in, numpy
out.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from orthocal.accuracy import DIFF_STEP, parameter_vector
from orthocal.geometry import AXES, Geometry, split_params
from orthocal.joint_count import count_vector
from orthocal.joint_error import Direction, JointErrors, JointRangeError, JointTable
from orthocal.kinematics import forward, inverse

#: What each route out of the station takes into account, in the words every export's
#: header, the statement and docs/design.md use.
ROUTES: dict[str, str] = {
    "offsets": "offsets only: each joint's zero (Δρ) in the controller's offsets; the "
               "axes' tilts and gaps and the joints' positioning errors stay at the tool",
    "offsets+tables": "the offsets and the joint tables: each joint's zero in the "
                      "controller's offsets and its positioning error, per direction, in "
                      "its compensation table; the axes' tilts and gaps stay at the tool",
    "kinematics": "the kinematics: the identified geometry in the controller's kinematics; "
                  "the joints' positioning errors stay at the tool",
    "kinematics+tables": "the kinematics and the joint tables: the identified geometry in "
                         "the controller's kinematics and each joint's positioning error, "
                         "per direction, in its compensation table",
    "program": "a compensated program: the identified geometry in the program's points, "
               "for a controller with the nominal kinematics; the joints' positioning "
               "errors stay at the tool",
    "program+tables": "a compensated program: the identified geometry and each joint's "
                      "positioning error, taken in the direction the program moves the "
                      "joint, in the program's points, for a controller with the nominal "
                      "kinematics",
}
#: The fixed point (J5) to this (mm), within this many steps.
COUNT_TOL_MM = 1e-12
COUNT_STEPS = 60
#: The 95 % half-width of a rectangular ±b is 0.95·b (GUM).
RECTANGULAR_95 = 0.95


def _span_clip(table: JointTable, c: np.ndarray) -> np.ndarray:
    """``c`` held within the table's span: a count may stand |ε| beyond the end its
    joint does not (J5), and ε there is its end's to ε'·|ε| (nanometres)."""
    a, b = table.span
    return np.clip(c, a, b)


def counted(table: JointTable, q, direction: Direction = "mean") -> np.ndarray:
    """(J5): the counts c that put the joint at ``q`` (mm) approached in ``direction``
    (one of orthocal.DIRECTIONS, or +1 / −1 / 0 per value): c = q − ε(c, dir).
    JointRangeError for a q outside the table's span; ValueError where the iteration
    does not settle (a table whose slope reaches 1 is no screw)."""
    q = np.asarray(q, dtype=float)
    c = q - table.error(q, direction)  # the joint's own position within the span, or refused
    for _ in range(COUNT_STEPS):
        new = q - table.error(_span_clip(table, c), direction)
        if np.max(np.abs(new - c), initial=0.0) <= COUNT_TOL_MM:
            return new
        c = new
    raise ValueError("the count of a joint does not settle: its table's slope is near 1")


def counted_joints(errors: JointErrors, q, direction: Direction = "mean") -> np.ndarray:
    """(J5) for the three joints at joint values ``q`` (..., 3): each joint with a table
    counted so that it stands at q; a joint without one (exact) counted at q.
    JointRangeError naming the joint where a value lies outside its table."""
    q = np.asarray(q, dtype=float)
    sides = _sides_array(direction, q.shape)
    out = q.copy()
    for i, axis in enumerate(AXES):
        table = errors.table(axis)
        if table is None:
            continue
        try:
            out[..., i] = counted(table, q[..., i], sides[..., i])
        except JointRangeError as exc:
            raise JointRangeError(f"joint {axis}: {exc}") from None
    return out


def standing(errors: JointErrors, c, direction: Direction = "mean") -> np.ndarray:
    """Where joints counted ``c`` (..., 3) stand, moving in ``direction``: c + ε(c, dir)
    (J1), ε taken at the count held within its table's span (a count stands up to
    |ε| beyond the joint's own end, (J5)); a joint without a table stands at c."""
    c = np.asarray(c, dtype=float)
    sides = _sides_array(direction, c.shape)
    out = c.copy()
    for i, axis in enumerate(AXES):
        table = errors.table(axis)
        if table is not None:
            out[..., i] = c[..., i] + table.error(_span_clip(table, c[..., i]), sides[..., i])
    return out


def _sides_array(direction: Direction, shape: tuple[int, ...]) -> np.ndarray:
    if isinstance(direction, str):
        value = {"forward": 1.0, "reverse": -1.0, "mean": 0.0}.get(direction)
        if value is None:
            raise ValueError(f"direction must be forward, reverse or mean, got {direction!r}")
        return np.full(shape, value)
    return np.broadcast_to(np.sign(np.asarray(direction, dtype=float)), shape)


@dataclass(frozen=True)
class Trims:
    """What a controller adds to a joint's count at each ``nominal_mm`` (the joint it
    is commanded, mm) moving in +ρ (``forward_mm``) and in −ρ (``reverse_mm``):
    t = c − q of (J5) at q = nominal."""

    nominal_mm: np.ndarray
    forward_mm: np.ndarray
    reverse_mm: np.ndarray


def trims(table: JointTable) -> Trims:
    """The trims at the table's own targets (J5): −ε to first order, exactly
    c(ρ_k) − ρ_k (they differ by ε'·ε, nanometres for a lead)."""
    t = table.targets_mm
    return Trims(t.copy(), counted(table, t, "forward") - t, counted(table, t, "reverse") - t)


def shifted(table: JointTable, shift_mm: float) -> JointTable:
    """The table with its targets moved by ``shift_mm`` (the deviations as they are):
    the same screw counted from another zero. A joint tested with offsets o_test and
    commanded with o_now stands on its screw where the test's target ρ + o_now − o_test
    stood: its table in the joints commanded now is shifted by −(o_now − o_test)."""
    return JointTable(table.targets_mm + float(shift_mm), table.forward_mm,
                      table.reverse_mm, table.u95_mm, table.shift_mm)



def held_ends(table: JointTable, margin_mm: float) -> JointTable:
    """``table`` held at its end values for ``margin_mm`` beyond each end (docs/model.md,
    "Joint errors compensated"): a test planned for the offsets a run started from spans
    the joints it needed then, and the offsets written since move them by up to that
    much on the screw. ε there is the end's, off by ε'·margin (0.1 µm for 100 µm/m and
    a millimetre), as a controller holds a table's end value beyond it; further out it
    is still never extrapolated."""
    if not margin_mm > 0:
        return table
    t = table.targets_mm

    def ends(a: np.ndarray) -> np.ndarray:
        return np.r_[a[0], a, a[-1]]

    return JointTable(np.r_[t[0] - margin_mm, t, t[-1] + margin_mm],
                      ends(table.forward_mm), ends(table.reverse_mm),
                      None if table.u95_mm is None else ends(table.u95_mm), table.shift_mm)

# --- the tool where a controller compensates -----------------------------------------


def table_compensated_error(points, geometry: Geometry, truth, theta_c,
                            told: JointErrors, true: JointErrors | None = None,
                            direction: Direction = "mean") -> np.ndarray:
    """E = P − p (n, 3) mm where a controller with the machine ``theta_c`` in its
    kinematics (K1) and the tables ``told`` in its joints sends the tool to ``points``:
    it counts each joint c = (J5) of ρ = IK_c(p), and the real machine ``truth``, whose
    joints err by ``true`` (None: as told), puts the tool at FK_θ(c + ε_true(c, dir)).
    With ``true`` the tables told and θ_c = θ it is zero to rounding."""
    drho_c, dL_c, tilt_c, gap_c = split_params(parameter_vector(theta_c))
    p = np.asarray(points, dtype=float)
    rho = inverse(p, geometry, drho_c, dL_c, tilt_c, gap_c)
    c = counted_joints(told, rho, direction)
    joints = (told if true is None else true).joints(c, direction)
    drho, dL, tilt, gap = split_params(parameter_vector(truth))
    return forward(joints, geometry, drho, dL, tilt, gap) - p


def joint_sensitivity(points, geometry: Geometry, theta) -> np.ndarray:
    """J = ∂P/∂ρ (n, 3, 3) of the machine ``theta`` at the joints that put its tool at
    ``points``: central differences (h = DIFF_STEP) of the exact forward kinematics.
    Column i is what a millimetre of joint i does to the tool."""
    drho, dL, tilt, gap = split_params(parameter_vector(theta))
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    rho = inverse(p, geometry, drho, dL, tilt, gap)
    out = np.empty((len(p), 3, 3))
    for i in range(3):
        step = np.zeros(3)
        step[i] = DIFF_STEP
        plus = forward(rho + step, geometry, drho, dL, tilt, gap)
        minus = forward(rho - step, geometry, drho, dL, tilt, gap)
        out[:, :, i] = (plus - minus) / (2 * DIFF_STEP)
    return out


@dataclass(frozen=True, eq=False)
class JointResidual:
    """What the joints leave at the tool where a route compensates their tables
    (:func:`joint_residual`): per point and joint the half-width left (``halfwidth_mm``
    (n, 3), at 95 % where it is a table's uncertainty, a bound where it is a reversal or
    an assumed joint) and its ``standard_mm`` (n, 3), the sensitivity ``J`` (n, 3, 3);
    per point the bound at the tool ``bound_mm`` (n,), the largest |J·δ| over
    |δ_i| ≤ half-width, and the standard uncertainty ``standard_tool_mm`` (n,),
    sqrt(Σ_i |J_i|²·u_i²); and their RMS and max over the points."""

    halfwidth_mm: np.ndarray
    standard_mm: np.ndarray
    J: np.ndarray
    bound_mm: np.ndarray
    standard_tool_mm: np.ndarray

    @property
    def bound_rms_mm(self) -> float:
        return float(np.sqrt(np.mean(self.bound_mm**2)))

    @property
    def bound_max_mm(self) -> float:
        return float(np.max(self.bound_mm))

    @property
    def standard_rms_mm(self) -> float:
        return float(np.sqrt(np.mean(self.standard_tool_mm**2)))


def joint_error_columns(rho, tables: JointErrors,
                        bounds_um_per_m: Sequence[float | None], pi0_mm: float
                        ) -> tuple[np.ndarray, tuple[str, ...]]:
    """The joints' errors at joint values ``rho`` (n, 3) that a statement of the tool
    draws in the truth, as bounded inputs each uniform in ±1 (docs/model.md, "The tool
    with the joints' errors"), columns (3n × m: each input's error of every point's
    joints, x, y, z of each point, mm) and their names:

    - a joint with a table whose uncertainty is known: ±U_i(ρ), its expanded
      uncertainty interpolated, one input (a test's uncertainty is mostly its scale,
      the same sign along the travel, (J3));
    - a joint without a table and a bound b (µm/m in ``bounds_um_per_m``): a lead
      within ±b from Π0, b·(ρ − L) (``pi0_mm`` = L), one input."""
    rho = np.asarray(rho, dtype=float).reshape(-1, 3)
    if len(bounds_um_per_m) != 3:
        raise ValueError("bounds_um_per_m: one per joint (x, y, z)")
    cols, names = [], []
    for i, axis in enumerate(AXES):
        table, b = tables.table(axis), bounds_um_per_m[i]
        col = np.zeros_like(rho)
        if table is not None:
            if table.u95_mm is None or not np.any(table.u95_mm):
                continue
            a, z = table.span
            col[:, i] = np.interp(np.clip(rho[:, i], a, z), table.targets_mm, table.u95_mm)
            names.append(f"joint {axis} table")
        elif b:
            col[:, i] = 1e-6 * float(b) * (rho[:, i] - pi0_mm)
            names.append(f"joint {axis} lead")
        else:
            continue
        cols.append(col.ravel())
    return (np.column_stack(cols) if cols else np.zeros((rho.size, 0))), tuple(names)


_CORNERS = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [1, -1, -1]], dtype=float)


def _joint_left(table: JointTable | None, rho: np.ndarray, reversal: bool,
                bound_um_per_m: float | None, pi0_mm: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """(half-width, standard uncertainty) one joint leaves at joint values ``rho``."""
    if table is None:
        b = 0.0 if bound_um_per_m is None else 1e-6 * float(bound_um_per_m)
        reach = b * np.abs(rho - pi0_mm)  # rectangular ±b·|ρ − L|
        return RECTANGULAR_95 * reach, reach / np.sqrt(3.0)
    a, z = table.span
    at = np.clip(rho, a, z)  # a table is never extrapolated; the plan checks its span
    u95 = np.zeros_like(at) if table.u95_mm is None else np.interp(at, table.targets_mm,
                                                                   table.u95_mm)
    half, std = u95, u95 / 2.0  # an expanded uncertainty at 95 %, k = 2
    if not reversal:  # the side unknown: the middle of the band, ±B/2 rectangular
        band = 0.5 * np.abs(np.interp(at, table.targets_mm, table.reversal_mm))
        half, std = half + band, np.sqrt(std**2 + band**2 / 3.0)
    return half, std


def joint_residual(points, geometry: Geometry, theta_c, tables: JointErrors,
                   reversal_compensated: bool | Sequence[bool] = True,
                   bounds_um_per_m: Sequence[float | None] = (None, None, None)
                   ) -> JointResidual:
    """What the joints leave at the tool ``points`` (n, 3) mm where a route compensates
    the joints' ``tables`` with the machine ``theta_c`` in the controller (J7):

    - a joint with a table: its expanded uncertainty U_i(ρ) (interpolated; 0 where the
      test gave none), and where ``reversal_compensated`` is False for it (a side not
      known) ±B_i(ρ)/2 more, B_i = |forward − reverse|;
    - a joint without one: nothing compensated, its bound b_i·|ρ − L| (µm/m in
      ``bounds_um_per_m``, rectangular: 0.95·b at 95 %).

    At the tool δP = J·δρ (J: :func:`joint_sensitivity` at ρ = IK_c(p)), so the bound
    at each point is max |J·δ| over the box |δ_i| ≤ w_i, found at a corner."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    drho, dL, tilt, gap = split_params(parameter_vector(theta_c))
    rho = inverse(p, geometry, drho, dL, tilt, gap)
    flags = [reversal_compensated] * 3 if isinstance(reversal_compensated, bool) \
        else [bool(v) for v in reversal_compensated]
    if len(flags) != 3 or len(bounds_um_per_m) != 3:
        raise ValueError("reversal_compensated and bounds_um_per_m: one per joint (x, y, z)")
    half, std = np.empty_like(rho), np.empty_like(rho)
    for i, axis in enumerate(AXES):
        half[:, i], std[:, i] = _joint_left(tables.table(axis), rho[:, i], flags[i],
                                            bounds_um_per_m[i], geometry.leg_length)
    J = joint_sensitivity(p, geometry, theta_c)
    return JointResidual(half, std, J, *_at_tool(J, half, std))


def _at_tool(J: np.ndarray, half: np.ndarray, std: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Per point, what joints off by up to ``half`` (n, 3), with standard uncertainties
    ``std`` (n, 3), do at the tool through J (n, 3, 3): the bound max |J·δ| over the
    box |δ_i| ≤ half_i (at a corner; ±δ alike, so four corners), and
    sqrt(Σ_i |J_i|²·std_i²)."""
    corners = np.einsum("nij,cj,nj->nci", J, _CORNERS, half)  # (n, 4, 3)
    bound = np.sqrt(np.max(np.sum(corners**2, axis=-1), axis=1))
    return bound, np.sqrt(np.einsum("nij,nj->n", J**2, std**2))


def count_at_tool(points, geometry: Geometry, count_mm: Sequence[float] | np.ndarray
                  ) -> tuple[float, float]:
    """What the drive's count does at the tool of the nominal machine over ``points``
    (N, 3), mm (docs/model.md (J17)): a point between counts is reached with each joint
    up to c_j/2 off (J15), uniform, so the tool stands δP = J·δρ off. Returns (RMS of
    the standard |δP|, E|δP|² = Σ_j |J_j|²·c_j²/12; the largest bound, at a corner of
    ±c/2) over the points. At P = 0, J = I: c/2 and c·√3/2 for three equal counts.

    J is the nominal machine's in closed form, the inverse of ∂ρ/∂p of
    ρ_i = p_i + sqrt(L² − p_j² − p_k²), not :func:`joint_sensitivity`'s central
    differences (2e-10 off at P = 0): the check values are exact."""
    p = np.atleast_2d(np.asarray(points, dtype=float))
    c = count_vector(count_mm)
    L2 = geometry.leg_length ** 2
    m = np.empty((len(p), 3, 3))
    for i in range(3):
        j, k = [n for n in range(3) if n != i]
        root = np.sqrt(L2 - p[:, j] ** 2 - p[:, k] ** 2)
        m[:, i, i] = 1.0
        m[:, i, j] = -p[:, j] / root
        m[:, i, k] = -p[:, k] / root
    J = np.linalg.inv(m)  # ∂P/∂ρ
    half = np.broadcast_to(c / 2.0, p.shape)
    bound, std = _at_tool(J, half, np.broadcast_to(c / np.sqrt(12.0), p.shape))
    return float(np.sqrt(np.mean(std**2))), float(np.max(bound))
