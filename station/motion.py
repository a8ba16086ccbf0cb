"""The path the controller really takes between two stops (design.md, "Register
map": COMMAND 1 promises no interpolation).

Two motion models, named in the register-map profile (``RegisterMap.motion``)
and overridable in the config (``[controller] motion``):

* ``coordinated``: the axes move together on the straight line in joint space
  (one trapezoid on the longest axis, the others scaled to arrive with it);
* ``independent``: each axis runs its own rest-to-rest trapezoid at the
  commanded speed and acceleration, all starting together, so the short moves
  finish first and the path bends away from the straight line.

The plan check samples the path in time and checks every sample; for the
independent model it checks the straight line too, since a controller that
promises nothing may also interpolate.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np

import orthocal
from orthocal import Geometry

MotionModel = Literal["coordinated", "independent"]
MOTION_MODELS: tuple[str, ...] = ("coordinated", "independent")
# Samples per path (ends included). The leg's sideways excursion is smooth; on
# an independent path it turns within the short axes' trapezoid (~10 % of a
# long move), so 160 samples in time put ~16 on the turn: µm resolution.
PATH_SAMPLES = 160


def trapezoid_position(distance: float, v_max: float, accel: float,
                       t: np.ndarray) -> np.ndarray:
    """Distance travelled at times ``t`` by a rest-to-rest move over ``distance``
    (a triangle when too short to cruise); ``distance`` at and after the end."""
    t = np.asarray(t, dtype=float)
    if distance <= 0:
        return np.zeros_like(t)
    t_acc = v_max / accel
    if v_max * t_acc >= distance:  # never reaches v_max
        t_acc = math.sqrt(distance / accel)
        v_peak = accel * t_acc
        cruise = 0.0
    else:
        v_peak = v_max
        cruise = (distance - v_max * t_acc) / v_max
    d_acc = 0.5 * v_peak * t_acc
    t_dec = t_acc + cruise
    total = t_dec + t_acc
    s = np.where(t < t_acc, 0.5 * accel * np.clip(t, 0.0, None) ** 2,
                 np.where(t < t_dec, d_acc + v_peak * (t - t_acc),
                          distance - 0.5 * accel * np.clip(total - t, 0.0, None) ** 2))
    return np.clip(s, 0.0, distance)


def trapezoid_time(distance: float, v_max: float, accel: float) -> float:
    """Duration of the rest-to-rest move (drivers.axes.move_time, restated here so
    the plan does not need the driver)."""
    if distance <= 0:
        return 0.0
    d_acc = v_max**2 / accel
    if distance <= d_acc:
        return 2.0 * math.sqrt(distance / accel)
    return distance / v_max + v_max / accel


def straight_path(a: Sequence[float], b: Sequence[float],
                  samples: int = PATH_SAMPLES) -> np.ndarray:
    """Points on the straight line from a to b (the coordinated path)."""
    t = np.linspace(0.0, 1.0, samples)[:, None]
    a_v = np.asarray(a, dtype=float)
    return a_v + (np.asarray(b, dtype=float) - a_v) * t


def independent_path(a: Sequence[float], b: Sequence[float], speed: float, accel: float,
                     samples: int = PATH_SAMPLES) -> np.ndarray:
    """Joint positions sampled uniformly in time while each axis runs its own
    trapezoid from a to b (ends included)."""
    a_v = np.asarray(a, dtype=float)
    delta = np.asarray(b, dtype=float) - a_v
    duration = trapezoid_time(float(np.max(np.abs(delta))), speed, accel)
    t = np.linspace(0.0, duration, samples)
    out = np.empty((samples, 3))
    for i in range(3):
        out[:, i] = a_v[i] + math.copysign(1.0, delta[i]) * trapezoid_position(
            abs(float(delta[i])), speed, accel, t)
    return out


def real_path(a: Sequence[float], b: Sequence[float], motion: str, speed: float,
              accel: float) -> np.ndarray:
    """Every point the plan check must hold at for one COMMAND 1 from a to b."""
    line = straight_path(a, b)
    if motion == "coordinated":
        return line
    return np.vstack([independent_path(a, b, speed, accel), line])


def waypoints(a: Sequence[float], b: Sequence[float], n: int,
              geometry: Geometry) -> list[np.ndarray]:
    """The targets of n + 1 sub-moves from a to b: ``n`` waypoints that put the
    end point at even steps on the straight line from P(a) to P(b) (nominal
    kinematics), then b.

    Between two test postures of leg i the end point runs along axis i, so at
    every waypoint leg i is parallel to its axis and its indicators read their
    mounting value; each sub-move's own path (straight in joint space, or bent by
    independent axes) strays only by what a short move can. Waypoints on the
    straight line in joint space would not do: that line itself swings leg x by
    4.9 mm between Π_x^+ and Π_x^− of the paper's machine.
    """
    a_v = np.asarray(a, dtype=float)
    b_v = np.asarray(b, dtype=float)
    fractions = [k / (n + 1) for k in range(1, n + 1)]
    try:
        pa, pb = orthocal.forward(a_v, geometry), orthocal.forward(b_v, geometry)
        via = [orthocal.inverse(pa + (pb - pa) * f, geometry) for f in fractions]
    except ValueError:  # an end outside the workspace: the plan check says where
        via = [a_v + (b_v - a_v) * f for f in fractions]
    return [np.asarray(v, dtype=float) for v in via] + [b_v]
