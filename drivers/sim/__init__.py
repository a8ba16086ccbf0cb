"""Simulated devices that speak the real protocols: a virtual Orthoglide
(:mod:`drivers.sim.machine`, moving as :mod:`drivers.sim.drive_motion` says, seen by the
gauges as :mod:`drivers.sim.legs` says) behind a real pymodbus server
(:mod:`drivers.sim.controller`, TCP or RTU over :mod:`drivers.sim.ptypair`, serving
the drive's registers of :mod:`drivers.sim.drive` for any register map, laid out on
the wire by :mod:`drivers.sim.layout`), simulated dial indicators
(:mod:`drivers.sim.pty_gauges`, on the lines of :mod:`drivers.sim.gauge_lines`:
pseudo-terminals, or TCP where there are none), the devices' fault knobs
(:mod:`drivers.sim.faults`), the whole virtual station (:mod:`drivers.sim.station`, built
from the specs of :mod:`drivers.sim.specs`, its out-of-stroke count in
:mod:`drivers.sim.strokes`),
and in-process fakes at the Protocol level, no server nor pty, for tests of what
drives the devices (:mod:`drivers.sim.fake`)."""
