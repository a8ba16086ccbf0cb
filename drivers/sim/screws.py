"""The virtual machine's screws: where a carriage stands for its motor's count.

A drive counts its motor; the nut rides the screw, whose lead is off by k (µm per
metre of travel) and which carries a periodic (pitch) error of amplitude A (µm) and
period P (mm), both counted from home:

    nut(m) = m + k·1e-6·(m − m_h) + A·1e-3·sin(2π·(m − m_h)/P)

m the motor's position on the machine's own scale, m_h where homing put it
(docs/model.md, "Joint positioning errors", (J2); the simulator homes at Π0 by
default, so the carriage errs by nothing there). The carriage then follows the nut
through the joint's dead band (drivers.sim.machine, "Lost motion"). Computed here
from the formula, not from orthocal's tables, so that a test can compare the two.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Screws:
    """Each joint's lead error (``lead_um_per_m``, x, y, z), one periodic error for
    all (``pitch_um`` amplitude, ``pitch_period_mm``; amplitude 0: none) and where
    each motor stands at home (``home_mm``, machine scale)."""

    lead_um_per_m: np.ndarray
    pitch_um: float
    pitch_period_mm: float
    home_mm: np.ndarray

    @classmethod
    def of(cls, lead_um_per_m: Sequence[float] | None, pitch: Sequence[float] | None,
           home_mm: np.ndarray) -> Screws:
        """From a lead per joint (None: exact) and (amplitude µm, period mm) (None:
        none); ValueError naming what is wrong."""
        lead = np.zeros(3) if lead_um_per_m is None else \
            np.asarray(lead_um_per_m, dtype=float).reshape(-1)
        if lead.shape != (3,) or not np.all(np.isfinite(lead)):
            raise ValueError(f"joint_lead must be 3 finite numbers (µm/m), got {lead_um_per_m!r}")
        amplitude, period = (0.0, 0.0) if pitch is None else (float(v) for v in pitch)
        if not (math.isfinite(amplitude) and amplitude >= 0):
            raise ValueError(f"joint_pitch amplitude must be >= 0 µm, got {amplitude}")
        if amplitude > 0 and not (math.isfinite(period) and period > 0):
            raise ValueError(f"joint_pitch period must be > 0 mm, got {period}")
        return cls(lead, amplitude, period, np.asarray(home_mm, dtype=float).copy())

    @property
    def exact(self) -> bool:
        """No lead and no periodic error: the nut is where the motor is."""
        return not np.any(self.lead_um_per_m) and self.pitch_um == 0.0

    def nut(self, motor: np.ndarray) -> np.ndarray:
        """Where the nuts are with the motors at ``motor`` ((3,) or (n, 3), machine
        scale); ``motor`` itself when the screws are exact (bit for bit)."""
        if self.exact:
            return motor
        travel = np.asarray(motor, dtype=float) - self.home_mm
        out = motor + 1e-6 * self.lead_um_per_m * travel
        if self.pitch_um:
            out = out + 1e-3 * self.pitch_um * np.sin(2.0 * np.pi * travel
                                                       / self.pitch_period_mm)
        return out
