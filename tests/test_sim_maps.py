"""The virtual drive serving register maps other than the generic one (issue 22):
the real ModbusAxisController against the real pymodbus server on 127.0.0.1
(ephemeral ports) or on a pseudo-terminal null-modem (RTU), for IAI's PCON map and
for a map never seen before, built here: three single-axis drives behind one
gateway. One request/response pair of that map is checked byte for byte against
the Modbus spec. (The generic map's own tests, test_axes_sim.py and
test_sim_integrator.py, run unchanged against the same drive.)

Where a test looks at the machine mid-move it gives it a manual clock.
"""

from __future__ import annotations

import numpy as np

import orthocal
from drivers.sim.machine import VirtualOrthoglide

GEOMETRY = orthocal.Geometry()
PI0 = orthocal.posture("0", None, GEOMETRY)
LIMITS = ([200.25] * 3, [380.25] * 3)  # the drive's default soft limits
TIMEOUT_S = 0.25
COUNTS_PER_MM = 2000.0  # the gateway map's encoders


class ManualClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def fast_machine(**kw: object) -> VirtualOrthoglide:
    options: dict = {"speed_mm_s": 400.0, "accel_mm_s2": 20000.0, **kw}
    return VirtualOrthoglide(GEOMETRY, **options)


def test_a_second_stop_at_the_same_instant_keeps_braking() -> None:
    # A per-axis map stops each axis in turn: three stops within one instant of a
    # manual clock must brake from where the first one found the carriages.
    clock = ManualClock()
    machine = fast_machine(speed_mm_s=10.0, accel_mm_s2=100.0, clock=clock)
    machine.move_to(PI0 + np.array([20.0, 0.0, -20.0]))
    clock.t += 1.0
    machine.stop()
    braking = machine.actual()
    machine.stop()
    machine.stop()
    np.testing.assert_allclose(machine.actual(), braking, atol=1e-12)
    clock.t += 10.0
    # 10 mm/s braked at 100 mm/s²: 0.5 mm further
    np.testing.assert_allclose(machine.actual(), braking + np.array([0.5, 0.0, -0.5]), atol=1e-9)
