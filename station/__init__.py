"""The operator's calibration station, in rooms (arrows point down the list;
pyproject.toml's import-linter contracts keep them so):

- ``commands/``: the ``orthocal`` command line, one module per command, and the
  in-process virtual station behind ``run --simulate``;
- ``engine/``: the run: its flow and closed loop, the sequencer and the mover
  that execute the plan against the devices, the plunger guard watching the
  moves, statistics, identification, write-back, power-cut recovery, the result
  document;
- ``report/``: result.json, report.html and the summary, read from the result
  document alone;
- ``console/`` (the operator, prompts, the live progress bar) and ``rundir/``
  (the journal, the run directory, the machine lock);
- ``plan/``: the procedure as steps checked before anything moves, where the
  axes may pass during a move, the plunger guard's prediction;
- ``config/`` (the station config, and written as TOML) and ``errors.py``.
"""
