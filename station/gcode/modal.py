"""The program's modal state line by line, and each block's motion (RS274/NGC as
LinuxCNC's G-code reference defines it): two words of one modal group in a block
are an error, a mode set on one line holds on the next, and axis words without a
motion word move in the current motion mode.

Modes at the start, until the program sets them: G21 (mm), G90, G91.1 (arc centres
relative to the start), G17, G94 and no motion mode (axis words before a G0..G3 are
refused: the controller's mode is not in the program). The tool's position before
the first motion is not known, so the first motion must be a G0 to X, Y and Z
(absolute): only from there on is a path defined to keep.

Positions are kept in the program's work coordinates in mm (inches × 25.4), each
block's own units remembered for writing it back.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from station.gcode.codes import (
    G_GROUP,
    M_GROUP,
    OTHER_AXES,
    REFUSED_G,
    REFUSED_M,
    named,
)
from station.gcode.words import Block, GcodeError, Word

MM_PER_INCH = 25.4
AXES = "XYZ"
#: G0, G1, G2, G3 as codes (the number times ten).
RAPID, LINE, CW, CCW = 0, 10, 20, 30
#: The planes' axes (indices into X, Y, Z): first and second axis of the plane (an arc
#: from the first toward the second is counterclockwise, G3) and the normal.
PLANES: dict[int, tuple[int, int, int]] = {170: (0, 1, 2), 180: (2, 0, 1), 190: (1, 2, 0)}
_P_USERS = (40, 640)  # G4 (dwell) and G64 (path tolerance) read P too


@dataclass
class Modal:
    """What the controller holds between lines."""

    motion: int | None = None  # None: G80, or no motion mode set yet
    plane: int = 170
    absolute: bool = True  # G90
    arc_absolute: bool = False  # G90.1
    inches: bool = False  # G20
    position: np.ndarray | None = None  # mm, work coordinates; None before the first move

    @property
    def scale(self) -> float:
        return MM_PER_INCH if self.inches else 1.0


@dataclass(frozen=True)
class ProgramMove:
    """A block's motion, in the program's work coordinates (mm). ``start`` None: the
    first motion, from where the program does not say. ``removed``: the words
    compensate writes anew (the motion word, the axis words, the arc's words)."""

    lineno: int
    code: int
    start: np.ndarray | None
    end: np.ndarray
    plane: int
    inches: bool
    absolute: bool
    removed: tuple[Word, ...]
    centre: np.ndarray | None = None  # G2/G3 with I, J, K: the centre (mm, work coords)
    radius: float | None = None  # G2/G3 with R (mm; negative: more than half a turn)
    turns: int = 1  # G2/G3 P: full or partial turns
    label: str = field(default="")  # the words naming the motion in a message

    @property
    def arc(self) -> bool:
        return self.code in (CW, CCW)


def interpret(block: Block, state: Modal) -> ProgramMove | None:
    """The motion ``block`` commands (None: none), ``state`` updated as the controller
    would be after it; GcodeError for what compensate refuses."""
    _check_letters(block)
    g = _grouped(block, "G", G_GROUP, REFUSED_G)
    _grouped(block, "M", M_GROUP, REFUSED_M)
    axes = {w.letter: w for w in block.words if w.letter in AXES}
    arc_words = [w for w in block.words if w.letter in "IJKR"]
    if block.delete and (g or axes):
        first = (list(g.values()) + list(axes.values()))[0]
        raise GcodeError(block.lineno, first.text, "block delete (/) before a G word or "
                         "an axis word: whether the controller runs the line is its "
                         "switch's, and the path after it depends on that")
    _set_modes(g, state)
    motion_word = g.get("motion")
    if motion_word is not None:
        state.motion = None if motion_word.code == 800 else motion_word.code
    if not axes:
        if arc_words or (motion_word is not None and motion_word.code in (CW, CCW)
                         and block.of("P")):
            _arc_without_axes(block, state, arc_words or block.of("P"))
        return None
    if state.motion is None:
        raise GcodeError(block.lineno, next(iter(axes.values())).text,
                         "an axis word with no motion mode (G80, or none set yet): give "
                         "G0, G1, G2 or G3")
    return _motion(block, state, axes, arc_words, motion_word, g)


def _check_letters(block: Block) -> None:
    """Each letter but G and M once; no axis compensate does not know; no E on a move."""
    seen: set[str] = set()
    for w in block.words:
        if w.letter in OTHER_AXES:
            raise GcodeError(block.lineno, w.text, f"axis {w.letter} is not compensated "
                             "(compensate knows X, Y and Z)")
        if w.letter in seen and w.letter not in "GM":
            raise GcodeError(block.lineno, w.text, f"{w.letter} twice in one block")
        seen.add(w.letter)
    if "E" in seen and seen & set(AXES):
        raise GcodeError(block.lineno, block.of("E")[0].text, "an E word on a move would "
                         "not be split with the move's segments")


def _grouped(block: Block, letter: str, groups: dict[int, str],
             refused: dict[int, str]) -> dict[str, Word]:
    """The block's G (or M) words by modal group; GcodeError for an unknown or refused
    code, or two of one group (M7 with M8 excepted)."""
    found: dict[str, Word] = {}
    for w in block.of(letter):
        code = w.code
        if abs(w.value * 10 - code) > 1e-9 or (code not in groups and code not in refused
                                                 and letter == "G"):
            raise GcodeError(block.lineno, w.text, f"not a {letter} code of RS274/NGC "
                             "compensate knows")
        if code in refused:
            raise GcodeError(block.lineno, w.text, refused[code])
        group = groups.get(code)
        if group is None:  # an M code of no group (M62..M68, M19, ...): harmless
            continue
        other = found.get(group)
        if other is not None and not (letter == "M" and {other.code, code} == {70, 80}):
            raise GcodeError(block.lineno, w.text, f"{other.text} and {w.text} are both of "
                             f"modal group {group!r}: one per block")
        found[group] = w
    return found


def _set_modes(g: dict[str, Word], state: Modal) -> None:
    """The modes a block sets, which act before its motion (RS274/NGC's order)."""
    if "units" in g:
        state.inches = g["units"].code == 200
    if "plane" in g:
        state.plane = g["plane"].code
    if "distance" in g:
        state.absolute = g["distance"].code == 900
    if "arc distance" in g:
        state.arc_absolute = g["arc distance"].code == 901


def _arc_without_axes(block: Block, state: Modal, words: list[Word]) -> None:
    first, second, _ = PLANES[state.plane]
    raise GcodeError(block.lineno, words[0].text,
                     f"{words[0].letter} with no move to use it: an arc (G2/G3) needs "
                     f"{AXES[first]} or {AXES[second]}" if state.motion in (CW, CCW)
                     else f"{words[0].letter} with no G2/G3 to use it")


def _motion(block: Block, state: Modal, axes: dict[str, Word], arc_words: list[Word],
            motion_word: Word | None, g: dict[str, Word]) -> ProgramMove:
    code = state.motion
    assert code is not None
    label = motion_word.text if motion_word is not None else next(iter(axes.values())).text
    start = state.position
    end = _target(block, state, axes, label)
    if start is None and not (code == RAPID and state.absolute and len(axes) == 3):
        raise GcodeError(block.lineno, label, "the tool's position before the program's "
                         "first motion is not known, so no path from it can be kept: "
                         "start with a G0 to X, Y and Z (absolute)")
    removed = [*axes.values(), *([motion_word] if motion_word is not None else [])]
    if code not in (CW, CCW):
        if arc_words:
            raise GcodeError(block.lineno, arc_words[0].text,
                             f"{arc_words[0].letter} with no G2/G3 to use it")
        state.position = end
        return ProgramMove(block.lineno, code, start, end, state.plane, state.inches,
                           state.absolute, tuple(removed), label=label)
    move = _arc(block, state, axes, arc_words, g, label, start, end, removed)
    state.position = end
    return move


def _target(block: Block, state: Modal, axes: dict[str, Word], label: str) -> np.ndarray:
    """Where the block's axis words put the tool (mm, work coordinates)."""
    end = np.full(3, np.nan) if state.position is None else state.position.copy()
    for k, letter in enumerate(AXES):
        w = axes.get(letter)
        if w is None:
            continue
        value = w.value * state.scale
        end[k] = value if state.absolute else end[k] + value
    if np.isnan(end).any():
        raise GcodeError(block.lineno, label, "the tool's position before the program's "
                         "first motion is not known: start with a G0 to X, Y and Z "
                         "(absolute)")
    return end


def _arc(block: Block, state: Modal, axes: dict[str, Word], arc_words: list[Word],
         g: dict[str, Word], label: str, start: np.ndarray | None, end: np.ndarray,
         removed: list[Word]) -> ProgramMove:
    """G2/G3: the centre (I, J, K) or radius (R) and the turns (P)."""
    assert start is not None  # the first motion is a G0
    assert state.motion is not None  # G2 or G3 (_motion)
    first, second, normal = PLANES[state.plane]
    if AXES[first] not in axes and AXES[second] not in axes:
        raise GcodeError(block.lineno, label, f"{AXES[first]} and {AXES[second]} both "
                         f"missing for an arc in the {named('G', state.plane)} plane")
    radius = [w for w in arc_words if w.letter == "R"]
    offsets = [w for w in arc_words if w.letter != "R"]
    if radius and offsets:
        raise GcodeError(block.lineno, offsets[0].text, "an arc given by both R and "
                         "I/J/K: one or the other")
    if not arc_words:
        raise GcodeError(block.lineno, label, "an arc needs R or its centre (I, J, K)")
    off_plane = "IJK"[normal]
    for w in offsets:
        if w.letter == off_plane:
            raise GcodeError(block.lineno, w.text, f"{off_plane} is not a centre word of "
                             f"the {named('G', state.plane)} plane")
    turns = _turns(block, g)
    removed = [*removed, *arc_words, *block.of("P")]
    move = functools.partial(ProgramMove, lineno=block.lineno, code=state.motion, start=start,
                             end=end, plane=state.plane, inches=state.inches,
                             absolute=state.absolute, removed=tuple(removed), turns=turns,
                             label=label)
    if radius:
        return move(radius=radius[0].value * state.scale)
    centre = start.copy()
    for k in (first, second):
        word = next((w for w in offsets if w.letter == "IJK"[k]), None)
        value = 0.0 if word is None else word.value * state.scale
        centre[k] = value if state.arc_absolute else start[k] + value
    return move(centre=centre)


def _turns(block: Block, g: dict[str, Word]) -> int:
    """An arc's P: a whole number of turns, at least 1 (default 1)."""
    p = block.of("P")
    if not p:
        return 1
    users = [w for w in g.values() if w.code in _P_USERS]
    if users:
        raise GcodeError(block.lineno, p[0].text, f"P of both the arc and {users[0].text}")
    value = p[0].value
    if value < 1 or value != int(value):
        raise GcodeError(block.lineno, p[0].text, "an arc's turns (P) must be a whole "
                         "number of at least 1")
    return int(value)
