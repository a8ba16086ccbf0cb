"""The operator console: live on a terminal, one line per step in a log, silent
when disabled, no thread left running, prompts that never guess yes."""

from __future__ import annotations

import io
import re
import threading

import pytest

from station.console.terminal import RunProgress, format_eta
from station.plan.steps import Read, build_plan


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


class TtyStringIO(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_plain_mode_writes_one_line_per_update_with_eta() -> None:
    stream, clock = io.StringIO(), FakeClock()
    with RunProgress(12, stream=stream, clock=clock) as progress:
        assert progress.mode == "plain"
        progress.update("x", "Π_x^+", 1, 3, 0)
        clock.now += 60.0
        progress.update("x", "Π_x^-", 1, 3, 3)
        progress.message("mount the indicators on leg y")
    lines = stream.getvalue().splitlines()
    assert lines[0] == "[0/12] setup x · Π_x^+ · cycle 1/3 · estimating time left"
    # 3 steps took 60 s, so 9 steps take about 3 min
    assert lines[1] == "[3/12] setup x · Π_x^- · cycle 1/3 · about 3 min left"
    assert lines[2] == "mount the indicators on leg y"
    assert "\x1b" not in stream.getvalue()  # no terminal codes in a log file


def test_disabled_progress_is_silent() -> None:
    stream = TtyStringIO()
    with RunProgress(5, enabled=False, stream=stream) as progress:
        progress.update("y", "Π0", 2, 3, 4)
        progress.message("hello")
        with progress.paused():
            pass
    assert stream.getvalue() == ""


def test_default_stream_is_stderr_at_construction(capsys: pytest.CaptureFixture[str]) -> None:
    with RunProgress(2) as progress:
        progress.update("z", "Π_z^+", 1, 1, 1)
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "setup z · Π_z^+ · cycle 1/1" in captured.err


def test_live_mode_shows_state_and_stops_its_thread() -> None:
    stream, clock = TtyStringIO(), FakeClock()
    before = set(threading.enumerate())
    with RunProgress(10, stream=stream, clock=clock) as progress:
        assert progress.mode == "live"
        assert set(threading.enumerate()) - before, "expected rich's refresh thread"
        clock.now += 20.0
        progress.update("y", "Π_y^-", 2, 3, 5)
        progress.message("note for the operator")
        with progress.paused():
            stream.write("QUESTION?")
        progress.update("y", "Π0", 3, 3, 10)
    assert not [t for t in set(threading.enumerate()) - before if t.is_alive()]
    text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", stream.getvalue())
    assert "setup y · Π_y^- · cycle 2/3" in text
    assert "5/10" in text and "10/10" in text
    assert "about 20 s left" in text
    assert "note for the operator" in text
    assert "QUESTION?" in text


def test_live_thread_stops_when_the_run_raises() -> None:
    before = set(threading.enumerate())
    with pytest.raises(KeyError), RunProgress(3, stream=TtyStringIO()):
        raise KeyError("device fault")
    assert not [t for t in set(threading.enumerate()) - before if t.is_alive()]


def test_update_outside_with_block_is_an_error() -> None:
    with pytest.raises(RuntimeError):
        RunProgress(3, stream=io.StringIO()).update("x", "Π0", 1, 1, 1)


@pytest.mark.parametrize(
    ("seconds", "text"),
    [(None, "estimating time left"), (0.0, "no reading left as counted"),
     (3.2, "a few seconds left"),
     (42, "about 40 s left"),
     (3600, "about 60 min left"), (3 * 3600, "about 3.0 h left")],
)
def test_format_eta(seconds: float | None, text: str) -> None:
    assert format_eta(seconds) == text


def test_time_left_never_rises_until_the_total_is_rebased_and_says_so() -> None:
    stream, clock = io.StringIO(), FakeClock()
    with RunProgress(10, stream=stream, clock=clock) as progress:
        clock.now += 8.0
        progress.update("x", "Π0", 1, 3, 1)  # 8 s a step: 72 s left
        clock.now += 40.0
        progress.update("x", "Π_x^+", 1, 3, 2)  # 24 s a step would say 192 s
        clock.now += 5.0
        progress.update("x", "Π_x^-", 1, 3, 3)  # 53/3 × 7 ≈ 124 s
        progress.rebase(5, "another cycle (verify setup 1, cycle 4)")
        clock.now += 5.0
        progress.update("x", "Π0", 4, 3, 4)  # 58/4 × 11 ≈ 160 s: rises, after saying
    lines = stream.getvalue().splitlines()
    assert lines[0] == "[1/10] setup x · Π0 · cycle 1/3 · about 70 s left"
    assert lines[1].endswith("about 70 s left") and lines[2].endswith("about 70 s left")
    assert lines[3] == ("+5 readings: another cycle (verify setup 1, cycle 4); 15 in all, "
                        "time left estimated again")
    # the cycle past the planned three is counted as one of four, never "4/3"
    assert lines[4] == "[4/15] setup x · Π0 · cycle 4/4 · about 3 min left"


def test_live_bar_counts_against_the_rebased_total() -> None:
    stream, clock = TtyStringIO(), FakeClock()
    with RunProgress(4, stream=stream, clock=clock) as progress:
        progress.update("x", "Π0", 1, 1, 4)
        progress.rebase(2, "another pass (verify 2)")
        progress.update("x", "Π0", 1, 1, 5)
    text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", stream.getvalue())
    assert "5/6" in text and "+2 readings: another pass (verify 2)" in text
    assert "5/4" not in text


def test_done_is_said_at_the_end_alone_however_the_total_grows() -> None:
    # A run reaches the readings counted (the usual measurement and one verification),
    # then takes a cycle more in a mounting and another pass: it said "[86/86] ... done"
    # there and counted on. Only the run's end says done.
    from builders import station_config

    from station.console.progress import Progress

    plan = build_plan(station_config())
    stream = io.StringIO()
    progress = Progress(plan, verify=True)
    progress.bar = RunProgress(progress.bar.total_steps, stream=stream, clock=FakeClock())

    def read(phase: str, pass_index: int, cycle_shift: int = 0) -> None:
        for step in plan.steps("m", pass_index):
            if isinstance(step, Read):
                progress("read", phase=phase, setup=step.setup, sign=step.sign,
                         cycle=step.cycle + cycle_shift)

    with progress:
        read("m", 0)
        read("v", 1)  # every reading counted is taken: the count at its total
        first = plan.setups[0].index
        for step in plan.steps("m", 1):  # a cycle more in the first setup
            if isinstance(step, Read) and step.setup == first and step.cycle == 1:
                progress("read", phase="v", setup=step.setup, sign=step.sign,
                         cycle=plan.cycles + 1)
        read("v2", 2)  # and another pass
        before_end = stream.getvalue().splitlines()
        progress.finished()
    lines = stream.getvalue().splitlines()
    counts = [tuple(map(int, m.groups())) for line in lines
              if (m := re.match(r"\[(\d+)/(\d+)\]", line))]
    assert all(done <= total for done, total in counts)
    reached = [line for line in before_end if re.match(r"\[(\d+)/\1\]", line)]
    assert reached and all(line.endswith("no reading left as counted") for line in reached)
    assert not [line for line in before_end if "done" in line.split(" · ")[-1]]
    assert any(line.startswith("+") and "another cycle" in line for line in before_end)
    assert any(line.startswith("+") and "another pass" in line for line in before_end)
    done, total = counts[-1]
    assert lines[-1] == f"[{done}/{total}] done: every reading taken" and done == total
    assert done == len(before_end) - sum(1 for line in before_end if line.startswith("+"))
