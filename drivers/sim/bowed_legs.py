"""Form errors of the virtual machine's legs: a bowed leg.

A leg is not a straight line: its surface, where a gauge's plunger touches it,
lies off the straight line from the carriage A to the end point P by a bow
whose sagitta (the offset at the leg's middle) is ``h``. A plunger touching the
leg at the fraction t of the way from A to P sees

    w(t) = 4·h·t·(1 − t)

added to the coordinate it measures (a parabola through both ends, h at t = ½).
The gauge's stand is fixed to the base in the plane x_i = M, so the point it
touches slides along the leg as the machine moves: t is where the leg's axis
crosses that plane, t = (A_i − M)/(A_i − p_i) (orthocal.measurement.reading_at),
with A_i = q_i·u_ii (q = ρ + Δρ, u_i the actuator axis; u_ii = 1 untilted).
What a gauge zeroed at Π0 shows at Π_i^s is therefore 4h[t(1 − t) − t0(1 − t0)]
off the straight leg's deviation.

Deliberately computed here from :func:`orthocal.forward` alone, not from the
maths' own bow model, so that a test can compare the two.

Sign: h is along +j of each gauge plane (x_i, j) of leg i, the leg's own h the same
in both planes (``leg_bow``) and each plane's own added (``plane_bow``): the leg's
middle sits h further along +j than its straight line. A
gauge mounted reversed ("-j") reads the coordinate negated, so it shows −w, as
it shows every other displacement of the leg.
"""

from __future__ import annotations

import numpy as np

from orthocal import AXES, Geometry, axis_directions, forward


def contact_fraction(rho: np.ndarray, leg: str, geometry: Geometry, drho: np.ndarray,
                     dl: np.ndarray, tilt: np.ndarray, mount: float,
                     gap: np.ndarray | None = None) -> np.ndarray:
    """t: where along leg ``leg`` (0 at the carriage A, 1 at the end point P) the
    base-fixed plane x_leg = ``mount`` crosses its axis, at joints ``rho`` ((..., 3),
    controller counts from the delivered offsets, as orthocal.leg_reading takes
    them) of a machine with the true errors ``drho``, ``dl``, ``tilt``, ``gap``
    (a gap moves the carriage across its axis, never along it: A_i's own
    coordinate is the untilted one)."""
    rho = np.asarray(rho, dtype=float)
    i = AXES.index(leg)
    p = forward(rho, geometry, drho, dl, tilt, gap)
    u = axis_directions(tilt)
    a_i = (rho[..., i] + drho[i]) * (1.0 if u is None else u[i, i])
    return (a_i - mount) / (a_i - p[..., i])


def bow_mm(t: np.ndarray | float, sagitta_mm: float) -> np.ndarray:
    """w(t) = 4·h·t·(1 − t): the bow of sagitta h at the fraction t along the leg."""
    t = np.asarray(t, dtype=float)
    return 4.0 * sagitta_mm * t * (1.0 - t)
