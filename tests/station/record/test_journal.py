"""The journal: every record on disk (fsynced) when append returns, typed, and folded
into the run state (station.record.state) as it is saved or read back; a torn last
line is tolerated and resuming only appends."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from builders import journal_header

import station.record.journal_file as journal_mod
from station.errors import BadInput
from station.record.journal import Header, Reading, SetupRecord
from station.record.journal_file import Journal, read_journal, read_records
from station.record.state import RunState

HEADER = journal_header()


def test_each_append_is_flushed_and_fsynced(tmp_path: Path, monkeypatch) -> None:
    synced: list[int] = []
    real_fsync = os.fsync

    def spy(fd: int) -> None:
        synced.append(os.path.getsize(path))  # what is on disk at the fsync
        real_fsync(fd)

    path = tmp_path / "journal.jsonl"
    monkeypatch.setattr(journal_mod.os, "fsync", spy)
    with Journal(path) as j:
        j.append(HEADER)
        size_after_first = os.path.getsize(path)
        j.append({"type": "reading", "stop": "m:0:0:0", "indicator": "A", "values": [0.001]})
        size_after_second = os.path.getsize(path)
    # fsync saw the complete record each time (write + flush before fsync)
    assert size_after_first in synced and size_after_second in synced
    assert size_after_second > size_after_first


def test_the_state_saved_is_the_state_read_back(tmp_path: Path) -> None:
    path = tmp_path / "journal.jsonl"
    with Journal(path) as j:
        j.append(HEADER)
        j.append({"type": "setup", "phase": "m", "setup": 0, "leg": "x",
                  "indicators": {"A": "y"}, "operator_s": 1.5})
        j.append({"type": "reading", "stop": "m:0:0:0", "indicator": "A", "values": [0.1, 0.2]})
        j.append({"type": "event", "event": {"event": "retry", "device": "indicator A",
                                             "indicator": "A", "port": "/dev/a",
                                             "attempt": 1, "error": "no reply"}})
        j.append({"type": "writeback", "stage": "backup",
                  "before": {"x": 0.0, "y": 0.0, "z": 0.0}})
        saved = j.state
    records = read_records(path)
    assert [type(r) for r in records[:3]] == [Header, SetupRecord, Reading]  # each its type
    state = RunState.of(records)
    assert state == saved  # folded as saved, and folded again from the file: the same
    assert state.header is not None and state.header.config.indicators[1].name == "B"
    assert state.live is not None and (state.live.phase, state.live.setup) == ("m", 0)
    assert state.live.readings[("m:0:0:0", "A")] == [0.1, 0.2]
    assert (state.mountings, state.operator_s, state.retries) == (1, 1.5, 1)
    assert state.finished is None and state.resumes == 0
    assert "backup" in state.writebacks[1]  # round 1 without a round
    assert Journal(path).state == state  # a journal reopened folds the file


def test_a_record_of_no_type_is_refused_unwritten(tmp_path: Path) -> None:
    path = tmp_path / "journal.jsonl"
    with Journal(path) as j:
        j.append(HEADER)
        with pytest.raises(ValueError, match="'setup' is not of the journal's schema"):
            j.append({"type": "setup", "phase": "m", "setup": 0})  # no leg, no gauges
    assert [r["type"] for r in read_journal(path)] == ["header"]
    path.write_text(path.read_text() + json.dumps({"type": "mystery", "t": 1.0}) + "\n")
    with pytest.raises(BadInput, match="line 2 is not a journal record"):
        read_records(path)


def test_torn_last_line_is_tolerated_and_resume_only_appends(tmp_path: Path) -> None:
    path = tmp_path / "journal.jsonl"
    with Journal(path) as j:
        j.append(HEADER)
        j.append({"type": "setup", "phase": "m", "setup": 0, "leg": "x",
                  "indicators": {"A": "y"}})
        j.append({"type": "reading", "stop": "m:0:0:0", "indicator": "A", "values": [1.0]})
    with open(path, "ab") as fh:  # killed in the middle of writing a record
        fh.write(b'{"type":"reading","stop":"t","indi')
    before = path.read_bytes()
    records = read_journal(path)
    assert [r["type"] for r in records] == ["header", "setup", "reading"]

    with Journal(path) as j:
        j.append({"type": "resumed"})
        j.append({"type": "reading", "stop": "m:0:1:+", "indicator": "A", "values": [2.0]})
    after = path.read_bytes()
    assert after.startswith(before)
    state = RunState.of(read_records(path))
    assert state.live is not None and state.resumes == 1
    assert state.live.readings == {("m:0:0:0", "A"): [1.0], ("m:0:1:+", "A"): [2.0]}


def test_corruption_in_the_middle_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "journal.jsonl"
    lines = [json.dumps(HEADER), "garbage{", json.dumps({"type": "reading"})]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(BadInput, match="line 2 is corrupt"):
        read_journal(path)


def test_missing_journal_is_bad_input(tmp_path: Path) -> None:
    with pytest.raises(BadInput, match="no journal"):
        read_journal(tmp_path / "journal.jsonl")


# A real file-size limit (RLIMIT_FSIZE) in a child process: with SIGXFSZ ignored a
# write past the limit fails with EFBIG, as one on a full disk fails with ENOSPC.
FULL_CHILD = r"""
import json, sys
from station.errors import StorageFull
from station.record.journal_file import Journal

j = Journal(sys.argv[1])
n = 0
try:
    while True:
        j.append({"type": "reading", "stop": f"m:0:{n}:+", "indicator": "A",
                  "values": [0.001 * n] * 7})
        n += 1
except StorageFull as exc:
    print(json.dumps({"saved": n, "error": str(exc)}))
try:
    j.append({"type": "reading", "stop": "again", "indicator": "A", "values": [1.0] * 200})
except StorageFull:
    print(json.dumps({"again": "refused"}))
j.close()
"""


def _limited(limit: int):
    import resource
    import signal

    def preexec() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return preexec


@pytest.mark.parametrize("limit", [1000, 1337])
def test_a_full_disk_leaves_only_whole_records(tmp_path: Path, limit: int) -> None:
    import subprocess
    import sys

    path = tmp_path / "journal.jsonl"
    proc = subprocess.run([sys.executable, "-c", FULL_CHILD, str(path)], capture_output=True,
                          text=True, timeout=60, preexec_fn=_limited(limit),
                          cwd=Path(__file__).parents[3])
    assert proc.returncode == 0, proc.stderr
    first, again = (json.loads(line) for line in proc.stdout.splitlines())
    assert "the disk is full" in first["error"] and "was not saved" in first["error"]
    assert again == {"again": "refused"}
    raw = path.read_bytes()
    # Only whole records: the part of the failed record that fit was cut off again.
    assert raw.endswith(b"\n") and len(raw) <= limit
    records = read_journal(path)
    assert len(records) == first["saved"] > 0
    assert [r["stop"] for r in records] == [f"m:0:{n}:+" for n in range(first["saved"])]
    # After space is freed the journal goes on where it stopped.
    with Journal(path) as j:
        assert not j.torn
        j.append({"type": "resumed"})
    assert [r["type"] for r in read_journal(path)][-1] == "resumed"
