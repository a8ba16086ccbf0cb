"""A machine's history: every finished run as one entry (what the machine was as
found and as left, with uncertainties; :mod:`station.history.entry`), kept in a
database SQLAlchemy reaches, SQLite by default (:mod:`station.history.store`),
and what changed between two runs (:mod:`station.history.compare`)."""
