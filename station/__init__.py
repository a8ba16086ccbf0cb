"""The operator's calibration station: configuration, plan, run, journal,
write-back, report and the ``orthocal`` command line."""
