"""A command line in a process of its own, forked from the test worker instead of
started afresh: the same code in a real, separate process (its own pid, its own
signals, killed by SIGKILL as any is, its exit status and output read as
subprocess.Popen's), without the second and a half of imports a new interpreter
pays before the station's first line runs (numpy, scipy.optimize, pymodbus,
SQLAlchemy). test_interrupt kills and resumes some thirty runs.

What a fork does not show is a fresh interpreter's start: ``python -m station``
itself. The tests that use this keep runs of that too (test_interrupt's
uninterrupted references and its kill from outside), and every other test of the
command line in a subprocess starts one.

The child gets what ``subprocess.Popen(..., cwd=, env=)`` would give it: the
working directory, exactly that environment, stdin from /dev/null, stdout and
stderr on pipes, Ctrl-C at Python's default (KeyboardInterrupt) and unblocked, as
a terminal starts a command. It runs ``code`` with ``sys.argv`` and leaves by
``os._exit`` with the status ``python`` would exit with: the worker's atexit
handlers, pytest's among them, are not the child's to run.
"""

from __future__ import annotations

import os
import selectors
import signal
import sys
import time
import traceback
import warnings
from pathlib import Path

from builders import Completed

#: ``python -m station``, as code for :class:`Forked`.
STATION = "import sys\nfrom station.commands.cli import main\nsys.exit(main(sys.argv[1:]))\n"

#: How long ``communicate()`` without a timeout waits at most (a test never waits
#: for ever).
LIMIT_S = 120.0


def preload() -> None:
    """What a run imports, loaded in the worker before it forks: otherwise the
    first child of each worker would pay for them again, and every later one too
    until the worker happened to import them itself."""
    import scipy.optimize
    import scipy.special  # noqa: F401

    import station.commands.run
    import station.commands.simulate.launch
    import station.history.store  # noqa: F401


class Forked:
    """``python -c CODE ARGV...`` as a forked child (module docstring), with the parts
    of subprocess.Popen the tests use: ``pid``, ``poll``, ``send_signal``, ``kill``,
    ``communicate(timeout)`` and ``returncode``."""

    def __init__(self, code: str, argv: list[str], cwd: Path, env: dict[str, str]) -> None:
        preload()
        out_r, out_w = os.pipe()
        err_r, err_w = os.pipe()
        sys.stdout.flush()
        sys.stderr.flush()
        with warnings.catch_warnings():  # Python 3.12+ warns of forking with threads:
            warnings.simplefilter("ignore", DeprecationWarning)  # the child runs none of theirs
            pid = os.fork()
        if pid == 0:  # the child: never returns
            os.close(out_r)
            os.close(err_r)
            _child(code, argv, cwd, env, out_w, err_w)
        os.close(out_w)
        os.close(err_w)
        self.pid = pid
        self.returncode: int | None = None
        self._pipes = {out_r: bytearray(), err_r: bytearray()}
        self._out, self._err = out_r, err_r
        # Which of the two are still open: a closed fd's number may be handed to
        # another file at once, so "is it open?" cannot be asked of the number.
        self._open = {out_r, err_r}

    def poll(self) -> int | None:
        if self.returncode is None:
            done, status = os.waitpid(self.pid, os.WNOHANG)
            if done:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, sig)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def communicate(self, timeout: float | None = None) -> tuple[str, str]:
        """Both pipes read to their end and the child reaped, within ``timeout``
        seconds (TimeoutError beyond it; the caller kills)."""
        limit = LIMIT_S if timeout is None else timeout
        deadline = time.monotonic() + limit
        with selectors.DefaultSelector() as sel:
            for fd in self._open:
                sel.register(fd, selectors.EVENT_READ)
            while sel.get_map():
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"child {self.pid} still running after {limit} s")
                for key, _ in sel.select(left):
                    chunk = os.read(key.fd, 65536)
                    if chunk:
                        self._pipes[key.fd] += chunk
                    else:
                        sel.unregister(key.fd)
                        os.close(key.fd)
                        self._open.discard(key.fd)
        while self.poll() is None:
            if time.monotonic() > deadline:
                raise TimeoutError(f"child {self.pid} still running after {limit} s")
            time.sleep(0.005)
        return (self._pipes[self._out].decode(errors="replace"),
                self._pipes[self._err].decode(errors="replace"))

    def close(self) -> None:
        """Kill (if still running), reap, and close what is left open."""
        if self.poll() is None:
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
            self.returncode = -signal.SIGKILL
        for fd in self._open:
            os.close(fd)
        self._open.clear()


def _child(code: str, argv: list[str], cwd: Path, env: dict[str, str], out_w: int,
           err_w: int) -> None:
    status = 1
    try:
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.dup2(out_w, 1)
        os.dup2(err_w, 2)
        for fd in (null, out_w, err_w):
            os.close(fd)
        sys.stdin = open(0, encoding="utf-8", closefd=False)
        sys.stdout = open(1, "w", encoding="utf-8", buffering=1, closefd=False)
        sys.stderr = open(2, "w", encoding="utf-8", buffering=1, closefd=False)
        os.chdir(cwd)
        os.environ.clear()
        os.environ.update(env)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        sys.argv = ["-c", *argv]
        exec(compile(code, "<forked>", "exec"), {"__name__": "__main__"})
        status = 0
    except SystemExit as exc:
        status = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        if not isinstance(exc.code, int | None):
            print(exc.code, file=sys.stderr)
    except BaseException:
        traceback.print_exc()
        status = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(status)


def run(argv: list[str], cwd: Path, code: str = STATION, env: dict[str, str] | None = None,
        timeout: float = LIMIT_S) -> Completed:
    """subprocess.run(..., capture_output=True, text=True) of a forked child: ``code``
    (``python -m station`` by default) with ``argv``, from ``cwd``, in ``env`` (this
    process's by default)."""
    child = Forked(code, argv, cwd, dict(os.environ) if env is None else env)
    try:
        out, err = child.communicate(timeout)
    finally:
        child.close()
    return Completed(child.returncode if child.returncode is not None else -9, out, err)
