"""The command line: one module per command (``orthocal run`` in run.py, ...), and
the in-process virtual station behind ``run --simulate``."""
