"""G-code for a controller that runs the machine's nominal kinematics (``orthocal
compensate``): a program read as blocks of words (:mod:`station.gcode.words`), its
modal state and motions as RS274/NGC defines them (:mod:`station.gcode.modal`, the
codes in :mod:`station.gcode.codes`), each motion as a curve
(:mod:`station.gcode.paths`), cut into segments that keep the identified machine's
tool on the programmed path (:mod:`station.gcode.subdivide`, checked against the run's
soft limits, :mod:`station.gcode.soft_bounds`), and written back with everything else as
it was (:mod:`station.gcode.rewrite`). A program to measure the cost by:
:mod:`station.gcode.sample`."""
