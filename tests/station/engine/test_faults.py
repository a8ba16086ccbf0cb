"""One line for every fault: every command, given a path it cannot use (missing, a
file where a folder is expected, a folder where a file is, a place nobody may write,
a full disk), a bad argument value, or a stdout whose reader has gone, ends with
exit 2 (what the user gave) or 1 (a failure while it ran), exactly one line on stderr
naming the path, the option or the port, and never an "internal error" or a
traceback; a closed stdout ends quietly.

In process (station.commands.cli.main through the ``orthocal`` fixture) but for the
real pipes at the end. /proc refuses new files and folders to root too (the tests may
run as root, whom permissions do not stop)."""

from __future__ import annotations

import errno
import io
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from builders import cli, journal_header
from compensate_runs import write_run

from station.record.journal_file import JOURNAL_NAME, Journal

#: A folder nobody can make anything in, root included.
NOWHERE = "/proc/orthocal-nowhere"
PROGRAM = "G21 G90\nG0 X0 Y0 Z0\nG1 X10 Y0 Z0\n"
CSV = ("posture,leg,direction,deviation_mm\n+,y,x,-0.19\n+,x,y,0.08\n-,y,x,0.22\n"
       "-,x,y,-0.34\n+,z,x,-0.29\n+,x,z,-0.52\n-,z,x,0.08\n-,x,z,0.62\n+,z,y,0.02\n"
       "+,y,z,-0.24\n-,z,y,0.20\n-,y,z,0.45\n")


@pytest.fixture(scope="module")
def places(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """Paths to give: a file, a folder, two finished runs of one machine (the first
    with a journal, for resume), a program, a readings file, a history of the runs."""
    tmp_path = tmp_path_factory.mktemp("places")
    (tmp_path / "afile").write_text("not a folder\n")
    (tmp_path / "adir").mkdir()
    runs = tmp_path / "runs"
    run_a = write_run(runs / "run-a")
    run_b = write_run(runs / "run-b")
    (tmp_path / "part.ngc").write_text(PROGRAM)
    (tmp_path / "readings.csv").write_text(CSV)
    (tmp_path / "station.toml").write_text("[controller]\nport = 502\n")
    journal = Journal(run_a / JOURNAL_NAME)
    journal.append(journal_header())
    journal.append({"type": "finished", "status": "ok", "message": None})
    journal.close()
    assert cli("history", "--out", str(runs), "--rebuild", str(runs),
               cwd=tmp_path).returncode == 0
    return {"file": str(tmp_path / "afile"), "dir": str(tmp_path / "adir"),
            "missing": str(tmp_path / "no" / "such"), "run": str(run_a),
            "run_b": str(run_b), "runs": str(runs), "program": str(tmp_path / "part.ngc"),
            "csv": str(tmp_path / "readings.csv"), "tmp": str(tmp_path),
            "config": str(tmp_path / "station.toml")}


# (argv with {place} fields, exit status, what its one line must name)
PATHS = [
    # run: --out is a folder the user gave; checked before anything starts
    (["run", "--simulate", "--yes", "--out", NOWHERE], 2, f"--out {NOWHERE}"),
    (["run", "--simulate", "--yes", "--out", "{file}"], 2, "--out {file}"),
    (["run", "--simulate", "--yes", "--out", "{file}/sub"], 2, "--out {file}/sub"),
    (["run", "--config", "{missing}.toml", "--yes"], 2, "{missing}.toml"),
    (["run", "--config", "{dir}", "--yes"], 2, "{dir}"),
    (["run", "--simulate", "{missing}.toml", "--yes"], 2, "{missing}.toml"),
    (["resume", "{missing}"], 2, "{missing}"),
    (["resume", "{file}"], 2, "{file}"),
    (["resume", "{dir}"], 2, "{dir}"),
    (["rollback", "{missing}", "--yes"], 2, "{missing}"),
    (["rollback", "{file}", "--yes"], 2, "{file}"),
    (["identify", "{missing}.csv"], 2, "{missing}.csv"),
    (["identify", "{dir}"], 2, "{dir}"),
    (["probe", "{missing}"], 2, "{missing}"),
    (["probe", "/dev/null", "--timeout", "0.1"], 1, "/dev/null"),
    (["probe", "--config", "{missing}.toml"], 2, "{missing}.toml"),
    (["init", "--out", "{missing}.toml", "--timeout", "0.1"], 2, "--out {missing}.toml"),
    (["init", "--out", "{file}", "--timeout", "0.1"], 2, "{file}"),
    (["init", "--out", f"{NOWHERE}/station.toml", "--timeout", "0.1"], 2, NOWHERE),
    (["design", "--config", "{missing}.toml"], 2, "{missing}.toml"),
    (["design", "--config", "{dir}"], 2, "{dir}"),
    (["report", "{missing}"], 2, "{missing}"),
    (["report", "{file}"], 2, "{file}"),
    (["report", "{run}", "--out", f"{NOWHERE}/r.html"], 2, f"--out {NOWHERE}/r.html"),
    (["report", "{run}", "--out", "{file}/r.html"], 2, "--out {file}/r.html"),
    (["report", "{run}", "--out", "{dir}"], 2, "--out {dir}"),
    # a device is never replaced by the report renamed over it, --force or not
    (["report", "{run}", "--out", "/dev/null", "--force"], 2, "--out /dev/null"),
    (["export", "{missing}", "--to", "csv"], 2, "{missing}"),
    (["export", "{run}", "--to", "csv", "--out", f"{NOWHERE}/x.csv"], 2, f"{NOWHERE}/x.csv"),
    (["export", "{run}", "--to", "csv", "--out", "{dir}"], 2, "{dir}"),
    (["export", "{run}", "--to", "csv", "--out", "/dev/full"], 2, "/dev/full"),  # ENOSPC
    (["export", "{run}", "--to", "linuxcnc", "--ini", "{missing}.ini"], 2, "{missing}.ini"),
    (["compensate", "{missing}.ngc", "--run", "{run}"], 2, "{missing}.ngc"),
    (["compensate", "{dir}", "--run", "{run}"], 2, "{dir}"),
    (["compensate", "{program}", "--run", "{missing}"], 2, "{missing}"),
    (["compensate", "{program}", "--run", "{run}", "--out", "{dir}"], 2, "--out {dir}"),
    (["compensate", "{program}", "--run", "{run}", "--out", f"{NOWHERE}/p.ngc"], 2,
     f"--out {NOWHERE}/p.ngc"),
    (["compensate", "{program}", "--run", "{run}", "--out", "{file}/p.ngc"], 2,
     "--out {file}/p.ngc"),
    (["history", "--out", "{missing}"], 2, "{missing}"),
    (["history", "--out", "{runs}", "--plot", f"{NOWHERE}/h.png"], 2, f"--plot {NOWHERE}"),
    (["history", "--out", "{runs}", "--plot", "{file}/h.svg"], 2, "--plot {file}/h.svg"),
    (["history", "--out", "{runs}", "--rebuild", "{missing}"], 2, "--rebuild {missing}"),
    (["history", "--db", "sqlite:///{missing}/h.sqlite"], 2, "{missing}/h.sqlite"),
    (["compare", "{missing}", "{run}"], 2, "{missing}"),
    (["compare", "{run}", "{file}"], 2, "{file}"),
    (["sim", "--config-out", "{config}"], 2, "--config-out {config}"),  # never overwritten
    (["sim", "--config-out", "{dir}"], 2, "--config-out {dir}"),
    (["sim", "--config-out", "{file}/x.toml"], 2, "--config-out {file}/x.toml"),
    (["sim", "--config-out", f"{NOWHERE}/x.toml"], 2, f"--config-out {NOWHERE}/x.toml"),
]

# every typed option of every command, given a value it cannot take
VALUES = [
    (["run", "--simulate", "--seed", "abc"], "--seed", "abc"),
    (["run", "--simulate", "--seed", "-1"], "--seed", "-1"),
    (["run", "--simulate", "--noise", "nan"], "--noise", "nan"),
    (["run", "--simulate", "--mount-error", "-1"], "--mount-error", "-1"),
    (["run", "--simulate", "--true-drho", "nan,0,0"], "--true-drho", "nan,0,0"),
    (["run", "--simulate", "--true-dl", "1,2"], "--true-dl", "1,2"),
    (["run", "--simulate", "--true-tilt", "a,b,c"], "--true-tilt", "a,b,c"),
    (["run", "--simulate", "--sim-speed", "0"], "--sim-speed", "0"),
    (["run", "--simulate", "--sim-procedure", "[1]"], "--sim-procedure", "[1]"),
    (["run", "--simulate", "--motion", "fast"], "--motion", "fast"),
    (["run"], "--simulate", ""),
    (["resume"], "RUN_DIR", ""),
    (["rollback", "--yes"], "RUN_DIR", ""),
    (["sim", "--config-out", "x.toml", "--port", "70000"], "--port", "70000"),
    (["sim", "--config-out", "x.toml", "--speed", "0"], "--speed", "0"),
    (["sim", "--config-out", "x.toml", "--transport", "udp"], "--transport", "udp"),
    (["sim", "--config-out", "x.toml", "--protocol", "morse"], "--protocol", "morse"),
    (["probe", "--timeout", "inf"], "--timeout", "inf"),
    (["probe", "--device-id", "300"], "--device-id", "300"),
    (["probe", "--baudrate", "0"], "--baudrate", "0"),
    (["init", "--out", "x.toml", "--device-id", "x"], "--device-id", "x"),
    (["identify", "r.csv", "--leg-length", "-5"], "--leg-length", "-5"),
    (["identify", "r.csv", "--rho-min", "nan"], "--rho-min", "nan"),
    (["identify", "r.csv", "--rho-max", "abc"], "--rho-max", "abc"),
    (["identify", "r.csv", "--mount-error", "inf"], "--mount-error", "inf"),
    (["identify", "r.csv", "--model", "everything"], "--model", "everything"),
    (["design", "--leg-length", "abc"], "--leg-length", "abc"),
    (["design", "--rho-min", "inf"], "--rho-min", "inf"),
    (["design", "--rho-max", "x"], "--rho-max", "x"),
    (["compensate", "p.ngc", "--run", "r", "--tolerance", "abc"], "--tolerance", "abc"),
    (["compensate", "p.ngc", "--run", "r", "--work-offset", "nan,0,0"], "--work-offset",
     "nan,0,0"),
    (["export", "r", "--to", "fanuc"], "--to", "fanuc"),
    (["schema", "everything"], "kind", "everything"),
    (["compare", "a"], "RUN_B", ""),
    (["history", "--frobnicate"], "--frobnicate", ""),
    (["report"], "RUN_DIR", ""),
    (["launch"], "launch", ""),
]


def _one_line(err: str) -> str:
    assert "internal error" not in err and "Traceback" not in err, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("argv,code,named", PATHS, ids=[" ".join(a[:3]) for a, _, _ in PATHS])
def test_a_path_that_cannot_be_used_is_one_line_naming_it(
        orthocal, places, argv: list[str], code: int, named: str) -> None:
    o = orthocal(*[a.format(**places) for a in argv])
    line = _one_line(o.err)
    assert o.code == code, line
    assert line.startswith("orthocal: error: " if code == 2 else "orthocal: failed: "), line
    assert named.format(**places) in line
    assert not Path(places["tmp"], "no").exists()  # nothing made on the way
    assert not Path(NOWHERE).exists()


@pytest.mark.parametrize("argv,option,value", VALUES, ids=[" ".join(a) for a, _, _ in VALUES])
def test_a_bad_argument_value_is_one_line_naming_option_and_value(
        orthocal, argv: list[str], option: str, value: str) -> None:
    o = orthocal(*argv, "--out", "never-made") if argv[0] == "run" else orthocal(*argv)
    line = _one_line(o.err)
    assert o.code == 2 and line.startswith("orthocal: error: "), line
    assert option in line and (not value or repr(value) in line), line
    assert not Path("never-made").exists()


def test_sim_never_overwrites_a_config(orthocal, places) -> None:
    before = Path(places["config"]).read_text()
    o = orthocal("sim", "--config-out", places["config"], "--seed", "3")
    assert o.code == 2 and "not overwritten" in _one_line(o.err)
    assert Path(places["config"]).read_text() == before


class _FullDisk(io.StringIO):
    def write(self, text: str) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_is_said_naming_the_file(orthocal, places, monkeypatch) -> None:
    # sim's config: the file made, its write refused (ENOSPC), nothing half-written left
    from station.commands import given_paths

    real_open = open

    def full_open(path: object, mode: str = "r", **kw: object) -> io.StringIO:
        real_open(path, mode, **kw).close()  # type: ignore[call-overload]
        return _FullDisk()

    target = Path(places["tmp"], "sim.toml")
    with monkeypatch.context() as m:
        m.setattr(given_paths, "open", full_open, raising=False)
        o = orthocal("sim", "--config-out", str(target), "--seed", "3")
    line = _one_line(o.err)
    assert o.code == 2 and f"--config-out {target}" in line and "disk is full" in line
    assert not target.exists()
    # report and compensate write whole files by rename: the rename's file refused
    from drivers import files
    from station.commands import report

    def refuse(path: Path, text: str, mode: int = 0o644) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    for argv, named in (
            (["report", places["run"], "--no-figures", "--out", f"{places['tmp']}/r.html"],
             "r.html"),
            (["compensate", places["program"], "--run", places["run"]], "part.compensated")):
        with monkeypatch.context() as m:
            m.setattr(files, "write_atomic", refuse)  # compensate's, imported as it runs
            m.setattr(report, "write_atomic", refuse)
            o = orthocal(*argv)
        line = _one_line(o.err)
        assert o.code == 2 and named in line and "disk is full" in line, line


class _Gone(io.TextIOBase):
    """A stdout whose reader has gone: a pipe whose read end is closed, every write
    EPIPE."""

    def __init__(self) -> None:
        read, self.fd = os.pipe()
        os.close(read)

    def fileno(self) -> int:
        return self.fd

    def isatty(self) -> bool:
        return False

    def write(self, text: str) -> int:
        raise BrokenPipeError(errno.EPIPE, "Broken pipe")

    def flush(self) -> None:
        pass

    def close(self) -> None:
        os.close(self.fd)


CLOSED: list[Callable[[dict[str, str]], list[str]]] = [
    lambda p: ["schema", "result"],
    lambda p: ["history", "--out", p["runs"]],
    lambda p: ["history", "--out", p["runs"], "--json"],
    lambda p: ["compare", p["run"], p["run_b"]],
    lambda p: ["export", p["run"], "--to", "csv"],
    lambda p: ["report", p["run"], "--no-figures"],
    lambda p: ["compensate", p["program"], "--run", p["run"]],
    lambda p: ["identify", p["csv"]],
    lambda p: ["probe", "/dev/null", "--timeout", "0.1"],
    lambda p: ["resume", p["run"]],  # finished: its summary again
]


@pytest.mark.parametrize("argv", CLOSED, ids=["schema", "history", "history-json", "compare",
                                              "export", "report", "compensate", "identify",
                                              "probe", "resume"])
def test_a_closed_stdout_ends_quietly(orthocal, places, monkeypatch, tmp_path, argv) -> None:
    gone = _Gone()
    with monkeypatch.context() as m:
        m.setattr(sys, "stdout", gone)
        o = orthocal(*argv(places))
    gone.close()
    assert o.code == 1, o.err
    assert not [line for line in o.err.splitlines() if line.startswith(
        ("orthocal: error", "orthocal: failed", "orthocal: internal"))], o.err
    assert "Traceback" not in o.err


def _orthocal(*argv: str, **kw: object) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "station", *argv], stderr=subprocess.PIPE,
                            text=True, **kw)  # type: ignore[call-overload]


def test_history_into_head_ends_quietly(places) -> None:
    # the real pipe: `orthocal history | head -1`, and a reader that closed at once
    history = _orthocal("history", "--out", places["runs"], stdout=subprocess.PIPE)
    head = subprocess.run(["head", "-1"], stdin=history.stdout, capture_output=True,
                          text=True, timeout=60)
    history.stdout.close()
    err = history.stderr.read()
    history.stderr.close()
    assert history.wait(timeout=60) in (0, 1) and err == "", err
    assert head.stdout.startswith("started")
    schema = _orthocal("schema", "journal", stdout=subprocess.PIPE)
    schema.stdout.close()  # before it writes: every write of its is EPIPE
    err = schema.stderr.read()
    schema.stderr.close()
    assert schema.wait(timeout=60) == 1 and err == "", err
