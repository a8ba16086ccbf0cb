"""The operator: mounting prompts and confirmations.

``ConsoleOperator`` asks a person on the terminal (or answers yes to everything
with ``--yes``); ``VirtualOperator`` stands in for one in ``--simulate``: it
mounts the simulated indicators where the prompt says and answers yes.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from contextlib import AbstractContextManager, nullcontext
from typing import Protocol, TextIO

from orthocal.postures import MIDDLE
from station.console.joint_prompts import JointPrompt, joint_instruction
from station.errors import BadInput, RunFailed
from station.plan.joint_test_plan import FaceSet, JointMount, JointTestPlan
from station.plan.mounting import GaugeMount, MountingSheet
from station.record.phase import Phase

# Keys typed ahead are dropped through the terminal's own module: termios on POSIX,
# msvcrt on Windows; with neither, nothing is dropped (a prompt is still answered).
try:
    import termios
except ImportError:  # not POSIX
    termios = None  # type: ignore[assignment]  # the module where there is one
try:
    import msvcrt
except ImportError:  # not Windows
    msvcrt = None  # type: ignore[assignment]  # the module where there is one
#: What asking a stream that is not a terminal raises (termios.error is no OSError).
_NOT_A_TERMINAL: tuple[type[Exception], ...] = (AttributeError, OSError, ValueError) + (
    () if termios is None else (termios.error,))


class Operator(Protocol):
    def mount(self, phase: str, setup: int, leg: str, indicators: Mapping[str, str],
              all_names: Sequence[str], at: float = MIDDLE, *,
              sheet: MountingSheet | None = None, picture: str | None = None,
              count: Mapping[str, int] | None = None, remount: str | None = None) -> None:
        """Mount ``indicators`` (name -> direction) on ``leg`` at Π0, at the fraction
        ``at`` of its length from the carriage's joint (the middle by default), and
        remove the others; ``sheet``, ``picture``, ``count``, ``remount``: what the
        prompt says beside it (:func:`mount_instruction`). Returns once done; raises
        RunFailed if the operator aborts."""
        ...

    def confirm(self, question: str) -> bool: ...

    def joint_test(self, step: JointPrompt, test: JointTestPlan, all_names: Sequence[str],
                   *, picture: str | None = None) -> None:
        """The operator's part of joint ``test.axis``'s own test: mount its gauge on the
        carriage against the reference (taking every other gauge off), set a face at
        the plunger, or take the gauge and the reference off
        (station.console.joint_prompts). Returns once done; raises RunFailed if the
        operator aborts."""
        ...

    def attach(self, say: Callable[[str], None],
               pause: Callable[[], AbstractContextManager[None]]) -> None:
        """The run's live display: ``say`` prints a line above it, ``pause`` takes it
        off the screen while the operator is asked something."""
        ...


def gauge_words(g: GaugeMount) -> str:
    """One gauge's line of the prompt: its direction, side and face, its sign and
    its preload window (station.plan.mounting's conventions)."""
    rev = " (reversed)" if g.reversed else ""
    window = (f"push in {g.window_mm[0]:.2f}–{g.window_mm[1]:.2f} mm"
              if g.window_mm is not None else f"push in {g.preload_mm:.2f} mm")
    return (f"{g.name} along {g.face}{rev}: on the {g.face} side, plunger onto the "
            f"{g.face} face; reads + as the leg moves {g.face}; {window}")


def sheet_lines(sheet: MountingSheet) -> list[str]:
    """The mounting in words, as its picture draws it: the stand's place and
    tolerance, the bar, each gauge."""
    frac = "L/2" if sheet.middle else f"{sheet.at:g}·L"
    return [f"stand: {sheet.from_carriage_mm:.1f} mm ({frac}) from the centre of the "
            f"carriage's joint, along the leg; {sheet.tolerance_words()}",
            "plungers: square to the leg, on the parallelogram's bar on their side "
            f"(the same bar at every mounting of leg {sheet.leg})",
            *(gauge_words(g) for g in sheet.gauges)]


def mount_instruction(phase: str, setup: int, leg: str, indicators: Mapping[str, str],
                      all_names: Sequence[str], at: float = MIDDLE, *,
                      sheet: MountingSheet | None = None, picture: str | None = None,
                      count: Mapping[str, int] | None = None,
                      remount: str | None = None) -> str:
    """The mount prompt, a few short lines: what to mount where and what to remove,
    the picture (``picture``: its path) and, from ``sheet`` (station.plan.mounting:
    the plan check's preload windows, every stop and move of the setup kept inside
    the stroke less the guard's margin), the stand's place and tolerance, the bar and
    each plunger's side, face, sign and window; the mountings the run expects
    (``count``, at its first: closed_loop.mountings_expected) and, where gauges left
    on from the pass before are mounted again, why (``remount``)."""
    # "v", "v2", ...: the verification after each write-back of the closed loop.
    what = Phase.parse(phase).kind
    others = [n for n in all_names if n not in indicators]
    remove = f"; remove {', '.join(others)}" if others else ""
    where = "the middle of" if at == MIDDLE else \
        f"{at:g} of the length (from the carriage's joint) of"
    lines = [f"{what}, setup {setup + 1}: the machine is at Π0. Mount "
             f"{', '.join(indicators)} against {where} leg {leg}{remove}."]
    if picture:
        lines.append(f"picture: {picture}")
    if sheet is not None:
        lines.extend(sheet_lines(sheet))
    else:
        lines.extend(f"{n} along {d}" for n, d in indicators.items())
    if remount:
        lines.append(f"Mounted again, not kept from the setup before: with the "
                     f"write-back's shift, {remount}.")
    if count:
        lines.append(f"Mountings: expect {count['usual']} in all ({count['fewest']} if "
                     f"the machine is within tolerance; {count['per_write_back']} more per "
                     f"further write-back; up to {count['most']}).")
    return "\n  ".join(lines)


class ConsoleOperator:
    def __init__(self, yes: bool, stream_in: TextIO | None = None,
                 stream_out: TextIO | None = None) -> None:
        self.yes = yes
        # Set by the run to take a live progress bar off the screen while asking.
        self.pause: Callable[[], AbstractContextManager[None]] = nullcontext
        self._in = stream_in if stream_in is not None else sys.stdin
        self._out = stream_out if stream_out is not None else sys.stderr

    def attach(self, say: Callable[[str], None],
               pause: Callable[[], AbstractContextManager[None]]) -> None:
        del say  # a prompt is its own line: the bar steps aside for it instead
        self.pause = pause

    @staticmethod
    def require_tty_or_yes(yes: bool) -> None:
        """Real devices need someone to mount indicators: refuse to start otherwise."""
        if not yes and not sys.stdin.isatty():
            raise BadInput("operator prompts need a terminal (stdin is not a TTY); "
                           "pass --yes to answer them automatically")

    def _say(self, text: str) -> None:
        # Every line for the operator goes out with the live bar off the screen: a
        # redrawing bar and a direct write land on one line ("… s leftmeasurement").
        with self.pause():
            print(text, file=self._out, flush=True)

    def _discard_typeahead(self) -> None:
        """Forget keys typed before the question was shown: an Enter pressed during
        a move must not answer the next prompt (a write-back among them), and an
        answer consumed before its question would let the live bar redraw over it."""
        try:
            if not self._in.isatty():
                return  # a pipe, a test stream: nothing typed ahead to drop
            if termios is not None:
                termios.tcflush(self._in.fileno(), termios.TCIFLUSH)
            elif msvcrt is not None and self._in is sys.stdin:
                while msvcrt.kbhit():  # the console's keys not yet read
                    msvcrt.getwch()
        except _NOT_A_TERMINAL:
            pass  # not a terminal after all: nothing typed ahead to drop

    def _ask(self, prompt: str, preamble: str = "") -> str:
        with self.pause():
            self._discard_typeahead()
            if preamble:
                print(preamble, file=self._out)
            print(prompt, end="", file=self._out, flush=True)
            line = self._in.readline()
        if not line:  # EOF: nobody is there to answer
            raise RunFailed("operator input closed (EOF) while waiting for an answer")
        return line.strip().lower()

    def mount(self, phase: str, setup: int, leg: str, indicators: Mapping[str, str],
              all_names: Sequence[str], at: float = MIDDLE, *,
              sheet: MountingSheet | None = None, picture: str | None = None,
              count: Mapping[str, int] | None = None, remount: str | None = None) -> None:
        instruction = mount_instruction(phase, setup, leg, indicators, all_names, at,
                                        sheet=sheet, picture=picture, count=count,
                                        remount=remount)
        if self.yes:
            self._say(instruction)
            return
        answer = self._ask("Press Enter when done (or type 'abort'): ", instruction)
        if answer in ("a", "abort", "q", "quit", "n", "no"):
            raise RunFailed(f"aborted by the operator at setup {setup + 1}")

    def confirm(self, question: str) -> bool:
        if self.yes:
            self._say(f"{question} [y/N] yes (--yes)")
            return True
        return self._ask(f"{question} [y/N] ") in ("y", "yes")

    def joint_test(self, step: JointPrompt, test: JointTestPlan, all_names: Sequence[str],
                   *, picture: str | None = None) -> None:
        instruction = joint_instruction(step, test, [n for n in all_names if n != test.gauge],
                                        picture)
        if self.yes:
            self._say(instruction)
            return
        answer = self._ask("Press Enter when done (or type 'abort'): ", instruction)
        if answer in ("a", "abort", "q", "quit", "n", "no"):
            raise RunFailed(f"aborted by the operator in joint {test.axis}'s own test")


class JointHands(Protocol):
    """What a virtual operator does for the station's own joint test: a gauge clamped to
    a carriage on a reference's datum face, a face set, the reference taken off
    (drivers.sim: the virtual station's and the fake rig's)."""

    def mount_joint_gauge(self, name: str, axis: str, plunger: int) -> None: ...

    def set_face(self, axis: str, face_mm: float) -> None: ...

    def remove_reference(self, axis: str) -> None: ...


class VirtualOperator:
    """Mounts simulated indicators through ``mount_fn(name, leg, direction, at=…)`` and
    ``unmount_fn(name)``; says yes to every question. ``place_fn("phase:setup")``,
    if given, is told which placement the next mountings are, so that a simulated
    stand placed again for the same setup after a resume stands where it stood.
    ``joint_hands``: the simulator's hands for the station's own joint test."""

    def __init__(self, mount_fn: Callable[..., None],  # (name, leg, direction, *, at)
                 unmount_fn: Callable[[str], None],
                 say: Callable[[str], None] | None = None,
                 place_fn: Callable[[str], None] | None = None,
                 joint_hands: JointHands | None = None) -> None:
        self._mount = mount_fn
        self._unmount = unmount_fn
        self._say = say
        self._place = place_fn
        self._hands = joint_hands

    def mount(self, phase: str, setup: int, leg: str, indicators: Mapping[str, str],
              all_names: Sequence[str], at: float = MIDDLE, *,
              sheet: MountingSheet | None = None, picture: str | None = None,
              count: Mapping[str, int] | None = None, remount: str | None = None) -> None:
        for name in all_names:
            if name not in indicators:
                self._unmount(name)
        if self._place is not None:
            self._place(f"{phase}:{setup}")
        for name, direction in indicators.items():
            self._mount(name, leg, direction, at=at)
        if self._say is not None:
            self._say("[virtual operator] " + mount_instruction(
                phase, setup, leg, indicators, all_names, at, sheet=sheet, picture=picture,
                count=count, remount=remount))

    def confirm(self, question: str) -> bool:
        if self._say is not None:
            self._say(f"[virtual operator] {question} yes")
        return True

    def joint_test(self, step: JointPrompt, test: JointTestPlan, all_names: Sequence[str],
                   *, picture: str | None = None) -> None:
        if self._hands is None:
            raise RunFailed("the virtual operator has no hands for a joint's own test")
        if isinstance(step, JointMount):
            for name in all_names:
                self._unmount(name)
            self._hands.mount_joint_gauge(step.gauge, step.axis, test.sign)
        elif isinstance(step, FaceSet):
            self._hands.set_face(step.axis, step.face_mm)
        else:
            self._unmount(step.gauge)
            self._hands.remove_reference(step.axis)
        if self._say is not None:
            self._say("[virtual operator] " + joint_instruction(
                step, test, [n for n in all_names if n != test.gauge], picture))

    def attach(self, say: Callable[[str], None],
               pause: Callable[[], AbstractContextManager[None]]) -> None:
        del pause  # it asks nobody
        self._say = say
