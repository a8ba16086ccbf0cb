"""The operator console: run progress, yes/no prompts and error lines.

Everything here writes to stderr (or the stream given), never stdout: with
``--json`` the only thing on stdout is the JSON document, and a progress bar or a
prompt in it would break whatever parses it.
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Iterator
from types import TracebackType
from typing import TextIO

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TaskID,
    TextColumn,
)
from rich.text import Text


def _is_tty(stream: TextIO) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or the stream is closed
        return False


def _stop_and_join(progress: Progress) -> None:
    """Stop a live display and wait for its refresh thread to end.

    rich's stop() only signals the thread (it holds the display lock, so it cannot
    join); the thread then lingers up to one refresh period. The station promises
    no threads left behind, so join it here, outside the lock.
    """
    thread = getattr(progress.live, "_refresh_thread", None)
    progress.stop()
    if thread is not None:
        thread.join(timeout=5.0)


#: The time left when every reading counted so far is taken: not "done", since the
#: run may count more (another cycle, another pass) until it ends (RunProgress.finish).
NONE_LEFT = "no reading left as counted"


def format_eta(seconds: float | None) -> str:
    """'about 3 min left': rounded coarsely, because the estimate is no better."""
    if seconds is None:
        return "estimating time left"
    if seconds <= 0:
        return NONE_LEFT
    if seconds < 10:
        return "a few seconds left"
    if seconds < 90:
        return f"about {round(seconds / 5) * 5:.0f} s left"
    if seconds < 90 * 60:
        return f"about {round(seconds / 60):.0f} min left"
    return f"about {seconds / 3600:.1f} h left"


class RunProgress:
    """Progress of a run: setup, posture, cycle and estimated time left.

    Three modes, chosen at construction: a live rich progress bar on a terminal;
    one plain line per update when the stream is a file or pipe (a log must not
    fill up with cursor movements); nothing at all when disabled.

    Use as a context manager: rich's live display runs a refresh thread, and
    leaving the ``with`` block stops and joins it even when the run raises.
    """

    def __init__(
        self,
        total_steps: int,
        *,
        enabled: bool = True,
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if total_steps < 0:
            raise ValueError(f"total_steps must be ≥ 0, got {total_steps}")
        # Resolved now, not as a default argument: a default would bind the
        # sys.stderr of import time and miss any later redirection.
        self.stream: TextIO = stream if stream is not None else sys.stderr
        self.total_steps = total_steps
        self.mode = "off" if not enabled else ("live" if _is_tty(self.stream) else "plain")
        self._clock = clock
        self._started_at: float | None = None
        self._steps_done = 0
        self._progress: Progress | None = None
        self._task: TaskID | None = None
        # The time left last shown: the next is never more (the estimate wanders as
        # mountings and moves alternate), until the total is re-based (rebase).
        self._eta_shown: float | None = None

    # -- context -------------------------------------------------------------

    def __enter__(self) -> RunProgress:
        self._started_at = self._clock()
        if self.mode == "live":
            console = Console(file=self.stream, force_terminal=True, highlight=False)
            self._progress = Progress(
                SpinnerColumn(),
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.fields[eta]}"),
                console=console,
                # stdout belongs to --json; stderr may be captured only if it is ours.
                redirect_stdout=False,
                redirect_stderr=self.stream is sys.stderr,
                refresh_per_second=4,
            )
            self._task = self._progress.add_task(
                "starting", total=self.total_steps or None, eta=format_eta(None)
            )
            self._progress.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._stop()

    def _stop(self) -> None:
        if self._progress is not None:
            progress, self._progress = self._progress, None
            _stop_and_join(progress)

    # -- updates ---------------------------------------------------------------

    def eta_s(self) -> float | None:
        """Seconds left, assuming the remaining steps take as long as the done ones."""
        if self._started_at is None or self._steps_done <= 0:
            return None
        elapsed = self._clock() - self._started_at
        remaining = max(self.total_steps - self._steps_done, 0)
        return elapsed / self._steps_done * remaining

    def rebase(self, added: int, why: str) -> None:
        """The run takes ``added`` steps more than counted (another cycle, another
        pass): the total grows, and says so, and the time left is estimated afresh
        (it may rise, here only)."""
        if added <= 0:
            return
        self.total_steps += added
        self._eta_shown = None
        self.message(f"+{added} readings: {why}; {self.total_steps} in all, "
                     "time left estimated again")

    def update(self, setup: str, posture: str, cycle: int, cycles: int, steps_done: int) -> None:
        """Report that ``steps_done`` of ``total_steps`` are done and where the run is.
        The count never passes its total (a step beyond it grows the total, as a
        caller that counted short would need), and the time left never rises
        between re-basings."""
        if self.mode == "off":
            return
        if self._started_at is None:
            raise RuntimeError("RunProgress.update() outside its 'with' block")
        self._steps_done = steps_done
        self.total_steps = max(self.total_steps, steps_done)
        where = f"setup {setup} · {posture} · cycle {cycle}/{max(cycles, cycle)}"
        left = self.eta_s()
        if left is not None and self._eta_shown is not None:
            left = min(left, self._eta_shown)
        self._eta_shown = left if left is not None else self._eta_shown
        eta = format_eta(left)
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, completed=steps_done, total=self.total_steps,
                                  description=where, eta=eta)
        elif self.mode == "plain":
            self._line(f"[{steps_done}/{self.total_steps}] {where} · {eta}")

    def finish(self) -> None:
        """The run has taken its last reading: "done", said here alone (the total may
        grow until the end), the count made what was taken (a run that needed fewer
        passes than counted ends below its total)."""
        if self.mode == "off" or self._started_at is None:
            return
        self.total_steps = self._steps_done
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, completed=self._steps_done,
                                  total=self.total_steps, eta="done")
        elif self.mode == "plain":
            self._line(f"[{self._steps_done}/{self.total_steps}] done: every reading taken")

    def message(self, text: str) -> None:
        """A line for the operator, printed above the live bar rather than through it."""
        if self.mode == "off":
            return
        if self._progress is not None:
            self._progress.console.print(Text(text))
        else:
            self._line(text)

    @contextlib.contextmanager
    def paused(self) -> Iterator[None]:
        """Take the live bar off the screen while the operator answers a prompt;
        a redrawing bar would overwrite the question and the typed answer."""
        progress = self._progress
        if progress is None:
            yield
            return
        _stop_and_join(progress)
        try:
            yield
        finally:
            if self._progress is progress:  # not stopped for good meanwhile
                progress.start()

    def _line(self, text: str) -> None:
        self.stream.write(text + "\n")
        self.stream.flush()
