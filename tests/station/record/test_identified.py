"""The machine a run identified, as a controller is told it (station/record/identified.py):
what the kept model holds, with its 95 % interval; what it does not, nominal and said;
runs that identified nothing refused in one line naming the file."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builders import cli
from result_builders import golden_result

from orthocal import PARAM_NAMES, coverage_factor
from station.record import exportable
from station.record.identified import NotACalibration, identified_machine
from station.record.io import read_result
from station.record.model import MachineModel

LAYOUT = {"tilt_yx": 0.2, "tilt_zx": 0.1, "tilt_zy": -0.15, "gap_xy": 0.15,
          "gap_xz": -0.1, "gap_yz": 0.12}
NOW = {"drho_x": 0.002, "drho_y": -0.001, "drho_z": 0.0005}


def model_json(model: str) -> dict[str, Any]:
    estimated = ["drho_x", "drho_y", "drho_z", *LAYOUT]
    se = {n: 0.004 if n.startswith("drho") else 0.01 if n.startswith("tilt") else 0.002
          for n in estimated}
    doc = {
        "format": "orthocal machine model 1",
        "geometry": {"leg_length_mm": 310.25, "rho_min_mm": -100.0, "rho_max_mm": 60.0},
        "conventions": {k: "docs/model.md" for k in ("model", "axes", "gaps", "drho",
                                                     "parameters")},
        "units": {"drho": "mm", "dL": "mm", "tilt": "mrad", "gap": "mm"},
        "model": model,
        "parameters": {n: LAYOUT.get(n, 0.6 if n == "drho_x" else 0.0) for n in PARAM_NAMES},
        "estimated": estimated,
        "not_estimated": {f"dL_{a}": "taken as 0: not identifiable beside the tilts and gaps "
                                     "from two postures per leg" for a in "xyz"},
        "std_errors": se,
        "covariance": {"names": estimated,
                       "matrix": np.diag([se[n] ** 2 for n in estimated]).tolist()},
        "std_errors_dof": 40.0,
        "drho_now": NOW,
        "offsets_before": {"x": 0.0, "y": 0.0, "z": 0.0},
        "offsets_written": {"x": -0.6, "y": 0.4, "z": -0.9},
    }
    return MachineModel.model_validate(doc).model_dump(mode="json")


#: The 95 % expanded uncertainty this test's runs state: Δρ as left, the tilts, the gaps.
U_NOW, U_TILT, U_GAP = 0.0016, 0.021, 0.0043


def _statement(quantities: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The golden run's statement with this test's machine in it: Δρ as left NOW, the
    layout LAYOUT, each with its expanded uncertainty (its other quantities kept)."""
    said = {**{f"{n}.as_left": (v, U_NOW) for n, v in NOW.items()},
            **{n: (v, U_TILT if n.startswith("tilt") else U_GAP) for n, v in LAYOUT.items()}}
    out = []
    for q in quantities:
        if q["name"] in said:
            v, u = said[q["name"]]
            q = {**q, "value": v, "expanded": u, "interval_95": [v - u, v + u]}
        out.append(q)
    return out


def run_dir(tmp_path: Path, model: str = "rho+tilt+gap", status: str = "ok",
            with_model: bool = True, ambiguous: bool = False) -> Path:
    d = tmp_path / f"run-{model}-{status}"
    d.mkdir()
    # a whole record (the golden run's), with what this test's run says
    result = golden_result()
    result.update(run_dir=str(d), status=status, message=None, offsets_held_by="controller")
    result["machine"]["id"] = "OG-7"
    assert result["remaining"] is not None
    result["remaining"].update(std_errors={n: 0.0008 for n in NOW}, std_errors_dof=60.0)
    result["statement"] = _statement(result["statement"])
    if ambiguous:  # the legs' bows explained its last round as well as the tilts
        result["iterations"][-1]["model"] = model
        result["iterations"][-1]["ambiguity"] = {
            "explained_by": "rho+gap+form", "apart_mm": {"drho_x": 0.015}}
    (d / "result.json").write_text(json.dumps(result))
    if with_model:
        (d / "model.json").write_text(json.dumps(model_json(model)))
    return d


def test_the_kept_model_is_told_with_its_intervals(tmp_path: Path) -> None:
    m = identified_machine(run_dir(tmp_path))
    told = {v.name: v for v in m.values if v.identified}
    assert sorted(told) == sorted([*NOW, *LAYOUT])
    # each value's 95 % interval is the statement's, not model.json's σ times a k
    lo, hi = told["tilt_yx"].interval_95
    assert lo == pytest.approx(0.2 - U_TILT) and hi == pytest.approx(0.2 + U_TILT)
    assert "+0.200 ± 0.021 mrad (95 %)" in told["tilt_yx"].note
    assert told["drho_x"].value == pytest.approx(0.002)  # what the offsets did not correct
    lo, hi = told["drho_x"].interval_95
    assert (lo, hi) == pytest.approx((0.002 - U_NOW, 0.002 + U_NOW))
    assert "+2.0 ± 1.6 µm (95 %)" in told["drho_x"].note
    assert [v.pin for v in m.values] == [
        "drho-x", "drho-y", "drho-z", "leg-length-x", "leg-length-y", "leg-length-z",
        "tilt-yx", "tilt-zx", "tilt-zy", "gap-xy", "gap-xz", "gap-yz"]
    legs = [v for v in m.values if v.pin.startswith("leg-length")]
    assert all(v.value == 310.25 and not v.identified and "two postures" in v.note
               for v in legs)
    theta = m.theta_c()
    assert theta[3:6].tolist() == [0.0, 0.0, 0.0]  # ΔL, not L + ΔL
    assert theta[6:].tolist() == pytest.approx(list(LAYOUT.values()))
    assert "OG-7" in m.describe() and "rho+tilt+gap" in m.describe()


def test_what_the_model_test_did_not_keep_stays_nominal_and_says_so(tmp_path: Path) -> None:
    m = identified_machine(run_dir(tmp_path, "rho+gap"))
    tilts = [v for v in m.values if v.name.startswith("tilt")]
    assert all(v.value == 0.0 and not v.identified for v in tilts)
    assert "rho+gap" in tilts[0].note and "+0.200 ± 0.021 mrad (95 %" in tilts[0].note
    assert m.theta_c()[6:9].tolist() == [0.0, 0.0, 0.0]
    assert m.theta_c()[9:].tolist() == pytest.approx([0.15, -0.1, 0.12])
    assert m.estimate[6] == pytest.approx(0.2)  # the run's best value is kept beside


def test_a_record_from_before_the_statement_keeps_model_json_s_intervals(
        tmp_path: Path) -> None:
    d = run_dir(tmp_path)
    doc = json.loads((d / "result.json").read_text())
    del doc["statement"], doc["advice"]
    (d / "result.json").write_text(json.dumps(doc))
    told = {v.name: v for v in identified_machine(d).values if v.identified}
    k = coverage_factor(40.0)
    lo, hi = told["tilt_yx"].interval_95
    assert lo == pytest.approx(0.2 - k * 0.01) and hi == pytest.approx(0.2 + k * 0.01)
    lo, hi = told["drho_x"].interval_95
    assert hi - lo == pytest.approx(2 * coverage_factor(60.0) * 0.0008)


@pytest.mark.parametrize("status", ["failed", "aborted"])
def test_a_run_that_did_not_finish_is_refused(tmp_path: Path, status: str) -> None:
    with pytest.raises(NotACalibration, match=f"the run {status}"):
        identified_machine(run_dir(tmp_path, status=status))


def test_a_run_that_identified_nothing_is_refused(tmp_path: Path) -> None:
    with pytest.raises(NotACalibration, match="identified nothing"):
        identified_machine(run_dir(tmp_path, with_model=False))
    with pytest.raises(NotACalibration, match=r"result\.json: cannot read"):
        identified_machine(tmp_path / "nowhere")


def test_a_damaged_model_is_named(tmp_path: Path) -> None:
    d = run_dir(tmp_path)
    doc = json.loads((d / "model.json").read_text())
    del doc["drho_now"]
    (d / "model.json").write_text(json.dumps(doc))
    with pytest.raises(NotACalibration, match=r"model\.json: drho_now"):
        identified_machine(d)


def test_a_run_that_could_not_tell_tilts_from_bows_is_no_calibration(tmp_path: Path) -> None:
    # docs/model.md, "Tilts or bows": put into a controller, tilts that may be bows
    # would move the tool by what the bows only seemed to be. The machine is read as
    # it is; whether it may go out is the one decision of station.record.exportable,
    # which export (--force) and compensate (never) ask.
    ambiguous_dir = run_dir(tmp_path, ambiguous=True)
    assert identified_machine(ambiguous_dir).model == "rho+tilt+gap"
    record = read_result(ambiguous_dir / "result.json")
    assert exportable.ambiguous(record) == ("its last round could not tell the axes' tilts "
                                            "from the legs' bows (rho+tilt+gap or "
                                            "rho+gap+form)")
    assert exportable.unresolved(record) == [exportable.ambiguous(record)]
    plain = read_result(run_dir(tmp_path, model="rho+tilt") / "result.json")
    assert exportable.ambiguous(plain) is None and exportable.unresolved(plain) == []
    program = tmp_path / "part.ngc"
    program.write_text("G0 X0 Y0 Z0\nG1 X1 F100\nM2\n")
    refused = cli("compensate", str(program), "--run", str(ambiguous_dir), cwd=tmp_path)
    assert refused.returncode == 2 and refused.stdout == ""
    (line,) = refused.stderr.strip().splitlines()
    assert "could not tell the axes' tilts from the legs' bows" in line
    assert str(ambiguous_dir) in line
    assert not list(tmp_path.glob("part.compensated*"))
