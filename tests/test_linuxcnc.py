"""orthocal's kinematics component (orthocal/orthoglidekins.comp) in a real LinuxCNC 2.9:
the example machine (examples/linuxcnc/orthoglide.ini) MDIs a grid over the workspace
and the joints LinuxCNC commands are orthocal.kinematics.inverse of each point, with
the nominal geometry and with a geometry set by ``setp`` lines in a HAL file listed
after the one that loads the kinematics, as ``orthocal export --kinematics`` writes it
(tests/linuxcnc_run.py starts and stops LinuxCNC; one start per test, ~5 s)."""

from __future__ import annotations

import shutil
from pathlib import Path

import linuxcnc_run as lcnc
import numpy as np
import pytest

from orthocal.geometry import Geometry
from orthocal.kinematics import inverse

#: LinuxCNC keeps positions as doubles from the G-code (17 decimals: the double
#: itself) to the joints (kinematicsInverse of the trajectory's end point, which is
#: the target to ~1e-13 mm): measured, the joints are orthocal's to ~1e-13 mm.
TOL = 1e-9  # mm
GRID = np.linspace(-100.0, 60.0, 3)
KINEMATICS_BOTH = 4  # LinuxCNC's KINEMATICS_TYPE: a forward and an inverse of its own
PINS = ("leg-length", "tilt", "gap", "drho")

pytestmark = pytest.mark.timeout(360)  # within: the lock (120 s), start, moves, stop


def grid() -> np.ndarray:
    """3 × 3 × 3 points over [−100, 60]³, each next to the one before (80 mm moves)."""
    points = []
    for i, x in enumerate(GRID):
        for j, y in enumerate(GRID if i % 2 == 0 else GRID[::-1]):
            row = GRID if (i * 3 + j) % 2 == 0 else GRID[::-1]
            points += [(x, y, z) for z in row]
    return np.array(points)


def check(run: lcnc.Run, targets: np.ndarray, joints: np.ndarray) -> None:
    assert run.kinematics_type == KINEMATICS_BOTH
    assert len(run.joints) == len(targets)
    np.testing.assert_allclose(run.position, targets, rtol=0, atol=TOL)
    # the feedback, LinuxCNC's call of the component's forward kinematics on the joints
    np.testing.assert_allclose(run.actual_position, targets, rtol=0, atol=TOL)
    np.testing.assert_allclose(run.joints, joints, rtol=0, atol=TOL)
    assert lcnc.leftovers() == []


def test_the_nominal_machine_commands_the_papers_joints() -> None:
    targets = grid()
    run = lcnc.mdi(lcnc.EXAMPLE, targets)
    check(run, targets, inverse(targets, Geometry()))
    print(f"LinuxCNC start, homing, {len(targets)} MDI moves and stop: {run.seconds:.1f} s")


def with_geometry(folder: Path, pins: dict[str, float]) -> Path:
    """The example machine with a geometry HAL file of ``setp`` lines, listed after the
    HAL file that loads the kinematics and motion (whose first call of kinematicsType()
    makes the pins)."""
    shutil.copytree(lcnc.EXAMPLE, folder)
    (folder / "orthoglide-geometry.hal").write_text(
        "# the machine's geometry (tests/test_linuxcnc.py)\n"
        + "".join(f"setp orthoglidekins.{pin} {value!r}\n" for pin, value in pins.items()),
        encoding="utf-8")
    ini = folder / "orthoglide.ini"
    text = ini.read_text(encoding="utf-8")
    assert text.count("HALFILE = orthoglide.hal\n") == 1
    ini.write_text(text.replace("HALFILE = orthoglide.hal\n", "HALFILE = orthoglide.hal\n"
                                "HALFILE = orthoglide-geometry.hal\n"), encoding="utf-8")
    return folder


def test_a_calibrated_machine_commands_orthocals_joints(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    dL, tilt = rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3)
    gap, drho = rng.uniform(-0.5, 0.5, 3), rng.uniform(-3, 3, 3)
    values = {"leg-length": Geometry().leg_length + dL, "tilt": tilt, "gap": gap,
              "drho": drho}
    names = {"leg-length": "xyz", "drho": "xyz", "tilt": ("yx", "zx", "zy"),
             "gap": ("xy", "xz", "yz")}
    pins = {f"{pin}-{name}": float(v) for pin in PINS
            for name, v in zip(names[pin], values[pin], strict=True)}
    targets = grid()
    run = lcnc.mdi(with_geometry(tmp_path / "machine", pins), targets)
    want = inverse(targets, Geometry(), drho=drho, dL=dL, tilt=tilt, gap=gap)
    assert np.abs(want - inverse(targets, Geometry())).max() > 1.0  # not the nominal's
    check(run, targets, want)
