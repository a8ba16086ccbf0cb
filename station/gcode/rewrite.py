"""A program rewritten for a controller that runs the machine's nominal kinematics:
every motion replaced by the points that make the identified machine's tool follow
the programmed path (station.gcode.subdivide), everything else kept as written.

What is kept: comments, F, S, M, T and every other word the controller reads that
moves nothing, line numbers (N stays on the first line of its block), blank lines
and the ``%`` delimiters. A motion's first line is its block with the motion, axis
and arc words (G0..G3, X Y Z, I J K R, an arc's P) replaced by ``G0``/``G1`` and the
first point; the further points follow on lines of their own, and a stopping M code
(M0, M1, M2, M30, M60), which acts after the motion, moves to the last of them.
Points are written in the block's units (G20: inches) and distance mode, in a fixed
format whose rounding stays within a tenth of the tolerance; in G91 each increment is
taken between points as rounded, so rounding never accumulates.

What the tolerance assumes of the controller: that it moves in straight lines between
the points it is sent. Its path blending (G64, G64 P) may round the corners between
segments by up to what it allows, and a rapid (G0) is a straight line only on a
controller that interpolates rapids (LinuxCNC does; a Sinumerik with RTLIOF does
not): both add to the tolerance, and the header does not hide them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from station.gcode.codes import STOPS
from station.gcode.modal import MM_PER_INCH, RAPID, Modal, ProgramMove, interpret
from station.gcode.paths import curves_of
from station.gcode.subdivide import CompensatedMachine, JointLimits, WriteGrid, subdivide
from station.gcode.words import Block, Word, tokenize

#: The header's first words: a program that holds them was written by compensate.
MARK = "written by orthocal compensate"


@dataclass(frozen=True)
class Job:
    """What a program is compensated for and how."""

    machine: CompensatedMachine
    limits: JointLimits
    tolerance: float  # mm
    work_offset: np.ndarray  # mm, the program's origin in machine coordinates
    describe: str  # the run, the machine and the model, for the header
    notes: tuple[str, ...] = ()  # further header lines (e.g. where the offsets live)


@dataclass(frozen=True)
class CompensatedProgram:
    text: str
    motions: int
    segments: int


def decimals(tolerance: float, inches: bool) -> int:
    """Decimals that keep a coordinate's rounding within a tenth of the tolerance."""
    step = tolerance / 10.0 / (MM_PER_INCH if inches else 1.0)
    return max(4 if inches else 3, math.ceil(-math.log10(step) - 1e-9))


def compensate(text: str, name: str, job: Job) -> CompensatedProgram:
    """``text`` (the program ``name``) rewritten for ``job``; GcodeError (one line:
    line, word, why) for what cannot be compensated safely."""
    lines = text.splitlines()
    state = Modal()
    blocks: list[Block] = []
    moves: list[ProgramMove] = []
    for lineno, line in enumerate(lines, start=1):
        block = tokenize(line, lineno)
        blocks.append(block)
        move = interpret(block, state)
        if move is not None:
            moves.append(move)
    points = _points(moves, job)
    body = _emit(blocks, moves, points, job.tolerance)
    newline = "\r\n" if "\r\n" in text else "\n"
    out = _with_header(body, _header(name, job, _style(blocks)))
    segments = sum(len(p) for p in points)
    return CompensatedProgram(newline.join(out) + newline, len(moves), segments)


def _points(moves: list[ProgramMove], job: Job) -> list[np.ndarray]:
    """Per motion the points to send, in its units, rounded as written."""
    scale = np.array([MM_PER_INCH if m.inches else 1.0 for m in moves])
    factor = np.array([10.0 ** decimals(job.tolerance, m.inches) for m in moves])
    grid = WriteGrid(np.asarray(job.work_offset, dtype=float), scale, factor)
    labels = [(m.lineno, m.label) for m in moves]
    return subdivide(curves_of(moves), grid, job.machine, job.limits, job.tolerance, labels)


def _emit(blocks: list[Block], moves: list[ProgramMove], points: list[np.ndarray],
          tolerance: float) -> list[str]:
    """The program's lines, each motion's block replaced by its points."""
    by_line = {m.lineno: (m, p) for m, p in zip(moves, points, strict=True)}
    position: np.ndarray | None = None  # where the controller is, mm (work coordinates)
    out: list[str] = []
    for block in blocks:
        found = by_line.get(block.lineno)
        if found is None:
            out.append(block.text)
            continue
        move, pts = found
        d = decimals(tolerance, move.inches)
        coords, position = _coordinates(move, pts, position, d)
        out.extend(_motion_lines(block, move, coords, d))
    return out


def _coordinates(move: ProgramMove, pts: np.ndarray, position: np.ndarray | None,
                 d: int) -> tuple[np.ndarray, np.ndarray]:
    """The numbers to write (absolute, or G91 increments between the rounded points)
    and where the controller then is (mm)."""
    unit = MM_PER_INCH if move.inches else 1.0
    if move.absolute:
        return pts, pts[-1] * unit
    assert position is not None  # the first motion is absolute (station.gcode.modal)
    before = np.vstack([position / unit, pts[:-1]])
    steps = np.round(pts - before, d)
    return steps, (position / unit + steps.sum(axis=0)) * unit


def _motion_lines(block: Block, move: ProgramMove, coords: np.ndarray, d: int) -> list[str]:
    """The block's first line (its other words kept as written) and one line per
    further point; stopping M codes on the last."""
    word = "G0" if move.code == RAPID else "G1"
    fmt = f"{word} X{{:.{d}f}} Y{{:.{d}f}} Z{{:.{d}f}}"
    rows = [fmt.format(*row) for row in (coords + 0.0).tolist()]  # + 0.0: no "-0.000"
    stops = [w for w in block.of("M") if w.code in STOPS] if len(rows) > 1 else []
    first = _replace(block.text, move.removed, stops, rows[0])
    if stops:
        rows[-1] += " " + " ".join(w.text for w in stops)
    return [first, *rows[1:]]


def _replace(text: str, removed: tuple[Word, ...], dropped: list[Word], new: str) -> str:
    """``text`` without the words ``removed`` and ``dropped``, ``new`` where the first
    removed word stood; the rest of the line as it was."""
    cut = sorted((*removed, *dropped), key=lambda w: w.start)
    at = min(w.start for w in removed)
    pieces, cursor = [], 0
    for w in cut:
        start = w.start
        while start > cursor and text[start - 1] in " \t":
            start -= 1  # the word's own leading blanks go with it
        pieces.append(text[cursor:start])
        if w.start == at:
            pieces.append((" " if start > 0 else "") + new)
        cursor = w.end
    rest = text[cursor:]
    if rest and not rest[0].isspace() and not pieces[-1].endswith(" "):
        rest = " " + rest
    pieces.append(rest)
    return "".join(pieces)


def _style(blocks: list[Block]) -> str:
    """The program's own comment style for the header: ``;`` where it writes only
    those, else parentheses."""
    texts = [b.text for b in blocks]
    semicolon = any(";" in t for t in texts)
    parens = any("(" in t for t in texts)
    return ";" if semicolon and not parens else "("


def _header(name: str, job: Job, style: str) -> list[str]:
    off = ", ".join(f"{v:.4f}" for v in job.work_offset)
    lim = job.limits
    if np.isfinite(lim.lower).any() or np.isfinite(lim.upper).any():
        limits = (f"soft limits of the joints checked along the whole path: lower "
                  f"{_triple(lim.lower)}, upper {_triple(lim.upper)} mm ({lim.source})")
    else:
        limits = f"no soft limits known ({lim.source}): only the workspace is checked"
    lines = [
        f"{MARK}: do not compensate it again",
        f"from {name}, for a controller with the machine's nominal kinematics and the "
        "run's offsets in its joints",
        job.describe,
        f"tolerance {job.tolerance:g} mm: the identified machine's tool within it of the "
        "programmed path, between the points as well as at them",
        f"work offset {off} mm assumed: the program's work origin in machine "
        "coordinates, P = 0 at the mechanical zero",
        limits,
        "modes assumed until the program sets them: G21 G90 G91.1 G17 G94",
        *job.notes,
    ]
    clean = [line.replace("(", "[").replace(")", "]") for line in lines]
    return [f"; {c}" if style == ";" else f"({c})" for c in clean]


def _triple(v: np.ndarray) -> str:
    return " ".join("—" if not np.isfinite(x) else f"{x:.3f}" for x in v)


def _with_header(body: list[str], header: list[str]) -> list[str]:
    """The header after a leading ``%`` line (the program starts after it), else first."""
    first = next((i for i, line in enumerate(body) if line.strip()), None)
    if first is not None and body[first].strip() == "%":
        return [*body[:first + 1], *header, *body[first + 1:]]
    return [*header, *body]
