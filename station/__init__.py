"""The operator's calibration station, in rooms (arrows point down the list;
pyproject.toml's import-linter contracts keep them so):

- ``commands/``: the ``orthocal`` command line, one module per command, and in
  ``commands/simulate/`` the in-process virtual station behind ``run --simulate``;
- ``engine/``: running the calibration: the procedure, its steps against the
  devices (flow) and the closed loop's decisions, the sequencer and the mover that
  execute the plan, the plunger guard's monitor, write-back, power-cut recovery,
  the result it fills;
- ``report/``: report.html and the summary, read from the typed run record alone;
- ``analysis/`` (what the numbers say: statistics, verdict, accuracy, budget,
  reversal), ``console/`` (the operator, prompts, the live progress bar),
  ``history/`` and ``gcode/``;
- ``record/``: the run record: the result, the journal (its records, its durable
  file and its one fold), the run directory, the machine lock, the schemas;
- ``plan/``: the procedure as steps checked before anything moves, where the
  axes may pass during a move, the plunger guard's prediction;
- ``config/`` (the station config, and written as TOML) and ``errors.py``.
"""
