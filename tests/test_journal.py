"""The journal: every record on disk (fsynced) when append returns; replay
rebuilds the state; a torn last line is tolerated and resuming only appends."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

import station.journal as journal_mod
from station.errors import BadInput
from station.journal import Journal, read_journal, replay


def test_each_append_is_flushed_and_fsynced(tmp_path: Path, monkeypatch) -> None:
    synced: list[int] = []
    real_fsync = os.fsync

    def spy(fd: int) -> None:
        synced.append(os.path.getsize(path))  # what is on disk at the fsync
        real_fsync(fd)

    path = tmp_path / "journal.jsonl"
    monkeypatch.setattr(journal_mod.os, "fsync", spy)
    with Journal(path) as j:
        j.append({"type": "header", "config": {}})
        size_after_first = os.path.getsize(path)
        j.append({"type": "reading", "stop": "m:0:0:0", "indicator": "A", "values": [0.001]})
        size_after_second = os.path.getsize(path)
    # fsync saw the complete record each time (write + flush before fsync)
    assert size_after_first in synced and size_after_second in synced
    assert size_after_second > size_after_first


def test_replay_rebuilds_state(tmp_path: Path) -> None:
    path = tmp_path / "journal.jsonl"
    with Journal(path) as j:
        j.append({"type": "header", "config": {"a": 1}})
        j.append({"type": "setup", "phase": "m", "setup": 0})
        j.append({"type": "reading", "stop": "m:0:0:0", "indicator": "A", "values": [0.1, 0.2]})
        j.append({"type": "event", "event": {"event": "retry", "device": "indicator A"}})
        j.append({"type": "writeback", "stage": "backup", "before": {"x": 0.0}})
    state = replay(read_journal(path))
    assert state.header is not None and state.header["config"] == {"a": 1}
    assert state.mounted == [("m", 0)]
    assert state.readings[("m:0:0:0", "A")] == [0.1, 0.2]
    assert state.retries == 1
    assert "backup" in state.writeback and state.finished is None


def test_torn_last_line_is_tolerated_and_resume_only_appends(tmp_path: Path) -> None:
    path = tmp_path / "journal.jsonl"
    with Journal(path) as j:
        j.append({"type": "header"})
        j.append({"type": "reading", "stop": "s", "indicator": "A", "values": [1.0]})
    with open(path, "ab") as fh:  # killed in the middle of writing a record
        fh.write(b'{"type":"reading","stop":"t","indi')
    before = path.read_bytes()
    records = read_journal(path)
    assert [r["type"] for r in records] == ["header", "reading"]

    with Journal(path) as j:
        j.append({"type": "resumed"})
        j.append({"type": "reading", "stop": "t", "indicator": "A", "values": [2.0]})
    after = path.read_bytes()
    assert after.startswith(before)
    state = replay(read_journal(path))
    assert state.readings[("t", "A")] == [2.0] and state.resumes == 1


def test_corruption_in_the_middle_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "journal.jsonl"
    lines = [json.dumps({"type": "header"}), "garbage{", json.dumps({"type": "reading"})]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(BadInput, match="line 2 is corrupt"):
        read_journal(path)


def test_missing_journal_is_bad_input(tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="no journal"):
        read_journal(tmp_path / "journal.jsonl")
