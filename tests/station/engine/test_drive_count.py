"""The drive's count (docs/model.md, "The drive's count", (J15)): a drive that takes its
targets in 0.01 mm (IAI) puts every test posture's joints up to 5 µm off, the same at
every cycle. The identification takes that out; left in, it reads as tilts of about
0.1 mrad on a square machine, and as advice to shim rails that are straight."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from fakes import FakeRig, fake_config, run_on

from station import report

#: off the 0.01 mm grid, so that no offset the drive can hold zeroes a joint
TRUE = (0.6034, -0.4071, 0.9088)
IAI_MM = 0.01


def _run(tmp_path: Path, counted_by_station: bool) -> tuple[int, dict[str, Any], FakeRig]:
    rig = FakeRig(true_drho=TRUE, noise_mm=0.0005, seed=4)
    rig.axes.count_mm = IAI_MM
    if not counted_by_station:  # the control: the station told the targets are exact
        rig.axes.target_resolution_mm = lambda: np.zeros(3)  # type: ignore[method-assign]
    code, result = run_on(rig, tmp_path / "runs", fake_config())
    return code, result, rig


def _stated(result: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {q["name"]: q for q in result["statement"]}


def test_a_coarse_count_is_taken_out_and_a_square_machine_stays_square(tmp_path: Path) -> None:
    code, result, rig = _run(tmp_path, counted_by_station=True)
    assert code == 0 and result["loop"]["stopped"] == "converged", result["loop"]
    stated = _stated(result)
    for name in ("tilt_yx", "tilt_zx", "tilt_zy"):  # square: 0 inside every interval
        assert abs(stated[name]["value"]) <= stated[name]["expanded"], stated[name]
    assert [a["id"] for a in result["advice"]] == ["nothing"]
    # each joint left at the count nearest its zero, within the fit's error
    left_um = 1e3 * (rig.machine.offsets + np.array(TRUE))
    assert np.all(np.abs(left_um) <= 1e3 * IAI_MM / 2 + 1.5), left_um
    # the record says what the count made of the deviations (J15), a few µm here
    words = result["joints"]["in_identification"]
    assert "the drive's count (x 0.01, y 0.01, z 0.01 mm" in words
    up_to = float(words.split("up to ")[-1].split(" µm")[0])
    assert 0.5 < up_to < 5.0, words


def test_what_the_count_does_at_the_tool_is_stated_once_and_shown(tmp_path: Path) -> None:
    _, result, _ = _run(tmp_path, counted_by_station=True)
    count = result["accuracy"]["drive_count"]
    assert count["target_mm"] == {"x": IAI_MM, "y": IAI_MM, "z": IAI_MM}
    # (J17) over the paper's workspace: at least the centre's c/2 and c·√3/2, and
    # within a few per cent of them (the legs tilt at most 19°)
    assert 0.005 <= count["rms_mm"] < 0.0055 and 0.00866 <= count["max_mm"] < 0.016
    said = (f"{1000 * count['rms_mm']:.1f} µm RMS and up to "
            f"{1000 * count['max_mm']:.1f} µm at the tool")
    assert sum(said in w for w in result["accuracy"]["assumes"]) == 1
    joints = [ln for ln in report.summary_text(result).splitlines()
              if ln.strip().startswith("joints")]
    assert len(joints) == 1 and (f"the drive's 0.01 mm count adds up to "
                                 f"{1000 * count['max_mm']:.1f} µm") in joints[0], joints


def test_left_in_the_count_reads_as_tilts_and_shims(tmp_path: Path) -> None:
    # the control: the same machine, the station blind to the count
    _, result, _ = _run(tmp_path, counted_by_station=False)
    stated = _stated(result)
    out = [n for n in ("tilt_yx", "tilt_zx", "tilt_zy")
           if abs(stated[n]["value"]) > stated[n]["expanded"]]
    assert out, {n: stated[n] for n in stated if n.startswith("tilt")}
    assert any(a["id"].startswith("shim.") for a in result["advice"])
