"""``orthocal compensate`` with each joint's table (docs/design.md, "Compensate",
directions): every joint's error taken for the direction the program moves it, the
point written twice where a joint turns back, and the tool kept on the programmed path.

The judge is stated here on its own: a nominal controller interpolates straight chords
between the points the output file holds (read back by tests/helpers/gcode_paths.py);
each joint's count follows the nominal inverse kinematics, and its carriage follows the
count as a screw with a dead band does, the play operator of the simulator (carriage =
clamp(carriage before, nut − B/2, nut + B/2), nut = count + the table's mean error),
stepped along the chords: no direction is told to it, it comes from the counts' own
motion. The identified machine (TILTED, tests/helpers/compensate_runs.py) puts the tool
at FK_c of the carriages."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from compensate_runs import TILTED, write_run
from gcode_paths import Z_AXIS, Arc, Line, distance_to, sent
from tabled_runs import L, table_record, with_tables

from orthocal import Geometry
from orthocal.compensation import landed
from orthocal.kinematics import inverse
from station.commands.cli import main

G = Geometry(310.25, -100.0, 60.0)
TOL = 0.001
FRACTIONS = np.linspace(0.0, 1.0, 21)
LEADS = {"x": 100.0, "y": -80.0}
BANDS_UM = {"x": 20.0, "y": 12.0}
#: The run's offsets (the golden run's, compensate_runs.write_run): o_final − o_before.
MOVED = np.array([-1.101, 0.698, -0.401])

# Joint x turns back at the end of the first line (X60), y and z within each line (at
# X0, where the leg along y stands straightest) and at its end; a circle in XY turns
# every joint twice.
BACK_AND_FORTH = [("G21 G90 G17 G94", None), ("G0 X-40 Y0 Z0", None),
                  ("G1 X60 Y0 Z0 F500", Line((-40, 0, 0), (60, 0, 0))),
                  ("G1 X-40 Y0 Z0", Line((60, 0, 0), (-40, 0, 0)))]
CIRCLE = [("G21 G90 G17 G94", None), ("G0 X30 Y0 Z-20", None),
          ("G3 X30 Y0 I-30 J0 F400", Arc((0, 0, -20), Z_AXIS, (30, 0, -20), 2 * math.pi))]


def numbered(program: list[tuple[str, object]]) -> str:
    return "".join(f"N{10 * (k + 1)} {g}\n" for k, (g, _) in enumerate(program))


def paths(program: list[tuple[str, object]]) -> dict[int, object]:
    return {10 * (k + 1): p for k, (_, p) in enumerate(program) if p is not None}


def run_with_tables(folder: Path, bands: dict[str, float] = BANDS_UM,
                    targets=None) -> Path:
    run = write_run(folder)
    doc = json.loads((run / "result.json").read_text())
    kw = {} if targets is None else {"targets": targets}
    doc = with_tables(doc, {a: table_record(LEADS[a], bands.get(a, 0.0), **kw)
                            for a in LEADS})
    (run / "result.json").write_text(json.dumps(doc))
    return run


def compensate(tmp_path: Path, capsys, run: Path, program) -> tuple[int, str, str]:
    source = tmp_path / "part.ngc"
    source.write_text(numbered(program))
    out = tmp_path / "part.compensated.ngc"
    out.unlink(missing_ok=True)
    capsys.readouterr()
    rc = main(["compensate", str(source), "--run", str(run)])
    return rc, out.read_text() if out.exists() else "", capsys.readouterr().err


def nut_um(axis: str, count: np.ndarray) -> np.ndarray:
    """The table's mean error at a count (the controller's joints), µm: the screw the
    test found, at the spot the test's target count + (o_final − o_before) stood."""
    return LEADS[axis] * 1e-3 * (count + MOVED["xyz".index(axis)] - L)


def tool_path(text: str) -> tuple[dict[int, np.ndarray], np.ndarray]:
    """Per block, the identified machine's tool along the chords a nominal controller
    interpolates (the play operator on each joint), and every sent point's counts."""
    points = sent(text)
    counts = inverse(np.array([p for _, p in points]), G)
    carriage, tool = None, {}
    for k in range(1, len(points)):
        rho = inverse(points[k - 1][1] + FRACTIONS[:, None] * (points[k][1] - points[k - 1][1]),
                      G)
        nut = rho.copy()
        half = np.zeros(3)
        for i, axis in enumerate("xyz"):
            if axis in LEADS:
                nut[:, i] += 1e-3 * nut_um(axis, rho[:, i])
                half[i] = 0.5e-3 * BANDS_UM[axis]
        if carriage is None:  # the first point: reached moving as the program then moves
            first = np.sign(counts[1] - counts[0])
            carriage = nut[0] - first * half
        stood = np.empty_like(nut)
        for f in range(len(FRACTIONS)):
            carriage = np.clip(carriage, nut[f] - half, nut[f] + half)
            stood[f] = carriage
        tool.setdefault(points[k][0], []).append(landed(stood, G, TILTED))
    return {b: np.concatenate(v) for b, v in tool.items()}, counts


def off_path(tool: dict[int, np.ndarray], program) -> float:
    return max(1e3 * float(distance_to(p.dense(), tool[b]).max())
               for b, p in paths(program).items())


@pytest.mark.parametrize("program", [BACK_AND_FORTH, CIRCLE], ids=["back-and-forth", "circle"])
def test_the_tool_follows_the_path_through_every_turn(tmp_path, capsys, program) -> None:
    run = run_with_tables(tmp_path / "run")
    rc, text, err = compensate(tmp_path, capsys, run, program)
    assert rc == 0, err
    tool, _ = tool_path(text)
    # within the tolerance (1 µm) and the format's rounding (0.05 µm per coordinate)
    assert off_path(tool, program) <= 1e3 * TOL + 0.1
    assert "takes into account: a compensated program: the identified geometry and each " \
           "joint's positioning error" in text
    assert "joint tables: x [test: /shop/x.csv]; y [test: /shop/y.csv]" in text
    assert "no table, not compensated: z [assumed" in text


@pytest.mark.parametrize("program", [BACK_AND_FORTH, CIRCLE], ids=["back-and-forth", "circle"])
def test_without_the_directions_the_bands_put_the_tool_off(tmp_path, capsys,
                                                           program) -> None:
    # the check above can fail: the same tables without their reversal (the middle of
    # each band) leave the tool B/2 off after every turn (10 µm for x, 6 µm for y)
    run = run_with_tables(tmp_path / "run", bands={})
    rc, text, err = compensate(tmp_path, capsys, run, program)
    assert rc == 0, err
    tool, _ = tool_path(text)
    assert off_path(tool, program) > 5.0


def test_where_a_joint_turns_back_its_point_is_written_twice(tmp_path, capsys) -> None:
    run = run_with_tables(tmp_path / "run")
    rc, text, err = compensate(tmp_path, capsys, run, BACK_AND_FORTH)
    assert rc == 0, err
    points = sent(text)
    _, counts = tool_path(text)
    jumps = np.diff(counts, axis=0)
    steps = np.linalg.norm(np.diff([p for _, p in points], axis=0), axis=1)
    at = np.flatnonzero(steps < 0.05)  # a point written again: the tool stays
    # at X60 (the end of the first line) every joint turns; near X0 on each line y and z
    # (z has no table: its turn changes nothing written)
    assert len(at) == 3
    end = [k for k in at if abs(points[k][1][0] - 60.0) < 0.05]
    assert len(end) == 1 and points[end[0] + 1][0] == 40  # the second line starts with it
    # there x's count drops by its band (it now moves down: the play taken up), y's rises
    # by its own, z (no table) stays: to the format's rounding
    assert jumps[end[0]] == pytest.approx([-0.020, 0.012, 0.0], abs=2e-4)
    middle = [k for k in at if k not in end]
    for k in middle:  # near X0 only y turns (with a table): x keeps its way (the tilted
        assert abs(points[k][1][0]) < 0.5  # machine's y turns 0.1 mm off X0)
        assert abs(jumps[k][1]) == pytest.approx(0.012, abs=2e-4)
        assert abs(jumps[k][0]) < 2e-4 and abs(jumps[k][2]) < 2e-4


def test_a_point_beyond_a_joints_table_is_refused_naming_its_line(tmp_path, capsys) -> None:
    run = run_with_tables(tmp_path / "run", targets=np.arange(250.0, 381.0, 10.0))
    program = [("G21 G90 G17 G94", None), ("G0 X-40 Y0 Z0", None),
               ("G1 X-70 Y0 Z0 F500", None)]
    rc, text, err = compensate(tmp_path, capsys, run, program)
    assert rc == 2 and text == ""
    (line,) = err.strip().splitlines()
    # (240.248 mm: the tilted machine's joint for X-70; the test's 250–380 mm in the joints
    # commanded, 251.101–381.101, held at its ends for the 1.101 mm the offsets moved)
    assert "part.ngc:3: G1: joint x would stand at 240.248 mm, outside its table " \
           "(250.000 to 382.202 mm, the run's joint test)" in line
