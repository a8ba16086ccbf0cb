"""A real PostgreSQL server for the history tests, started in a temporary directory
(imported by the tests): initdb, then pg_ctl on a Unix socket only (no TCP port),
trust authentication, stopped and removed afterwards. As root (CI), the server runs
as ``nobody``: PostgreSQL refuses to run as root."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

PORT = 5432  # only names the socket file: nothing listens on TCP


def _bin(name: str) -> str | None:
    """A server program: on PATH, else where Debian keeps it (postgresql-NN puts only
    its clients on PATH), the newest version first."""
    found = shutil.which(name)
    if found:
        return found
    for folder in sorted(Path("/usr/lib/postgresql").glob("*/bin"), reverse=True,
                         key=lambda p: int(p.parent.name) if p.parent.name.isdigit() else 0):
        if (folder / name).is_file():
            return str(folder / name)
    return None


def available() -> bool:
    return _bin("initdb") is not None and _bin("pg_ctl") is not None


def _as_server_user(argv: list[str]) -> list[str]:
    if os.geteuid() == 0:
        return [shutil.which("runuser") or "/usr/sbin/runuser", "-u", "nobody", "--", *argv]
    return argv


@contextlib.contextmanager
def server() -> Iterator[str]:
    """A running server; yields its SQLAlchemy URL (psycopg 3)."""
    initdb, pg_ctl = _bin("initdb") or "initdb", _bin("pg_ctl") or "pg_ctl"
    root = Path(tempfile.mkdtemp(prefix="orthocal-pg-"))
    data = root / "data"
    try:
        if os.geteuid() == 0:
            shutil.chown(root, "nobody")
        root.chmod(0o755)
        subprocess.run(_as_server_user([initdb, "-D", str(data), "-U", "postgres",
                                        "--auth=trust", "-E", "UTF8"]),
                       check=True, capture_output=True, timeout=120)
        subprocess.run(_as_server_user(
            [pg_ctl, "-D", str(data), "-l", str(root / "log"), "-w", "-t", "60", "-o",
             f"-k {root} -p {PORT} -c listen_addresses=''", "start"]),
            check=True, capture_output=True, timeout=90)
        try:
            yield f"postgresql+psycopg://postgres@/postgres?host={root}&port={PORT}"
        finally:
            subprocess.run(_as_server_user([pg_ctl, "-D", str(data), "-m", "fast", "-w",
                                            "stop"]), capture_output=True, timeout=60)
    finally:
        shutil.rmtree(root, ignore_errors=True)
