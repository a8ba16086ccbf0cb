"""What the gauges see of the virtual Orthoglide: its legs in their planes, its end point."""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

import numpy as np

import orthocal
from drivers.sim import bowed_legs as form
from drivers.sim.drive_motion import SAMPLE_DT_S, SAMPLE_MIN, Segment
from drivers.sim.screws import Screws
from orthocal import Geometry

#: The gauge planes (leg, direction gauged) in plane_bow's order: xy, xz, yx, yz, zx, zy
#: (orthocal.stands.GAUGES' order, which the simulator's test checks).
PLANES: tuple[tuple[str, str], ...] = tuple(
    (i, j) for i in orthocal.AXES for j in orthocal.AXES if i != j)
#: Noise-free readings remembered by leg_reading (cleared when full).
_READINGS_KEPT = 4096


class GaugeView:
    """The part of :class:`~drivers.sim.machine.VirtualOrthoglide` the dial indicators
    read: its carriages seen through its hidden errors, at an instant or along a
    segment (the machine's state and lock, named here, are its own)."""

    geometry: Geometry
    true_drho: np.ndarray
    true_dl: np.ndarray
    true_tilt: np.ndarray
    true_gap: np.ndarray
    leg_bow: np.ndarray
    plane_bow: np.ndarray
    offsets_initial: np.ndarray
    _half_band: np.ndarray
    screws: Screws
    _lock: threading.RLock
    _clock: Callable[[], float]
    _carriage: Callable[[float], np.ndarray]

    def sample_segment(self, segment: Segment, max_dt_s: float = SAMPLE_DT_S,
                       min_samples: int = SAMPLE_MIN, extra_times: Sequence[float] = ()
                       ) -> tuple[np.ndarray, np.ndarray]:
        """(times, joint values (n, 3)) of ``segment`` sampled densely (as
        :meth:`Segment.sample`), the joints as :func:`orthocal.leg_reading` takes
        them with ``drho=self.true_drho`` (ρ from the delivered offsets, see
        drivers.sim.machine, "Frames")."""
        times, motor = segment.sample(max_dt_s, min_samples, extra_times)
        c0 = segment.motion.carriage0
        nut = self.screws.nut(motor)
        carriage = nut if c0 is None else \
            np.clip(c0, nut - self._half_band, nut + self._half_band)
        return times, carriage - self.offsets_initial

    def joint_values(self) -> np.ndarray:
        """Kinematic joint values q (model (1)) at this instant: the carriages'."""
        with self._lock:
            return self._carriage(self._clock()) - self.offsets_initial + self.true_drho

    def _rho_kin(self) -> np.ndarray:
        return self._carriage(self._clock()) - self.offsets_initial

    def leg_reading(self, leg: str, direction: str, mount: float | None = None) -> float:
        """What a dial indicator on ``leg`` measuring along ``direction`` reads (mm):
        :meth:`readings` at the instantaneous joint values."""
        with self._lock:
            rho = self._rho_kin()
        # At rest the joints do not change between a stop's readings (and the guard's
        # polls), and the exact kinematics behind each is most of a simulated run's
        # cost: the noise-free value is remembered for the very joints and errors.
        key = (np.asarray(rho, dtype=float).tobytes(), leg, direction, mount,
               self._errors_key())
        cache: dict[tuple[object, ...], float] = self.__dict__.setdefault("_readings", {})
        value = cache.get(key)
        if value is None:
            if len(cache) >= _READINGS_KEPT:
                cache.clear()
            value = cache[key] = float(self.readings(rho, leg, direction, mount))
        return value

    def _errors_key(self) -> bytes:
        """The hidden errors as bytes: a test may change them between readings."""
        return b"".join(np.asarray(a, dtype=float).tobytes() for a in (
            self.true_drho, self.true_dl, self.true_tilt, self.true_gap, self.leg_bow,
            self.plane_bow))

    def readings(self, rho: np.ndarray, leg: str, direction: str,
                 mount: float | None = None) -> np.ndarray:
        """The coordinate along ``direction`` of leg ``leg`` in the plane x_leg =
        ``mount`` (default: the nominal L/2) at joints ``rho`` ((..., 3), as
        :meth:`sample_segment` gives them): :func:`orthocal.leg_reading` with the
        true errors, plus the leg's bow where the plane touches it
        (:mod:`drivers.sim.bowed_legs`: the leg's sagitta and the gauge plane's own;
        nothing computed for a straight leg, so its readings stay those of the maths
        to the bit)."""
        reading = orthocal.leg_reading(rho, leg, direction, self.geometry, self.true_drho,
                                       self.true_dl, mount=mount, tilt=self.true_tilt,
                                       gap=self.true_gap)
        plane_of = (leg, direction.lstrip("-"))
        h = float(self.leg_bow[orthocal.AXES.index(leg)]) + (
            float(self.plane_bow[PLANES.index(plane_of)]) if plane_of in PLANES else 0.0)
        if h == 0.0:
            return reading
        plane = self.geometry.mount_plane if mount is None else mount
        t = form.contact_fraction(rho, leg, self.geometry, self.true_drho, self.true_dl,
                                  self.true_tilt, plane, self.true_gap)
        return reading + form.bow_mm(t, h)

    def source(self, leg: str, direction: str,
               mount: float | None = None) -> Callable[[], float]:
        """A zero-argument callable for a simulated indicator's ``source``."""
        return lambda: self.leg_reading(leg, direction, mount)

    def end_point(self) -> np.ndarray:
        """The end point P (mm) at this instant."""
        with self._lock:
            rho = self._rho_kin()
        return orthocal.forward(rho, self.geometry, self.true_drho, self.true_dl, self.true_tilt,
                                self.true_gap)
