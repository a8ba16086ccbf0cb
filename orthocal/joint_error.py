"""Each joint's positioning error ε_i(ρ, direction) (docs/model.md, "Joint positioning
errors").

A drive counts its motor; the carriage stands where the screw (a belt, a rack)
puts it. With the offsets o changed since the joint was tested and Δρ its zero
error, the true joint of model (1') is

    q_i = ρ_i + o_i + Δρ_i + ε_i(ρ_i + o_i, dir_i)                               (J1)

ε_i is a table over the joint's travel (:class:`JointTable`): targets ρ_k (the
joint coordinate as the station commands it, absolute, Π0 at ρ = L), the error
approached in +ρ (``forward``) and in −ρ (``reverse``), actual − target as ISO
230-2 defines it, with an expanded (95 %) uncertainty per point where known.
Between targets ε is interpolated linearly; outside the table's span it is an
error (:class:`JointRangeError`), never extrapolated. A table is referred to Π0:
its bidirectional mean at ρ = L is 0 (a constant is Δρ's, which the
identification takes); a table given with a constant is shifted and says by how
much (``shift_mm``).

Directions: ``"forward"``, ``"reverse"``, ``"mean"`` (the bidirectional mean, the
middle of the band, to which Δρ refers), or an array of +1 / −1 / 0 per joint
value (each point reached from a stated side). Lengths in mm; leads in µm/m.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from orthocal.geometry import AXES, Geometry, split_params
from orthocal.joint_count import JointModel
from orthocal.measurement import Key, check_key, deviations, leg_reading
from orthocal.noise import coverage_factor
from orthocal.postures import plane_offset, posture, split_plane, stroke, tilt

#: The named directions: approached in +ρ, in −ρ, and their mean.
DIRECTIONS: tuple[str, str, str] = ("forward", "reverse", "mean")
#: What a direction may be: one of DIRECTIONS, or +1 / −1 / 0 per joint value.
Direction = str | np.ndarray | Sequence[float]
# How far beyond a table's ends a joint value still counts as inside (mm): the
# rounding of an inverse kinematics that lands on an end of the span.
_EDGE_MM = 1e-9


class JointRangeError(ValueError):
    """A joint value outside its table's span: a table is never extrapolated."""


def _sides(direction: Direction, shape: tuple[int, ...]) -> np.ndarray:
    """+1 / −1 / 0 per joint value from a named direction or an array of them."""
    if isinstance(direction, str):
        if direction not in DIRECTIONS:
            raise ValueError(f"direction must be one of {DIRECTIONS} or an array of "
                             f"+1/-1/0, got {direction!r}")
        return np.full(shape, {"forward": 1.0, "reverse": -1.0, "mean": 0.0}[direction])
    sides = np.sign(np.broadcast_to(np.asarray(direction, dtype=float), shape))
    if not np.all(np.isfinite(sides)):
        raise ValueError("a direction array must hold +1, -1 or 0")
    return sides


@dataclass(frozen=True, eq=False)
class JointTable:
    """ε of one joint over its travel (mm): ``targets_mm`` strictly increasing,
    ``forward_mm`` approached in +ρ, ``reverse_mm`` in −ρ, ``u95_mm`` the expanded
    (95 %) uncertainty per point (None: not known); ``shift_mm``: the constant
    taken out to refer the table to Π0 (the table as given is this one plus it)."""

    targets_mm: np.ndarray
    forward_mm: np.ndarray
    reverse_mm: np.ndarray
    u95_mm: np.ndarray | None = None
    shift_mm: float = 0.0

    def __post_init__(self) -> None:
        arrays = {n: np.array(getattr(self, n), dtype=float)
                  for n in ("targets_mm", "forward_mm", "reverse_mm")}
        if self.u95_mm is not None:
            arrays["u95_mm"] = np.array(self.u95_mm, dtype=float)
        t = arrays["targets_mm"]
        for name, a in arrays.items():
            if a.ndim != 1 or a.shape != t.shape:
                raise ValueError(f"{name} must be one value per target ({t.size}), got "
                                 f"shape {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name} must be finite numbers")
            a.flags.writeable = False
            object.__setattr__(self, name, a)
        if t.size < 2 or not np.all(np.diff(t) > 0):
            raise ValueError("targets_mm must be at least two, strictly increasing")
        if self.u95_mm is not None and np.any(arrays["u95_mm"] < 0):
            raise ValueError("u95_mm must be >= 0")
        if not math.isfinite(self.shift_mm):
            raise ValueError("shift_mm must be finite")

    @property
    def span(self) -> tuple[float, float]:
        """(first target, last target), mm."""
        return float(self.targets_mm[0]), float(self.targets_mm[-1])

    @property
    def mean_mm(self) -> np.ndarray:
        """The bidirectional mean (forward + reverse)/2 per target."""
        return 0.5 * (self.forward_mm + self.reverse_mm)

    @property
    def reversal_mm(self) -> np.ndarray:
        """forward − reverse per target: −B for a dead band of width B."""
        return self.forward_mm - self.reverse_mm

    def covers(self, lo: float, hi: float) -> bool:
        """Whether the table spans [lo, hi] (mm)."""
        a, b = self.span
        return a <= lo + _EDGE_MM and hi - _EDGE_MM <= b

    def error(self, rho, direction: Direction = "mean") -> np.ndarray:
        """ε(ρ, direction), mm, linear between targets (docs/model.md (J1)).
        JointRangeError where a ρ lies outside the span."""
        rho = np.asarray(rho, dtype=float)
        a, b = self.span
        outside = (rho < a - _EDGE_MM) | (rho > b + _EDGE_MM) | ~np.isfinite(rho)
        if np.any(outside):
            bad = float(np.asarray(rho)[outside].flat[0])
            raise JointRangeError(f"ρ = {bad:.3f} mm is outside the table's span "
                                  f"[{a:.3f}, {b:.3f}] mm")
        sides = _sides(direction, rho.shape)
        t = self.targets_mm
        out = np.interp(rho, t, self.mean_mm)
        if np.any(sides != 0):
            half = 0.5 * np.interp(rho, t, self.reversal_mm)
            out = out + sides * half
        return out

    def referred_to_pi0(self, pi0_mm: float) -> JointTable:
        """This table shifted so that its bidirectional mean at ρ = ``pi0_mm`` (L) is 0;
        the constant joins ``shift_mm``."""
        c = float(self.error(pi0_mm, "mean"))
        if c == 0.0:
            return self
        return replace(self, forward_mm=self.forward_mm - c, reverse_mm=self.reverse_mm - c,
                       shift_mm=self.shift_mm + c)

    def with_reversal(self, b_mm: float) -> JointTable:
        """This table's bidirectional mean with a dead band of width ``b_mm`` at every
        target: forward = mean − B/2, reverse = mean + B/2 (the measured B wins over
        a table's own reversal: docs/model.md, "Joint positioning errors")."""
        if not (math.isfinite(b_mm) and b_mm >= 0):
            raise ValueError(f"a reversal B must be >= 0 mm, got {b_mm}")
        m = self.mean_mm
        return replace(self, forward_mm=m - 0.5 * b_mm, reverse_mm=m + 0.5 * b_mm)


# --- constructors --------------------------------------------------------------------


def iso230_table(targets_mm, forward_um, reverse_um, u95_um=None,
                 pi0_mm: float | None = None) -> JointTable:
    """The table of an ISO 230-2 test (a laser interferometer's, or any): targets in
    mm, deviations actual − target in µm approached in +ρ and in −ρ, the test's
    expanded uncertainty (95 %) per point in µm where given; referred to Π0 when
    ``pi0_mm`` (L) is given (``shift_mm`` says by how much)."""
    table = JointTable(np.asarray(targets_mm, dtype=float),
                       1e-3 * np.asarray(forward_um, dtype=float),
                       1e-3 * np.asarray(reverse_um, dtype=float),
                       None if u95_um is None else 1e-3 * np.asarray(u95_um, dtype=float))
    return table if pi0_mm is None else table.referred_to_pi0(pi0_mm)


def _grid(span_mm: Sequence[float], step_mm: float) -> np.ndarray:
    lo, hi = (float(v) for v in span_mm)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ValueError(f"span must be [lo, hi] with lo < hi, got {span_mm}")
    if not (math.isfinite(step_mm) and step_mm > 0):
        raise ValueError(f"step must be > 0 mm, got {step_mm}")
    return np.linspace(lo, hi, max(2, math.ceil((hi - lo) / step_mm) + 1))


def screw_table(span_mm: Sequence[float], home_mm: float, lead_um_per_m: float = 0.0,
                pitch_um: float = 0.0, pitch_period_mm: float | None = None,
                step_mm: float | None = None) -> JointTable:
    """A screw's ε over ``span_mm`` for a drive homed at ρ = ``home_mm``, the same
    both ways (its play is the reversal's, :meth:`JointTable.with_reversal`):

        ε(ρ) = k·1e-6·(ρ − ρ_h) + A·1e-3·sin(2π·(ρ − ρ_h)/P)                       (J2)

    k = ``lead_um_per_m``, A = ``pitch_um``, P = ``pitch_period_mm``. Targets every
    ``step_mm`` (default 10 mm, P/64 with a periodic term: its interpolation is then
    within 0.13 % of A). Homed at Π0 (ρ_h = L) the table is referred to Π0."""
    if pitch_um and not (pitch_period_mm is not None and math.isfinite(pitch_period_mm)
                         and pitch_period_mm > 0):
        raise ValueError(f"a periodic error needs a period > 0 mm, got {pitch_period_mm}")
    if step_mm is None:
        step_mm = pitch_period_mm / 64.0 if pitch_um and pitch_period_mm else 10.0
    t = _grid(span_mm, step_mm)
    e = 1e-6 * float(lead_um_per_m) * (t - home_mm)
    if pitch_um:
        assert pitch_period_mm is not None  # checked above
        e = e + 1e-3 * float(pitch_um) * np.sin(2.0 * np.pi * (t - home_mm) / pitch_period_mm)
    return JointTable(t, e, e.copy())


def lead_table(lead_um_per_m: float, span_mm: Sequence[float], home_mm: float,
               step_mm: float = 10.0) -> JointTable:
    """A pure lead error, ε(ρ) = k·1e-6·(ρ − ρ_h) (J2); linear, so interpolating it is
    exact."""
    return screw_table(span_mm, home_mm, lead_um_per_m=lead_um_per_m, step_mm=step_mm)


def pitch_table(pitch_um: float, pitch_period_mm: float, span_mm: Sequence[float],
                home_mm: float) -> JointTable:
    """A periodic (pitch) error of amplitude A µm and period P mm alone (J2)."""
    return screw_table(span_mm, home_mm, pitch_um=pitch_um, pitch_period_mm=pitch_period_mm)


# --- the lead a table shows ----------------------------------------------------------


@dataclass(frozen=True)
class Lead:
    """A table's lead (µm/m): the least-squares slope of its bidirectional mean over
    its span, and its 95 % interval (docs/model.md (J3)): ``points_um_per_m`` the
    half-width the points' uncertainty makes, ``scatter_um_per_m`` the slope's
    standard error from the residual scatter on ``dof`` degrees of freedom."""

    value_um_per_m: float
    interval_95_um_per_m: tuple[float, float]
    points_um_per_m: float
    scatter_um_per_m: float
    dof: int
    residual_rms_um: float


def lead_um_per_m(table: JointTable) -> Lead:
    """The lead of ``table`` (J3): slope k̂ = Σ d_k·m_k / Σ d_k², d_k = ρ_k − ρ̄, of the
    bidirectional mean m; half-width of its 95 % interval
    sqrt(U_p² + (t₀.₉₇₅,ₙ₋₂·s/√Σd²)²) with U_p = Σ|d_k|·U_k / Σd² (the points'
    expanded uncertainties taken as correlated in the worst way: a test's
    uncertainty is mostly its scale, the same at every point) and s the RMS of the
    residuals about the line on n − 2 dof (none with two points)."""
    t, m = table.targets_mm, table.mean_mm
    d = t - t.mean()
    sxx = float(d @ d)
    slope = float(d @ m) / sxx
    resid = m - m.mean() - slope * d
    dof = t.size - 2
    s = math.sqrt(float(resid @ resid) / dof) if dof > 0 else 0.0
    se = s / math.sqrt(sxx)
    scatter = coverage_factor(dof) * se if dof > 0 else 0.0
    points = 0.0 if table.u95_mm is None else float(np.abs(d) @ table.u95_mm) / sxx
    half = 1e6 * math.hypot(points, scatter)
    k = 1e6 * slope
    return Lead(k, (k - half, k + half), 1e6 * points, 1e6 * se, dof,
                1e3 * math.sqrt(float(np.mean(resid**2))))


# --- the three joints ----------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class JointErrors:
    """ε of the three joints: a :class:`JointTable` per joint, or None for a joint
    taken as exact."""

    x: JointTable | None = None
    y: JointTable | None = None
    z: JointTable | None = None

    @classmethod
    def of(cls, tables: Mapping[str, JointTable | None]) -> JointErrors:
        """From a mapping axis → table (axes left out: exact)."""
        unknown = set(tables) - set(AXES)
        if unknown:
            raise ValueError(f"unknown joint(s) {sorted(unknown)}: expected x, y, z")
        return cls(**{a: tables.get(a) for a in AXES})

    @classmethod
    def screws(cls, geometry: Geometry, span_mm: Sequence[float],
               lead_um_per_m: Sequence[float] = (0.0, 0.0, 0.0), pitch_um: float = 0.0,
               pitch_period_mm: float | None = None) -> JointErrors:
        """Three screws (J2) homed at Π0 (ρ_h = L), the same periodic error on each, one
        ``span_mm`` for all: the simulator's joints (drivers.sim.screws)."""
        k = [float(v) for v in lead_um_per_m]
        if len(k) != 3:
            raise ValueError(f"expected 3 leads (x, y, z), got {lead_um_per_m!r}")
        return cls(*(screw_table(span_mm, geometry.leg_length, v, pitch_um, pitch_period_mm)
                     for v in k))

    def table(self, axis: str) -> JointTable | None:
        return {"x": self.x, "y": self.y, "z": self.z}[axis]

    def error(self, rho, direction: Direction = "mean") -> np.ndarray:
        """ε of each joint at joint values ``rho`` (..., 3), mm; 0 where exact.
        JointRangeError naming the joint where a value is outside its table."""
        rho = np.asarray(rho, dtype=float)
        sides = _sides(direction, rho.shape)
        out = np.zeros_like(rho)
        for i, axis in enumerate(AXES):
            table = self.table(axis)
            if table is None:
                continue
            try:
                out[..., i] = table.error(rho[..., i], sides[..., i])
            except JointRangeError as exc:
                raise JointRangeError(f"joint {axis}: {exc}") from None
        return out

    def joints(self, rho, direction: Direction = "mean") -> np.ndarray:
        """ρ + ε(ρ, direction): where the joints stand for joint inputs ``rho`` (J1,
        the zero error Δρ aside: the kinematics adds it)."""
        rho = np.asarray(rho, dtype=float)
        return rho + self.error(rho, direction)


# --- the travel a table must span ----------------------------------------------------


def workspace_joint_range(box, geometry: Geometry) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's range (lo, hi), mm, over the workspace box [[xmin, xmax], …]
    through the nominal inverse kinematics, exact: ρ_i = p_i + sqrt(L² − p_j² − p_k²)
    is least at p_i's least with |p_j|, |p_k| largest and greatest at p_i's greatest
    with |p_j|, |p_k| least. ValueError where the box leaves a leg's reach."""
    b = np.asarray(box, dtype=float)
    if b.shape != (3, 2) or np.any(b[:, 1] < b[:, 0]):
        raise ValueError(f"box must be [[xmin, xmax], [ymin, ymax], [zmin, zmax]], got {box}")
    far = np.max(np.abs(b), axis=1) ** 2
    near = np.where((b[:, 0] <= 0) & (b[:, 1] >= 0), 0.0, np.min(np.abs(b), axis=1)) ** 2
    L2 = geometry.leg_length**2
    lo, hi = np.empty(3), np.empty(3)
    for i in range(3):
        j, k = [n for n in range(3) if n != i]
        if L2 - far[j] - far[k] < 0:
            raise ValueError("the workspace box leaves a leg's reach")
        lo[i] = b[i, 0] + math.sqrt(L2 - far[j] - far[k])
        hi[i] = b[i, 1] + math.sqrt(L2 - near[j] - near[k])
    return lo, hi


def posture_joint_range(geometry: Geometry, strokes: Sequence[float] | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's range (lo, hi), mm, over Π0 and the test postures Π_i(s) of
    ``strokes`` (None: the paper's two, ρmin and ρmax): L + s on joint i, L·cos α on
    the other two (docs/model.md, "Test postures")."""
    L = geometry.leg_length
    s = [geometry.rho_min, geometry.rho_max] if strokes is None else [float(v) for v in strokes]
    widest = max(abs(v) for v in s)
    lo = min(L + min(s), L * math.cos(math.asin(widest / L)))
    hi = max(L + max(s), L)
    return np.full(3, lo), np.full(3, hi)


# --- what the gauges see -------------------------------------------------------------


def joint_error_deviations(keys: Sequence[Key], geometry: Geometry, params,
                           errors: JointModel, direction: Direction = "forward",
                           mount_offsets=None) -> np.ndarray:
    """Exact deviations Δ^s_{i,j} of a machine whose joints err by ``errors``: each
    reading at the joints ρ + ε(ρ, direction) of its test posture, less the one at
    Π0's (every stop approached from one side: ``"forward"`` from below, the
    station's default). ``params``: 12-, 9- or 6-vector of PARAM_NAMES;
    ``mount_offsets`` as for :func:`orthocal.deviations`. With ε = 0 this is
    :func:`orthocal.deviations` to rounding."""
    drho, dL, tilt_v, gap = split_params(params)
    offsets = np.zeros(len(keys)) if mount_offsets is None else \
        np.asarray(mount_offsets, dtype=float).reshape(-1)
    if offsets.shape != (len(keys),):
        raise ValueError(f"mount_offsets needs one value per key ({len(keys)})")
    rho0 = errors.joints(posture("0", None, geometry), direction)
    out = np.empty(len(keys))
    for n, key in enumerate(keys):
        sign, leg, along = check_key(key)
        rho = errors.joints(posture(sign, leg, geometry), direction)
        mount = geometry.mount_plane + plane_offset(sign, geometry) + offsets[n]
        read = [leg_reading(r, leg, along, geometry, drho, dL, mount, tilt_v, gap=gap)
                for r in (rho, rho0)]
        out[n] = float(read[0] - read[1])
    return out


def joint_deviation_change(keys: Sequence[Key], geometry: Geometry, params,
                           errors: JointModel, mount_offsets=None) -> np.ndarray:
    """What the joints' errors ``errors`` (their bidirectional mean: the lost motion is
    the run's measured reversal's, docs/model.md "Lost motion") add to the deviations
    of the machine ``params``, exactly: :func:`joint_error_deviations` less
    :func:`orthocal.deviations` (mm). Subtracted from the measured deviations, what
    is left is what a machine with exact joints would have read (docs/model.md, "The
    identification with joint tables"); ``errors`` may be
    :class:`orthocal.joint_count.CountedJoints`: the stops at the drive's count, (J15))."""
    exact = deviations(list(keys), geometry, params, mount_offsets)
    return joint_error_deviations(keys, geometry, params, errors, "mean",
                                  mount_offsets) - exact


def lead_deviation_change(keys: Sequence[Key], geometry: Geometry,
                          lead_um_per_m: Sequence[float] | np.ndarray) -> np.ndarray:
    """What pure leads k (µm/m, x, y, z; drives homed at Π0) add to the deviations,
    first order in k (docs/model.md (J4)), mm:

        δΔ^s_{i,j} = μ_s·(k_i·s·tan α_s − k_j·L·(1 − cos α_s)),   μ_s = 1/2 + sin α_s

    (the gauges at the legs' middles; a second plane's f replaces 1/2 in μ)."""
    k = 1e-6 * np.asarray(lead_um_per_m, dtype=float)
    L = geometry.leg_length
    out = np.empty(len(keys))
    for n, key in enumerate(keys):
        sign, leg, along = check_key(key)
        base, f = split_plane(sign)
        s, a = stroke(base, geometry), tilt(base, geometry)
        mu = f + math.sin(a)
        out[n] = mu * (k[AXES.index(leg)] * s * math.tan(a)
                       - k[AXES.index(along)] * L * (1.0 - math.cos(a)))
    return out
