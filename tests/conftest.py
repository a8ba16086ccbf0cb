"""Shared fixtures. Every test must leave no thread, pty or server behind.

Time. Every virtual station of the tests (drivers.sim.station, in-process or in a
subprocess: ``orthocal run --simulate``, ``orthocal sim``) runs on a clock
:data:`SIM_TIME_SCALE` times faster than real time, its moves that many times
shorter and its gauges' line time too: a whole calibration proves the same at
any speed (the readings at the stops, the counts, the journal do not depend on
it). A test whose subject is timing — the plunger guard polling while the axes
move, a deadline, line time, the console — is marked ``real_time`` and gets the
virtual station at real time. ``ORTHOCAL_SIM_TIME_SCALE=1 python -m pytest``
runs the whole suite at real time.

Builders (the options of a simulated run, the short procedure, a station config,
the rig of the CLI fixture below) are plain functions in builders.py.
"""

from __future__ import annotations

import gc
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

# The shared helpers (builders, fakes, the wire, the real systems) live in tests/helpers/
# and are imported by name from every folder of tests.
sys.path.insert(0, str(Path(__file__).resolve().parent / "helpers"))

from builders import NO_FIGURES, CliOutcome, Prepare, Rig

from drivers.sim.station import TIME_SCALE_ENV

#: How much faster than real time the tests' virtual stations run (module docstring):
#: moves of 1000 mm/s take a few milliseconds, a reading at 9600 baud under one.
SIM_TIME_SCALE = "20"

#: Device timeouts of the ``orthocal`` fixture's runs: each lost reply costs little
#: (a reply takes ~15 ms at 9600 baud in real time).
CLI_TIMEOUT_S = 0.25


# pytest keeps the test modules it has rewritten (their asserts) as bytecode, and reads
# it back next session, unless Python is told not to write bytecode
# (PYTHONDONTWRITEBYTECODE, set on some machines, CI images among them): every worker
# then parses and rewrites every test module again, about six seconds of CPU each. The
# project's own modules are compiled anyway (_compile_the_project); so are the tests'.
sys.dont_write_bytecode = False


def pytest_configure(config: pytest.Config) -> None:
    # A session default, so that module-scoped fixtures and subprocesses get it too;
    # an ORTHOCAL_SIM_TIME_SCALE given to pytest wins.
    os.environ.setdefault(TIME_SCALE_ENV, SIM_TIME_SCALE)
    # One BLAS thread per process: the station's matrices are a few dozen rows, too
    # small for OpenBLAS to split, yet its pool of one thread per core spins up in
    # every process that imports numpy or scipy (each has its own pool). With four
    # workers and their subprocesses on two cores that is CPU taken from the tests,
    # never given back: a simulated run in a subprocess took 4.2-4.4 s of CPU with
    # one thread against 4.6 s without (BENCHMARKS.md). Workers and subprocesses
    # inherit it.
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if not hasattr(config, "workerinput"):  # once, in pytest's own process
        _compile_the_project()
    config.addinivalue_line(
        "markers", "real_time: the virtual stations of this test run at real time "
        "(its subject is timing: guard polls during moves, deadlines, line time)")


def pytest_collection_finish(session: pytest.Session) -> None:
    _settle_the_heap()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    yield
    _settle_the_heap()


def _settle_the_heap() -> None:
    """Collect what the test (or the collection) left as garbage, then freeze what
    survives: Python's full collections, which run every few hundred thousand
    allocations and once per report drawn (plots.release_fonts), then walk only the
    objects the running test made, not the hundreds of thousands every test before
    it left alive (modules, fixtures, caches). Measured on the report and closed-loop
    files: 6.1 s of their 42 s went to the collector, 2.3 s with this. Objects alive
    now and garbage later in a cycle stay in memory: a few MB over a session. The
    leak check (no_leaks) has run by now: what it judged is not hidden from it."""
    gc.collect()
    gc.freeze()


def _compile_the_project() -> None:
    """Byte-compile orthocal, drivers and station before the tests start: a hundred
    tests run the station in a subprocess, and where Python is told not to write
    bytecode (PYTHONDONTWRITEBYTECODE, set on some machines, CI images among them)
    each of them compiles the same 10,000 lines again, 0.3 s of CPU apiece. Python
    reads bytecode that exists whatever that variable says."""
    import compileall

    root = Path(__file__).resolve().parents[1]
    for package in ("orthocal", "drivers", "station"):
        compileall.compile_dir(root / package, quiet=1)


@pytest.fixture(autouse=True)
def sim_time(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """A ``real_time`` test's virtual stations (and its subprocesses') at real time,
    ahead of the other workers' tests on a loaded machine (see :func:`_priority`)."""
    real_time = request.node.get_closest_marker("real_time") is not None
    if real_time:
        monkeypatch.setenv(TIME_SCALE_ENV, "1")
    _priority(real_time)


def _priority(real_time: bool) -> None:
    """A timing test (the plunger guard polling while the axes move) measures the
    station's latency, and on 2 cores with four workers the other tests' CPU (a
    design search, a dozen simulators) can stretch it past what a real station
    sees. So the worker's main thread, whose threads and subprocesses the test
    starts and which inherit it, runs at the normal priority for a timing test and
    at nice 10 for the others. Lowering a nice value needs root (CI's case); where
    that is refused, the worker keeps the priority it has."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, 0 if real_time else 10)
    except (OSError, AttributeError):  # not root, or not a POSIX system
        pass


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
    # A server thread closes its sockets as it winds down, and on a loaded machine that
    # can take seconds; a socket only unreachable garbage holds is closed by the
    # collector (which a test's own allocations may not have run yet). Neither is a
    # leak; a descriptor a live object holds still fails the test.
    deadline = time.monotonic() + 5.0
    collected = False
    while True:
        extra = [t for t in threading.enumerate() if t not in threads_before and t.is_alive()]
        leaked_fds = _open_fds() - fds_before
        if not extra and not leaked_fds:
            return
        if time.monotonic() > deadline:
            break
        if leaked_fds and not extra and not collected:
            gc.collect()
            collected = True
            continue
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


@pytest.fixture
def orthocal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
             capsys: pytest.CaptureFixture[str]) -> Iterator[Callable[..., CliOutcome]]:
    """``orthocal(*argv, prepare=fn)`` runs the real command line in-process
    (``station.commands.cli.main``); ``prepare(rig, station)`` gets every virtual
    station the command starts (run, then resume or rollback), whose config gives
    the devices :data:`CLI_TIMEOUT_S` (the controller ``controller_timeout_s`` where
    given) and a report without figures (``figures=True``: with them), and the rig
    records every register write."""
    from station.commands.cli import main
    from station.commands.simulate import launch as simulation

    def invoke(*argv: str, prepare: Prepare | None = None, out_dir: Path | None = None,
               rig: Rig | None = None, figures: bool = False,
               controller_timeout_s: float = CLI_TIMEOUT_S) -> CliOutcome:
        rig = rig if rig is not None else Rig()
        real_start = simulation.start_station

        def start(params: dict[str, Any], nvram: Path | None) -> Any:
            station = real_start(params, nvram)
            rig.stations.append(station)
            if not rig.gauges:
                rig.gauges = dict(station.indicators)
            describe = station.config

            def config() -> dict[str, Any]:
                c = describe()
                c["controller"]["timeout_s"] = controller_timeout_s
                if not figures:  # as the builders' runs (builders.NO_FIGURES)
                    c.setdefault("report", dict(NO_FIGURES))
                for ind in c["indicators"]:
                    ind["timeout_s"] = CLI_TIMEOUT_S
                return c

            station.config = config
            write = station.controller._write

            def record(start: int, address: int, values: list[int], registers: list[int]):
                rig.writes.append((address, len(values)))
                return write(start, address, values, registers)

            station.controller._write = record
            if prepare is not None:
                prepare(rig, station)
            return station

        monkeypatch.setattr(simulation, "start_station", start)
        out_dir = out_dir if out_dir is not None else tmp_path / "runs"
        try:
            code = main(list(argv))
        except SystemExit as exc:  # argparse reports usage errors by exiting 2
            code = exc.code if isinstance(exc.code, int) else 1
        monkeypatch.setattr(simulation, "start_station", real_start)
        out, err = capsys.readouterr()
        return CliOutcome(code, out, err, rig, out_dir)

    yield invoke
