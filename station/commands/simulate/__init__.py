"""The station's side of simulation: the in-process virtual station behind ``run
--simulate`` and ``orthocal sim`` (``launch``), the calibration setups its gauges are
mounted in (``station_setups``), and a rehearsal described by a file (SIM.toml:
``rehearsal_file``, merged with the command line in ``file_options``). The simulated
hardware itself is drivers.sim, which knows nothing of the station."""
