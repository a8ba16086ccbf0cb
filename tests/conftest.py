"""Shared fixtures. Every test must leave no thread, pty or server behind."""

from __future__ import annotations

import os
import threading
import time

import pytest


def _open_fds() -> set[int]:
    try:
        return {int(fd) for fd in os.listdir("/proc/self/fd")}
    except FileNotFoundError:  # not Linux: skip the fd check, keep the thread check
        return set()


@pytest.fixture(autouse=True)
def no_leaks():
    """Fail a test that leaves threads or file descriptors (sockets, ptys) behind."""
    threads_before = set(threading.enumerate())
    fds_before = _open_fds()
    yield
    deadline = time.monotonic() + 2.0
    while True:
        extra = [t for t in threading.enumerate() if t not in threads_before and t.is_alive()]
        leaked_fds = _open_fds() - fds_before
        if not extra and not leaked_fds:
            return
        if time.monotonic() > deadline:
            break
        time.sleep(0.02)
    # /proc/self/fd lists the fd of its own listing at times; only report real ones.
    real = []
    for fd in sorted(leaked_fds):
        try:
            real.append(f"{fd}->{os.readlink(f'/proc/self/fd/{fd}')}")
        except OSError:
            pass
    assert not extra, f"threads left behind: {[t.name for t in extra]}"
    assert not real, f"file descriptors left behind: {real}"


@pytest.fixture(autouse=True)
def machine_locks_in_tmp(tmp_path_factory, monkeypatch):
    """Runs lock their controller in a per-user state directory: keep the tests'
    locks out of the home directory (subprocesses inherit the variable)."""
    if "ORTHOCAL_STATE_DIR" not in os.environ:
        monkeypatch.setenv("ORTHOCAL_STATE_DIR", str(tmp_path_factory.mktemp("state")))

