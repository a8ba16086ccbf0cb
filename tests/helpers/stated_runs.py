"""What each shipped example's comment says it does: the command it names (``# Run:``)
and how that ends (``# Ends (exit N)…: FIRST LINE``, a trailing … for a line that goes
on), for the tests that run the examples (tests/station/commands/test_examples.py,
tests/station/report/test_first_screen.py)."""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
ENDS = re.compile(r"^# Ends \(exit (\d+)\)[^:]*: (.+)$")


@dataclass(frozen=True)
class Stated:
    """An example's stated run: the command's arguments after ``orthocal`` (example
    paths absolute), its exit status, and its first line (``prefix``: the line begins
    with ``first``)."""

    argv: tuple[str, ...]
    exit: int
    first: str
    prefix: bool

    def ends_so(self, code: int, stdout: str, stderr: str) -> str | None:
        """None where a run ended as stated; else what differs, in words."""
        shown = (stdout or stderr).splitlines()
        line = shown[0] if shown else ""
        same = line.startswith(self.first) if self.prefix else line == self.first
        if code == self.exit and same:
            return None
        return (f"exit {code}, first line {line!r}; the comment says exit {self.exit}, "
                f"{self.first!r}")


def stated(path: Path) -> Stated | None:
    """The run ``path``'s comment states, or None where it states none."""
    lines = path.read_text(encoding="utf-8").splitlines()
    run = next((i for i, ln in enumerate(lines) if ln.startswith("# Run:")), None)
    if run is None:
        return None
    words = shlex.split(lines[run].removeprefix("# Run:"))
    assert words[0] == "orthocal", lines[run]
    argv = tuple(str(ROOT / w) if w.startswith("examples/") else w for w in words[1:])
    ends = ENDS.match(lines[run + 1]) if run + 1 < len(lines) else None
    assert ends is not None, f"{path.name}: '# Run:' without '# Ends (exit N): …' below it"
    first = ends[2].strip()
    return Stated(argv, int(ends[1]), first.removesuffix("…"), first.endswith("…"))
