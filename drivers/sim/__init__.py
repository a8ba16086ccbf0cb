"""Simulated devices that speak the real protocols: a virtual Orthoglide
(:mod:`drivers.sim.machine`) behind a real pymodbus server
(:mod:`drivers.sim.controller`, TCP or RTU over :mod:`drivers.sim.ptypair`),
and simulated dial indicators (:mod:`drivers.sim.indicators`)."""
