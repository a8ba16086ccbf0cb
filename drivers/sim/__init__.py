"""Simulated devices that speak the real protocols: a virtual Orthoglide
(:mod:`drivers.sim.machine`, moving as :mod:`drivers.sim.motion` says) behind
a real pymodbus server (:mod:`drivers.sim.controller`, TCP or RTU over
:mod:`drivers.sim.ptypair`, serving the drive's registers of
:mod:`drivers.sim.drive` for any register map, laid out on the wire by
:mod:`drivers.sim.layout`; its fault knobs in :mod:`drivers.sim.faults`), simulated
dial indicators (:mod:`drivers.sim.indicators`), and the whole virtual station
(:mod:`drivers.sim.station`, its out-of-stroke count in :mod:`drivers.sim.strokes`)."""
