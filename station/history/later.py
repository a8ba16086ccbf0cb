"""The runs of a machine recorded after a given run (docs/design.md, "Machine
history"): a rollback of an older run, or an export of its offsets, would put back
what those later runs replaced, so both name them first. Later: started after the
run, with the same ``[machine] id``, in the history store the run's own config
names (``[history]``, else the store beside the run directories)."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from station.errors import say
from station.history.trend import started_at


def _store_url(run_dir: Path) -> str | None:
    """The history store of the run (its config.toml's ``[history]``), None where the
    run's config turned the history off."""
    from station.history.store import default_url

    try:
        data = tomllib.loads((run_dir / "config.toml").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        data = {}
    history = data.get("history") or {}
    if history.get("enabled") is False:
        return None
    url = history.get("url")
    return str(url) if url else default_url(run_dir.parent)


def _exists(url: str) -> bool:
    """Whether the store is there to read: a SQLite file that does not exist is not
    made by asking it (any other database is asked)."""
    from sqlalchemy.engine import make_url

    parsed = make_url(url)
    if not parsed.get_backend_name().startswith("sqlite"):
        return True
    database = parsed.database
    return database is not None and database not in ("", ":memory:") \
        and Path(database).exists()


def later_runs(run_dir: Path, machine_id: str | None, started: str | None
               ) -> list[dict[str, Any]]:
    """The history entries of machine ``machine_id`` that started after ``started``
    (the run in ``run_dir``), oldest first. None to compare ([machine] id or start
    unknown, history off, no store yet): []. A store that cannot be read is said in
    one line, and nothing is named."""
    start = started_at({"started": started})
    url = _store_url(Path(run_dir))
    if not machine_id or start is None or url is None or not _exists(url):
        return []
    from station.history.store import HistoryStore

    try:
        with HistoryStore(url) as store:
            entries = store.entries(machine_id)
    except Exception as exc:  # any database error: said, and the command goes on
        say(f"orthocal: the history at {url} could not be read for later runs of "
            f"machine {machine_id} ({type(exc).__name__}: {exc})")
        return []
    own = str(run_dir)
    return [e for e in entries if (when := started_at(e)) is not None and when > start
            and e.get("run_dir") not in (own, str(Path(own).resolve()))]


def later_warning(run_dir: Path, machine_id: str | None, started: str | None,
                  consequence: str) -> str | None:
    """One line naming the machine's later runs and what ``consequence`` says the
    command would do to them; None where there are none."""
    later = later_runs(run_dir, machine_id, started)
    if not later:
        return None
    names = ", ".join(f"{e.get('run_dir')} (started {e.get('started')})" for e in later)
    return (f"orthocal: warning: machine {machine_id} has {len(later)} later run(s) in the "
            f"history: {names}; {consequence}")
