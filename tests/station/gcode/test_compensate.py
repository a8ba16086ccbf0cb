"""``orthocal compensate``: a program rewritten for a controller with the nominal
kinematics keeps the identified machine's tool within the tolerance of the programmed
path, at the points written and between them, through the real command line.

The programmed paths are stated here on their own (lines, and arcs as rotations of
the start about the plane's normal, Rodrigues' formula), not by station.gcode; the
tool's path is orthocal's nominal_path of what a nominal controller interpolates
between the points the output file holds, read back by tests/helpers/gcode_paths.py."""

from __future__ import annotations

import json
import math
import re
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest
from compensate_runs import SQUARE, TILTED, write_run
from gcode_paths import INCH, X_AXIS, Y_AXIS, Z_AXIS, Arc, Line, distance_to, sent

from orthocal import Geometry
from orthocal.compensation import nominal_path
from station.commands.cli import main

G = Geometry(310.25, -100.0, 60.0)
TOL = 0.001
CHORD_FRACTIONS = np.linspace(0.0, 1.0, 21)


# --- the programs: (G-code, the path of its motion) per block, N numbered --------------

LINES = [
    ("G21 G90 G17 G94", None),
    ("G0 X-40 Y0 Z0", None),  # the first motion: from wherever the tool is
    ("G1 X60 Y0 Z0 F500", Line((-40, 0, 0), (60, 0, 0))),
    ("G1 X-40 Y-50 Z-60", Line((60, 0, 0), (-40, -50, -60))),
    ("X30 Y40 Z0", Line((-40, -50, -60), (30, 40, 0))),  # G1 carried
    ("G0 X0 Y0 Z-30", Line((30, 40, 0), (0, 0, -30))),
    ("G1 X0 Y0 Z-30", Line((0, 0, -30), (0, 0, -30))),
]
LINES_G91 = ["G21 G90 G17 G94", "G0 X-40 Y0 Z0", "G91 G1 X100 Y0 Z0 F500",
             "G1 X-100 Y-50 Z-60", "X70 Y90 Z60", "G0 X-30 Y-40 Z-30", "G1 X0 Y0 Z0"]

ARCS = [
    ("G21 G90 G17 G94", None),
    ("G0 X10 Y0 Z-10", None),
    ("G3 X0 Y10 I-10 J0 F400", Arc((0, 0, -10), Z_AXIS, (10, 0, -10), math.pi / 2)),
    ("G2 X10 Y0 R10", Arc((0, 0, -10), Z_AXIS, (0, 10, -10), -math.pi / 2)),
    ("G3 X10 Y0 I-10 J0", Arc((0, 0, -10), Z_AXIS, (10, 0, -10), 2 * math.pi)),
    ("G2 X10 Y0 Z-14 I-10 J0 P2", Arc((0, 0, -10), Z_AXIS, (10, 0, -10), -4 * math.pi, -4)),
    ("G18 G2 X0 Z-4 I-10 K0", Arc((0, 0, -14), Y_AXIS, (10, 0, -14), -math.pi / 2)),
    ("G19 G3 Y10 Z6 J0 K10", Arc((0, 0, 6), X_AXIS, (0, 0, -4), math.pi / 2)),
    ("G17 G2 X10 Y20 R-10", Arc((0, 20, 6), Z_AXIS, (0, 10, 6), -1.5 * math.pi)),
    ("G90.1 G3 X0 Y30 I0 J20", Arc((0, 20, 6), Z_AXIS, (10, 20, 6), math.pi / 2)),
    ("X-10 Y20 I0 J20", Arc((0, 20, 6), Z_AXIS, (0, 30, 6), math.pi / 2)),  # G3 carried
    ("G91.1 G1 X0 Y0 Z0", Line((-10, 20, 6), (0, 0, 0))),
]
ARCS_G91 = ["G21 G90 G17 G94", "G0 X10 Y0 Z-10", "G91 G3 X-10 Y10 I-10 J0 F400",
            "G2 X10 Y-10 R10", "G3 X0 Y0 I-10 J0", "G2 X0 Y0 Z-4 I-10 J0 P2",
            "G18 G2 X-10 Z10 I-10 K0", "G19 G3 Y10 Z10 J0 K10", "G17 G2 X10 Y10 R-10",
            "G90.1 G3 X-10 Y10 I0 J20", "X-10 Y-10 I0 J20", "G91.1 G1 X10 Y-20 Z-6"]

INCHES = [
    ("G20 G90 G17 G94", None),
    ("G0 X0.5 Y0 Z-0.25", None),
    ("G1 X2 Y0 Z-0.25 F20", Line((0.5 * INCH, 0, -0.25 * INCH), (2 * INCH, 0, -0.25 * INCH))),
    ("G3 X1.5 Y0.5 I-0.5 J0", Arc((1.5 * INCH, 0, -0.25 * INCH), Z_AXIS,
                                  (2 * INCH, 0, -0.25 * INCH), math.pi / 2)),
    ("G3 X1.5 Y0.5 I0 J-0.5", Arc((1.5 * INCH, 0, -0.25 * INCH), Z_AXIS,
                                  (1.5 * INCH, 0.5 * INCH, -0.25 * INCH), 2 * math.pi)),
    ("G1 X-1 Y-1.5 Z-1", Line((1.5 * INCH, 0.5 * INCH, -0.25 * INCH),
                              (-1 * INCH, -1.5 * INCH, -1 * INCH))),
]
MM_OF_INCHES = ["G21 G90 G17 G94", "G0 X12.7 Y0 Z-6.35", "G1 X50.8 Y0 Z-6.35 F508",
                "G3 X38.1 Y12.7 I-12.7 J0", "G3 X38.1 Y12.7 I0 J-12.7",
                "G1 X-25.4 Y-38.1 Z-25.4"]


def numbered(lines: list[str]) -> str:
    return "".join(f"N{10 * (k + 1)} {line}\n" for k, line in enumerate(lines))


def pieces(program: list[tuple[str, object]]) -> dict[int, object]:
    return {10 * (k + 1): p for k, (_, p) in enumerate(program) if p is not None}


# --- the command line, and its output read back ----------------------------------------

def compensate(tmp_path: Path, capsys, text: str, *args: str, run: Path | None = None,
               name: str = "part.ngc") -> tuple[int, Path, str]:
    """Exit status, the default output's path and stderr of ``orthocal compensate``."""
    if run is None:
        run = tmp_path / "run-tilted"
        if not run.exists():
            write_run(run)
    program = tmp_path / name
    program.write_text(text)
    capsys.readouterr()
    rc = main(["compensate", str(program), "--run", str(run), *args])
    return rc, program.with_name(program.stem + ".compensated" + program.suffix), \
        capsys.readouterr().err


def worst(text: str, paths: dict[int, object], theta: np.ndarray,
          offset=(0.0, 0.0, 0.0)) -> tuple[float, dict[int, int]]:
    """The largest distance of the tool from the programmed path, over every chord
    the controller interpolates (21 fractions each), and the segments per block."""
    points = sent(text, offset)
    worst_mm, count = 0.0, {}
    for _, (block, _) in pairwise(points):
        count[block] = count.get(block, 0) + 1
    for block, path in paths.items():
        chords = [(a, b) for (_, a), (n, b) in pairwise(points) if n == block]
        a = np.array([c[0] for c in chords])[:, None, :]
        b = np.array([c[1] for c in chords])[:, None, :]
        s = (a + CHORD_FRACTIONS[None, :, None] * (b - a)).reshape(-1, 3)
        tool = nominal_path(s, G, theta) - np.asarray(offset)
        worst_mm = max(worst_mm, float(distance_to(path.dense(), tool).max()))
    return worst_mm, count


# --- the tool on the programmed path ---------------------------------------------------

@pytest.mark.parametrize("program,args,offset", [
    (LINES, (), (0.0, 0.0, 0.0)),
    (ARCS, (), (0.0, 0.0, 0.0)),
    (INCHES, (), (0.0, 0.0, 0.0)),
    (ARCS, ("--tolerance", "0.005", "--work-offset", "10,-5,3"), (10.0, -5.0, 3.0)),
], ids=["lines", "arcs", "inches", "arcs-offset"])
def test_the_tool_stays_within_the_tolerance_between_the_points(
        tmp_path, capsys, program, args, offset) -> None:
    rc, out, err = compensate(tmp_path, capsys, numbered([g for g, _ in program]), *args)
    assert rc == 0, err
    tol = float(args[1]) if args else TOL
    text = out.read_text()
    deviation, count = worst(text, pieces(program), TILTED, offset)
    assert deviation <= tol
    assert set(count) >= set(pieces(program))  # every motion written
    assert f"work offset {', '.join(f'{v:.4f}' for v in offset)} mm" in text
    assert f"tolerance {tol:g} mm" in text


def test_uncompensated_the_program_would_miss_by_far_more(tmp_path) -> None:
    # the check above can fail: the program's own points, sent as they are, put the
    # identified machine's tool tens of µm off the path
    points = [(None, np.array(p.a, dtype=float)) for p in pieces(LINES).values()]
    text = "\n".join("N30 G1 X{:.4f} Y{:.4f} Z{:.4f}".format(*p) for _, p in points)
    text += "\nN30 G1 X-40 Y-50 Z-60"
    assert worst(text, {30: Line((-40, 0, 0), (60, 0, 0))}, TILTED)[0] > 20 * TOL


def test_a_100_mm_line_and_a_circle_take_few_segments(tmp_path, capsys) -> None:
    rc, out, err = compensate(tmp_path, capsys, numbered([
        "G21 G90", "G0 X-40 Y0 Z0", "G1 X60 Y0 Z0 F500", "G1 X2.265 Y-57.735 Z-57.735",
        "G0 X10 Y0 Z0", "G3 X10 Y0 I-10 J0"]))
    assert rc == 0, err
    _, count = worst(out.read_text(), {}, TILTED)
    # measured: 1 segment along x, 2 along the diagonal (100 mm each; 4 for the 141 mm
    # diagonal of the y-z plane): a chord strays only by how the compensation bends
    # over it, a few µm per 100 mm on this machine
    assert count[30] <= 8 and count[40] <= 8
    # the circle's own sagitta needs π / acos(1 − 0.9·tol/r) = 234 chords at least
    # (measured: 247)
    fewest = math.pi / math.acos(1 - 0.9 * TOL / 10)
    assert fewest <= count[60] <= 1.25 * fewest


def test_a_square_machine_with_nothing_left_gets_its_own_points(tmp_path, capsys) -> None:
    run = write_run(tmp_path / "run-square", "square")
    rc, out, err = compensate(tmp_path, capsys, numbered([g for g, _ in LINES]), run=run)
    assert rc == 0, err
    got = [p for _, p in sent(out.read_text())]
    want = [np.array(p, dtype=float) for p in ((-40, 0, 0), (60, 0, 0), (-40, -50, -60),
                                              (30, 40, 0), (0, 0, -30), (0, 0, -30))]
    assert len(got) == len(want)  # a line stays one line
    assert np.max(np.abs(np.array(got) - want)) <= 0.5e-4  # the format's resolution
    rc, out, err = compensate(tmp_path, capsys, numbered([g for g, _ in ARCS]), run=run,
                              name="arcs.ngc")
    assert rc == 0, err
    deviation, _ = worst(out.read_text(), pieces(ARCS), SQUARE)
    assert deviation <= TOL


# --- what is kept --------------------------------------------------------------------

KEPT = """%
(program header: fixture plate 3)
; a semicolon comment line

N5 G21 G90 G17 G94 (modes)
T1 M6 (tool one)
M3 S12000
G4 P0.5
G64 P0.01
(MSG, roughing)
N10 G0 X0 Y-50 Z-50
N20 G1 X0 Y50 Z50 F300 M8 D1 H1 Q2 $0 (cut) ; end note
N30 M9
N40 G1 X0 Y-50 Z-50 M0
M5
M30
%
"""


def test_everything_but_the_motions_is_kept_as_written(tmp_path, capsys) -> None:
    rc, out, err = compensate(tmp_path, capsys, KEPT)
    assert rc == 0, err
    lines = out.read_text().splitlines()
    assert lines[0] == "%" and lines[-1] == "%" and "written by orthocal compensate" in lines[1]
    kept = [k for k in KEPT.splitlines()[1:-1] if not re.match(r"N(10|20|40) ", k)]
    where = [lines.index(k) for k in kept]
    assert where == sorted(where)  # all of them, in their order
    n20 = next(i for i, line in enumerate(lines) if line.startswith("N20 "))
    assert re.fullmatch(r"N20 G1 X-?\d+\.\d{4} Y-?\d+\.\d{4} Z-?\d+\.\d{4} F300 M8 D1 H1 Q2 "
                        r"\$0 \(cut\) ; end note", lines[n20])
    n40 = next(i for i, line in enumerate(lines) if line.startswith("N40 "))
    block = lines[n40:lines.index("M5")]
    assert len(block) > 1  # the 141 mm diagonal is cut on this machine
    assert [line.endswith(" M0") for line in block] == [False] * (len(block) - 1) + [True]
    assert sum("M0" in line for line in lines) == 1
    assert all(line.startswith("G1 X") for line in lines[n20 + 1:lines.index("N30 M9")])


def test_modal_state_carries_and_g91_writes_increments(tmp_path, capsys) -> None:
    rc, out, err = compensate(tmp_path, capsys, numbered(LINES_G91))
    assert rc == 0, err
    text = out.read_text()
    assert "N30 G91 G1 X" in text  # the G91 word kept, the points as increments
    steps = [line for line in text.splitlines() if line.startswith(("G1 X", "N50 G1"))]
    assert steps and all(abs(float(re.search(r"X(\S+)", s).group(1))) < 100 for s in steps)


@pytest.mark.parametrize("absolute,relative", [
    ([g for g, _ in LINES], LINES_G91), ([g for g, _ in ARCS], ARCS_G91)],
    ids=["lines", "arcs"])
def test_relative_and_absolute_programs_get_the_same_points(
        tmp_path, capsys, absolute, relative) -> None:
    rc, out_a, err = compensate(tmp_path, capsys, numbered(absolute), name="abs.ngc")
    assert rc == 0, err
    rc, out_r, err = compensate(tmp_path, capsys, numbered(relative), name="rel.ngc")
    assert rc == 0, err
    a = np.array([p for _, p in sent(out_a.read_text())])
    r = np.array([p for _, p in sent(out_r.read_text())])
    assert a.shape == r.shape
    assert np.max(np.abs(a - r)) < 1e-9


def test_inch_and_mm_programs_get_the_same_path(tmp_path, capsys) -> None:
    rc, out_in, err = compensate(tmp_path, capsys, numbered([g for g, _ in INCHES]),
                                 name="inch.ngc")
    assert rc == 0, err
    rc, out_mm, err = compensate(tmp_path, capsys, numbered(MM_OF_INCHES), name="mm.ngc")
    assert rc == 0, err
    inch_text = out_in.read_text()
    # inches out, six decimals: 0.0254 µm, well below the tolerance
    assert re.search(r"^N30 G1 X\d+\.\d{6} Y-?\d+\.\d{6} Z-?\d+\.\d{6} F20$", inch_text, re.M)
    a = np.array([p for _, p in sent(inch_text)])
    b = np.array([p for _, p in sent(out_mm.read_text())])
    for p, q in ((a, b), (b, a)):  # each one's points on the other's polyline
        assert distance_to_polyline(p, q).max() <= TOL


def distance_to_polyline(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    a, b = poly[:-1][None], poly[1:][None]
    d = b - a
    p = points[:, None, :]
    t = np.clip(((p - a) * d).sum(2) / np.maximum((d * d).sum(2), 1e-300), 0, 1)
    return np.linalg.norm(p - (a + t[..., None] * d), axis=2).min(axis=1)


# --- what is refused -----------------------------------------------------------------

REFUSED = [
    ("G33 X1 K0.1", "G33"), ("G38.2 Z-5 F10", "G38.2"), ("G41 D1", "G41"),
    ("G42 D1", "G42"), ("G43 H1", "G43"), ("G52 X1", "G52"), ("G92 X0", "G92"),
    ("G92.1", "G92.1"), ("G73 X1 Y1 Z-1 R1 Q0.5", "G73"),
    ("G76 P0.05 Z-1 I-0.075 J0.008 K0.045", "G76"), ("G81 X1 Y1 Z-1 R1", "G81"),
    ("G83 X1 Y1 Z-1 R1 Q0.5", "G83"), ("G89 X1 Y1 Z-1 R1 P0.5", "G89"), ("G28", "G28"),
    ("G30", "G30"), ("G53 G0 X0", "G53"), ("G10 L2 P1 X0", "G10"), ("G93 G1 X1 F2", "G93"),
    ("G55", "G55"), ("G59.3", "G59.3"), ("G5 X1 Y1 I1 J1 P1 Q1", "G5"),
    ("G5.1 X1 Y1 I1 J1", "G5.1"), ("O100 sub", "O100"), ("#1 = 5", "#1"),
    ("G1 X[1+2]", "X[1+2]"), ("G1 X#1", "X#1"), ("G1 A10", "A10"), ("G1 B5", "B5"),
    ("G1 C1", "C1"), ("U1", "U1"), ("V1", "V1"), ("W1", "W1"), ("M98 P100", "M98"),
    ("G1 @5 ^30", "@5"),
]


@pytest.mark.parametrize("line,word", REFUSED, ids=[w for _, w in REFUSED])
def test_a_word_that_cannot_be_compensated_safely_is_refused(
        tmp_path, capsys, line, word) -> None:
    rc, out, err = compensate(tmp_path, capsys, f"G21 G90\nG0 X0 Y0 Z0\n{line}\nM2\n")
    assert rc == 2
    (message,) = err.strip().splitlines()
    assert f"part.ngc:3: {word}: " in message
    assert not out.exists() and list(tmp_path.glob("*.compensated*")) == []


MODAL = [
    ("G0 G1 X1 Y0 Z0", 3, "G1", "modal group 'motion'"),
    ("G90 G91 X1", 3, "G91", "modal group 'distance'"),
    ("G20 G21", 3, "G21", "modal group 'units'"),
    ("G17 G18", 3, "G18", "modal group 'plane'"),
    ("M3 M4 S100", 3, "M4", "modal group 'spindle'"),
    ("G1 X1 X2", 3, "X2", "twice"),
    ("G80 X5", 3, "X5", "no motion mode"),
    ("G2 X1 Y1", 3, "G2", "R or its centre"),
    ("G1 X1 I1", 3, "I1", "no G2/G3"),
    ("G2 X1 Y0 K1", 3, "K1", "not a centre word"),
    ("G2 X1 Y0 R1 I1", 3, "I1", "both R and"),
    ("G3 X0 Y0 I5 J0 P0.5", 3, "P0.5", "whole number"),
    ("G2 X20 Y0 R5", 3, "G2", "too small"),
    ("G3 X3 Y0 I5 J0", 3, "G3", "differs from the radius"),
    ("/G1 X5", 3, "G1", "block delete"),
]


@pytest.mark.parametrize("line,lineno,word,why", MODAL, ids=[m[0] for m in MODAL])
def test_a_block_rs274ngc_rejects_is_refused(tmp_path, capsys, line, lineno, word,
                                             why) -> None:
    rc, out, err = compensate(tmp_path, capsys, f"G21 G90\nG0 X0 Y0 Z0\n{line}\n")
    assert rc == 2
    (message,) = err.strip().splitlines()
    assert f"part.ngc:{lineno}: {word}: " in message and why in message
    assert not out.exists()


@pytest.mark.parametrize("first,word", [("X10 Y0 Z0", "X10"), ("G1 X0 Y0 Z0", "G1"),
                                        ("G0 Z5", "G0"), ("G91 G0 X1 Y1 Z1", "G0")])
def test_the_first_motion_must_say_where_the_tool_goes(tmp_path, capsys, first,
                                                       word) -> None:
    rc, out, err = compensate(tmp_path, capsys, f"(start)\n{first}\nG1 X1 Y1 Z1\n")
    assert rc == 2 and f"part.ngc:2: {word}: " in err and not out.exists()


@pytest.mark.parametrize("line,limits,why", [
    ("G1 X400 Y0 Z0", None, "beyond a leg's reach"),
    # the soft limits come before the workspace's edge along the same line
    ("G1 X400 Y0 Z0", "plan", "upper soft limit 380.250 mm (plan.json)"),
    ("G1 X75 Y0 Z0", "plan", "upper soft limit 380.250 mm (plan.json)"),
    # ends inside the limits (joint x 376.4 mm), the middle beyond them (382.25 mm)
    ("G1 X72 Y60 Z0", "config", "upper soft limit 380.250 mm (config.toml [controller])"),
])
def test_a_path_outside_the_workspace_or_the_soft_limits_is_refused(
        tmp_path, capsys, line, limits, why) -> None:
    run = write_run(tmp_path / "run", limits=limits)
    rc, out, err = compensate(tmp_path, capsys, f"G21 G90\nG0 X72 Y-60 Z0\n{line}\nM2\n",
                              run=run)
    assert rc == 2
    (message,) = err.strip().splitlines()
    assert "part.ngc:3: G1: " in message and why in message
    assert not out.exists()


def _named_point(message: str) -> np.ndarray:
    found = re.search(r"at machine point X(\S+) Y(\S+) Z(\S+) mm", message)
    assert found is not None, message
    return np.array([float(v) for v in found.groups()])


@pytest.mark.parametrize("limits", ["plan", None])
def test_the_first_point_out_of_reach_is_named_not_the_motions_start(
        tmp_path, capsys, limits) -> None:
    # G0 X500 from X0 Y0 Z10: the start is within reach; the line leaves the soft
    # limits of joint x (380.25 mm) near X70, and without them the workspace near X310
    from orthocal.compensation import controller_joints

    run = write_run(tmp_path / "run", limits=limits)
    rc, out, err = compensate(tmp_path, capsys, "G21 G90\nG0 X0 Y0 Z10\nG0 X500\n"
                              "G1 X0\n", run=run)
    assert rc == 2 and not out.exists()
    (message,) = err.strip().splitlines()
    assert "part.ngc:3: G0: " in message and "first point out of reach" in message
    point = _named_point(message)
    assert point[1] == 0.0 and point[2] == 10.0 and 1.0 < point[0] < 500.0
    # on either side of the named point, 0.005 mm along the line: within, and out of
    # reach, by the kinematics themselves (the message rounds to 0.001 mm)
    step = np.array([0.005, 0.0, 0.0])
    before, after = point - step, point + step
    if limits == "plan":
        assert "joint x beyond the controller's upper soft limit 380.250 mm" in message
        rho = controller_joints(np.array([before, after]), G, TILTED)
        assert rho[0, 0] < 380.25 < rho[1, 0]
    else:
        assert "leaves the workspace, beyond a leg's reach" in message
        controller_joints(before, G, TILTED)  # reached
        with pytest.raises(ValueError):
            controller_joints(after, G, TILTED)


def test_the_first_motion_out_of_reach_is_named_in_program_order(tmp_path, capsys) -> None:
    # line 3 leaves the soft limits only between its ends (each end within), line 4
    # ends beyond them: line 3 is the first, and its point is where joint x passes
    run = write_run(tmp_path / "run", limits="plan")
    rc, _, err = compensate(tmp_path, capsys, "G21 G90\nG0 X72 Y-60 Z0\n"
                            "G1 X72 Y60 Z0\nG1 X400 Y60 Z0\n", run=run)
    assert rc == 2
    (message,) = err.strip().splitlines()
    assert "part.ngc:3: G1: " in message and "upper soft limit 380.250 mm" in message
    point = _named_point(message)
    assert point[0] == 72.0 and -60.0 < point[1] < 0.0  # before the middle, where x peaks


def test_without_soft_limits_the_header_says_so(tmp_path, capsys) -> None:
    run = write_run(tmp_path / "run", limits=None)
    rc, out, err = compensate(tmp_path, capsys, "G0 X72 Y-60 Z0\nG1 X72 Y60 Z0\n", run=run)
    assert rc == 0, err
    assert "no soft limits known" in out.read_text()


# --- files and run directories ---------------------------------------------------------

def test_a_compensated_program_is_not_compensated_again(tmp_path, capsys) -> None:
    rc, out, err = compensate(tmp_path, capsys, "G0 X0 Y0 Z0\nG1 X10 Y0 Z0\n")
    assert rc == 0, err
    again = tmp_path / "again.ngc"
    again.write_text(out.read_text())
    rc = main(["compensate", str(again), "--run", str(tmp_path / "run-tilted")])
    (message,) = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and "written by orthocal compensate already" in message
    assert not (tmp_path / "again.compensated.ngc").exists()
    # its own earlier output is overwritten, anything else is not, nor the program
    rc, out, err = compensate(tmp_path, capsys, "G0 X0 Y0 Z0\nG1 X20 Y0 Z0\n")
    assert rc == 0 and "X20" not in out.read_text().splitlines()[-1][:3]
    other = tmp_path / "other.ngc"
    other.write_text("precious\n")
    rc, _, err = compensate(tmp_path, capsys, "G0 X0 Y0 Z0\n", "--out", str(other))
    assert rc == 2 and "not overwritten" in err and other.read_text() == "precious\n"
    rc, _, err = compensate(tmp_path, capsys, "G0 X0 Y0 Z0\n", "--out",
                            str(tmp_path / "part.ngc"))
    assert rc == 2 and "the program itself" in err


@pytest.mark.parametrize("status,model,why", [
    ("failed", True, "the run failed"), ("aborted", True, "the run aborted"),
    ("ok", False, "no model.json")])
def test_a_run_that_identified_no_machine_is_refused(tmp_path, capsys, status, model,
                                                     why) -> None:
    run = write_run(tmp_path / "run", status=status, model=model)
    rc, out, err = compensate(tmp_path, capsys, "G0 X0 Y0 Z0\n", run=run)
    (message,) = err.strip().splitlines()
    assert rc == 2 and why in message and not out.exists()


def test_a_tolerance_out_of_range_is_refused(tmp_path, capsys) -> None:
    rc, out, err = compensate(tmp_path, capsys, "G0 X0 Y0 Z0\n", "--tolerance", "0")
    assert rc == 2 and "--tolerance" in err and not out.exists()


def test_a_model_json_without_a_parameter_is_refused_in_one_line(tmp_path, capsys) -> None:
    run = write_run(tmp_path / "run")
    doc = json.loads((run / "model.json").read_text())
    del doc["drho_now"]["drho_y"]
    (run / "model.json").write_text(json.dumps(doc))
    rc, out, err = compensate(tmp_path, capsys, "G0 X0 Y0 Z0\n", run=run)
    (message,) = err.strip().splitlines()
    assert rc == 2 and "drho_now: no drho_y" in message and not out.exists()


def test_a_program_without_motion_is_kept_whole(tmp_path, capsys) -> None:
    rc, out, err = compensate(tmp_path, capsys, "(nothing moves)\nM3 S100\nM2\n")
    assert rc == 0, err
    assert out.read_text().splitlines()[-3:] == ["(nothing moves)", "M3 S100", "M2"]
