"""orthocal's kinematics component (orthocal/orthoglidekins.comp) in a real LinuxCNC 2.9:
the example machine (examples/linuxcnc/orthoglide.ini) MDIs a grid over the workspace
and the joints LinuxCNC commands are orthocal.kinematics.inverse of each point, with
the nominal geometry and with a geometry set by ``setp`` lines in a HAL file listed
after the one that loads the kinematics, as ``orthocal export --kinematics`` writes it;
and end to end, the held-out machine's run exported and its true tool where LinuxCNC
sends it (tests/helpers/linuxcnc_run.py starts and stops LinuxCNC; ~5-15 s a start)."""

from __future__ import annotations

import shutil
from pathlib import Path

import heldout
import linuxcnc_run as lcnc
import numpy as np
import pytest
from heldout import truth_now

from orthocal.compensation import controller_joints, landed
from orthocal.geometry import Geometry
from orthocal.kinematics import inverse
from station.commands.cli import main
from station.history.linuxcnc_kins import GEOMETRY_HAL
from station.record.identified import COMPONENT, IdentifiedMachine, identified_machine

#: LinuxCNC keeps positions as doubles from the G-code (17 decimals: the double
#: itself) to the joints (kinematicsInverse of the trajectory's end point, which is
#: the target to ~1e-13 mm): measured, the joints are orthocal's to ~1e-13 mm.
TOL = 1e-9  # mm
GRID = np.linspace(-100.0, 60.0, 3)
KINEMATICS_BOTH = 4  # LinuxCNC's KINEMATICS_TYPE: a forward and an inverse of its own
PINS = ("leg-length", "tilt", "gap", "drho")

#: LinuxCNC's joints against (K1) with the exported values: the HAL file's 9 decimals.
HAL_TOL = 1e-6  # mm
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
        "# the machine's geometry (tests/station/history/test_linuxcnc.py)\n"
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


def exported(tmp_path: Path, run_dir: Path) -> Path:
    """The example machine with ``orthocal export --kinematics`` of the run installed as a
    user installs it: the INI and the geometry's HAL file written over the machine's own
    (the INI's HALFILEs are read from its folder, which holds orthoglide.hal)."""
    config, out = tmp_path / "machine", tmp_path / "export"
    shutil.copytree(lcnc.EXAMPLE, config)
    assert main(["export", str(run_dir), "--to", "linuxcnc", "--ini",
                 str(config / "orthoglide.ini"), "--kinematics", "--out", str(out)]) == 0
    for name in ("orthoglide.ini", GEOMETRY_HAL):
        shutil.copy(out / name, config / name)
    return config


def nominal_hal(found: IdentifiedMachine) -> str:
    """The geometry's HAL file with every pin nominal: the offsets alone."""
    return "# offsets only\n" + "".join(f"setp {COMPONENT}.{v.pin} {v.nominal!r}\n"
                                         for v in found.values)


def true_tool_error(run: lcnc.Run, truth: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """|true tool − target| per point, µm: the hidden machine's forward kinematics on
    the joints LinuxCNC commanded."""
    return 1000 * np.linalg.norm(landed(run.joints, Geometry(), truth) - targets, axis=1)


def test_the_exported_geometry_takes_the_true_tool_to_the_targets(tmp_path: Path) -> None:
    """The held-out machine's run (tests/helpers/heldout.py) exported with --kinematics, MDI'd
    over the grid in LinuxCNC, and the true tool where the commanded joints put it.

    Which ρ the joints are. The example INI's joint n is ρ_n as the station commands
    it over Modbus: HOME_OFFSET = L makes the joint count L at the mechanical zero Π0,
    so before the run LinuxCNC's joint ρ and the station's commanded ρ put a carriage
    at the same place (with the offsets before the run, o_before). The fakes' drive
    holds the offsets (offsets_held_by = controller): it adds the offsets the run
    wrote, o_final, to whatever ρ it is sent, LinuxCNC's as the station's, and the
    export leaves HOME_OFFSET as it was. So LinuxCNC's joint ρ is the station's ρ in
    the frame of the offsets the run left, where the hidden machine is truth_now:
    Δρ_true + (o_final − o_before), and the true tool is FK of it on LinuxCNC's
    joints. (Where the station holds the offsets, the exported HOME_OFFSET moves by
    −(o_final − o_before) and LinuxCNC's joints land in that same frame:
    tests/station/history/test_export.py.)

    The control: the same INI with every geometry pin nominal (the offsets alone)
    leaves the gaps' and tilts' tens of µm, so the check can fail."""
    lcnc.require_linuxcnc()  # before the run: without LinuxCNC it is time lost
    result = heldout.held_out(tmp_path / "runs")
    assert result["offsets_held_by"] == "controller"
    run_dir = Path(result["run_dir"])
    found, truth, targets = identified_machine(run_dir), truth_now(result), grid()
    config = exported(tmp_path, run_dir)
    told = lcnc.mdi(config, targets)
    assert told.kinematics_type == KINEMATICS_BOTH
    np.testing.assert_allclose(told.joints, controller_joints(targets, found.geometry,
                                                              found.theta_c()),
                               rtol=0, atol=HAL_TOL)
    (config / GEOMETRY_HAL).write_text(nominal_hal(found), encoding="utf-8")
    only = lcnc.mdi(config, targets)
    np.testing.assert_allclose(only.joints, inverse(targets, Geometry()), rtol=0, atol=TOL)
    with_geometry, offsets_only = (true_tool_error(r, truth, targets) for r in (told, only))
    rms = {k: float(np.sqrt(np.mean(e ** 2))) for k, e in
           (("told", with_geometry), ("only", offsets_only))}
    print(f"true tool over {len(targets)} MDI targets: the geometry in LinuxCNC "
          f"{rms['told']:.2f} µm RMS, {with_geometry.max():.2f} µm max; offsets only "
          f"{rms['only']:.2f} µm RMS, {offsets_only.max():.2f} µm max")
    assert rms["told"] <= 3.0 and with_geometry.max() <= 8.0
    assert rms["only"] >= 25.0
