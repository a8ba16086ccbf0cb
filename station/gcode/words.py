"""A line of G-code as a block of words (RS274/NGC as LinuxCNC's G-code reference
defines it): letters with numbers, comments in parentheses or after a semicolon,
the block-delete slash and the ``%`` delimiter line.

Our own tokenizer, not a library's: the G-code libraries on PyPI either are
unmaintained and GPL (pygcode, last release 2017) or read the 3D printers' dialect,
where a line without a G, M or T word is dropped and parentheses are no comment
(gcodeparser, gcodetools). What compensate needs of a line is small: each word with
where it stands in the line, so that everything it does not rewrite is written
back as it was.

What this dialect has and compensate will not guess at is refused here, naming the
word: parameters (``#``), expressions (``[...]``), O-words (subroutines, loops,
conditions) and polar coordinates (``@``, ``^``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

# A number as RS274/NGC writes one: sign, digits, at most one point; no exponent.
_NUMBER = re.compile(r"\s*([+-]?(?:\d+\.?\d*|\.\d+))")
_LETTERS = frozenset("ABCDEFGHIJKLMNPQRSTUVWXYZ$")


class GcodeError(ValueError):
    """A line compensate refuses, as ``LINE: WORD: why`` (the caller puts the file's
    name in front: ``part.ngc:12: G33: ...``)."""

    def __init__(self, lineno: int, word: str, why: str) -> None:
        super().__init__(f"{lineno}: {word}: {why}")
        self.lineno = lineno
        self.word = word
        self.why = why


@dataclass(frozen=True)
class Word:
    """One word: its letter (upper case), its number, and where it stands in the line
    (``start``/``end``: the slice of the line it was read from)."""

    letter: str
    value: float
    start: int
    end: int
    text: str  # as written, spaces between letter and number taken out

    @property
    def code(self) -> int:
        """A G or M number times ten (G38.2 is 382): exact, where floats are not."""
        return round(self.value * 10)


@dataclass(frozen=True)
class Block:
    """One line of the program as read (``text``, without its line end)."""

    lineno: int
    text: str
    words: tuple[Word, ...]
    delete: bool  # starts with "/": the controller's block-delete switch decides
    delimiter: bool  # a "%" line

    def of(self, letter: str) -> list[Word]:
        return [w for w in self.words if w.letter == letter]


def tokenize(line: str, lineno: int) -> Block:
    """The block of ``line`` (the ``lineno``-th of the file, from 1); GcodeError for
    what cannot be read or will not be compensated."""
    if line.strip() == "%":
        return Block(lineno, line, (), False, True)
    words: list[Word] = []
    delete = False
    i, n = 0, len(line)
    while i < n:
        ch = line[i]
        if ch.isspace():
            i += 1
        elif ch == "(":
            i = _comment_end(line, i, lineno)
        elif ch == ";":
            break  # the rest of the line is a comment
        elif ch == "/" and not words and not delete and not line[:i].strip():
            delete, i = True, i + 1
        else:
            word = _word(line, i, lineno)
            words.append(word)
            i = word.end
    return Block(lineno, line, tuple(words), delete, False)


def _comment_end(line: str, i: int, lineno: int) -> int:
    """The index after the comment that opens at ``line[i]``."""
    close = line.find(")", i + 1)
    if close < 0:
        raise GcodeError(lineno, line[i:i + 12].strip(), "comment not closed on its line")
    if "(" in line[i + 1:close]:
        raise GcodeError(lineno, line[i:close + 1], "a comment inside a comment is not "
                                                      "RS274/NGC")
    return close + 1


def _word(line: str, i: int, lineno: int) -> Word:
    """The word that starts at ``line[i]``."""
    ch = line[i]
    upper = ch.upper()
    if ch == "#":
        raise GcodeError(lineno, _shown(line, i), "parameters are not compensated: the "
                                                  "point would depend on values compensate "
                                                  "cannot know; write numbers")
    if ch == "[":
        raise GcodeError(lineno, _shown(line, i), "expressions are not compensated; write "
                                                  "numbers")
    if upper == "O":
        raise GcodeError(lineno, _shown(line, i), "O-words (subroutines, loops, "
                                                  "conditions) are not compensated: the "
                                                  "path would depend on the controller's "
                                                  "run; expand them into the program")
    if ch in "@^":
        raise GcodeError(lineno, _shown(line, i), "polar coordinates are not compensated; "
                                                  "write X, Y and Z")
    if upper not in _LETTERS:
        raise GcodeError(lineno, _shown(line, i), "not a word of RS274/NGC")
    m = _NUMBER.match(line, i + 1)
    if m is None:
        after = line[i + 1:].lstrip()[:1]
        why = ("expressions are not compensated; write numbers" if after == "["
               else "parameters are not compensated; write numbers" if after == "#"
               else "a number must follow the letter")
        raise GcodeError(lineno, _shown(line, i), why)
    return Word(upper, float(m.group(1)), i, m.end(), upper + m.group(1))


def _shown(line: str, i: int) -> str:
    """The text at ``line[i]`` up to the next space, to name it in a message."""
    rest = line[i:].split(None, 1)
    return rest[0][:16] if rest else line[i:i + 1]
