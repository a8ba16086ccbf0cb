"""Device I/O for the calibration station: Modbus axis controller, serial dial
indicators, and simulated devices that speak the same protocols.

No calibration maths lives here; ``drivers.sim`` imports :mod:`orthocal` only
to place the virtual legs.
"""
