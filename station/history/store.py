"""The history store: one row per finished run, in any database SQLAlchemy reaches
(SQLite by default, beside the run directories; PostgreSQL where a site keeps one
for all its stations). The run directory stays the record: the store is an index of
it, which ``orthocal history --rebuild`` makes again from the run directories."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from sqlalchemy import JSON, Boolean, Float, String, create_engine, select
from sqlalchemy.engine import Engine
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, mapped_column

from station.errors import say
from station.history.entry import entry_of, profile_of
from station.record.io import UnreadableResult, read_result

#: The file the default store lives in, beside the run directories (--out).
DEFAULT_NAME = "history.sqlite"


class _Base(DeclarativeBase):
    pass


class RunRow(_Base):
    __tablename__ = "runs"

    run_dir: Mapped[str] = mapped_column(String(1024), primary_key=True)
    machine_id: Mapped[str | None] = mapped_column(String(100), index=True)
    started: Mapped[str | None] = mapped_column(String(40), index=True)
    finished: Mapped[str | None] = mapped_column(String(40))
    status: Mapped[str | None] = mapped_column(String(20))
    stopped: Mapped[str | None] = mapped_column(String(20))
    converged: Mapped[bool] = mapped_column(Boolean, default=False)
    tool_after_rms_mm: Mapped[float | None] = mapped_column(Float)
    entry: Mapped[dict[str, Any]] = mapped_column(JSON)


def default_url(runs_dir: Path) -> str:
    return f"sqlite:///{(Path(runs_dir) / DEFAULT_NAME).resolve()}"


class HistoryStore:
    """The store at ``url`` (created on first use)."""

    def __init__(self, url: str) -> None:
        self.url = url
        self._engine: Engine = create_engine(url)
        _Base.metadata.create_all(self._engine)

    def close(self) -> None:
        self._engine.dispose()

    def __enter__(self) -> HistoryStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def _session(self) -> Iterator[Session]:
        with Session(self._engine) as session, session.begin():
            yield session

    def record(self, entry: dict[str, Any]) -> None:
        """Add or replace the entry of its run directory (a resumed run's end
        replaces what its interrupted start may have left)."""
        row = RunRow(run_dir=entry["run_dir"], machine_id=entry.get("machine_id"),
                     started=entry.get("started"), finished=entry.get("finished"),
                     status=entry.get("status"), stopped=entry.get("stopped"),
                     converged=bool(entry.get("converged")),
                     tool_after_rms_mm=entry.get("tool_after_rms_mm"), entry=entry)
        with self._session() as session:
            session.merge(row)

    def entries(self, machine_id: str | None = None) -> list[dict[str, Any]]:
        """Entries oldest first, of one machine or of all."""
        query = select(RunRow).order_by(RunRow.started, RunRow.run_dir)
        if machine_id is not None:
            query = query.where(RunRow.machine_id == machine_id)
        with self._session() as session:
            return [dict(row.entry) for row in session.scalars(query)]

    def rebuild(self, runs_dir: Path) -> int:
        """Record every finished run under ``runs_dir`` again; how many. A result.json
        this version cannot read (torn, edited, of a later version) is skipped, said
        in one line naming it."""
        count = 0
        for result_path in sorted(Path(runs_dir).glob("*/result.json")):
            try:
                result = read_result(result_path)
            except UnreadableResult as exc:
                say(f"orthocal: skipped {exc}")
                continue
            if result.finished:  # a run that stopped early: the run directory says why
                self.record(entry_of(result, profile_of(result_path.parent)))
                count += 1
        return count
