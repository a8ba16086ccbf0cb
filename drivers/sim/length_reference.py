"""A length reference on the virtual machine's base and the gauge on a carriage that
reads it: what serves the station's own test of a joint (docs/model.md, "The
station's own joint test").

The reference lies beside joint i's rail, parallel to axis i; its datum face (a stop,
a step gauge's first face) stands where the gauge's plunger touches it as it is
mounted, and the face set at the plunger is ``face_mm`` further from the gauge:
F = F_0 − s·f (model.md (J8)), s = −1 for a plunger pointing toward lower ρ ("-"),
+1 toward higher. The gauge, clamped to carriage i, reads its plunger's push-in,

    s·(x − F) + c = s·(x − x_0) + f        (zero at the mounting, f = 0 there)

x the carriage's TRUE position: the motor's count plus the screw's error and the
lost motion (drivers.sim.machine, drivers.sim.screws), so the test finds what the
screw does. The faces are where the operator says (their calibrated distances, true
here: the reference is exact). The plunger's stroke and its clamp are the gauge's
(drivers.sim.pty_gauges, drivers.sim.fake).
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np

AXES = ("x", "y", "z")


class VirtualReference:
    """The references of the joints' tests, one per joint at most, over carriages whose
    true positions ``carriages()`` gives ((3,) mm, up to a constant per joint)."""

    def __init__(self, carriages: Callable[[], np.ndarray]) -> None:
        self._carriages = carriages
        self._lock = threading.Lock()
        # per joint: (s, x_0 the carriage at the mounting, the face set from the datum)
        self._set: dict[str, tuple[int, float, float]] = {}

    def _x(self, axis: str) -> float:
        return float(np.asarray(self._carriages(), dtype=float)[AXES.index(axis)])

    def mount(self, axis: str, plunger: int) -> Callable[[], float]:
        """The reference beside joint ``axis`` with its datum face at the plunger of a
        gauge just clamped to the carriage (``plunger``: −1 pointing toward lower ρ, +1
        higher): the gauge's source, 0 now."""
        if axis not in AXES or plunger not in (-1, 1):
            raise ValueError(f"a joint x, y or z and a plunger of -1 or +1, got {axis!r}, "
                             f"{plunger!r}")
        with self._lock:
            self._set[axis] = (plunger, self._x(axis), 0.0)

        def source() -> float:
            with self._lock:
                s, x0, face = self._set.get(axis, (plunger, 0.0, 0.0))
            return s * (self._x(axis) - x0) + face
        return source

    def standing(self, axis: str, plunger: int, faces_mm: list[float],
                 x_datum: float) -> Callable[[], float]:
        """A reference standing beside joint ``axis`` from the start, for a station in
        another process, which cannot be told what its operator sets: the face at the
        plunger is the one whose null (``x_datum`` − s·f, the carriage where face f
        meets the plunger as the datum did) lies nearest the carriage, as an operator
        setting each face the station asks for would leave it. The gauge's source, 0 at
        each null."""
        faces = np.asarray(faces_mm, dtype=float)

        def source() -> float:
            x = self._x(axis)
            f = float(faces[np.argmin(np.abs(x - (x_datum - plunger * faces)))])
            return plunger * (x - x_datum) + f
        return source

    def set_face(self, axis: str, face_mm: float) -> None:
        """The operator sets the face ``face_mm`` from the datum at the plunger."""
        with self._lock:
            if axis not in self._set:
                raise ValueError(f"no reference beside joint {axis}")
            s, x0, _ = self._set[axis]
            self._set[axis] = (s, x0, float(face_mm))

    def remove(self, axis: str) -> None:
        """The reference taken off the base."""
        with self._lock:
            self._set.pop(axis, None)

    def face(self, axis: str) -> float | None:
        """The face set beside joint ``axis`` (None: no reference there)."""
        with self._lock:
            got = self._set.get(axis)
        return None if got is None else got[2]
