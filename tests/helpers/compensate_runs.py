"""Run directories for ``orthocal compensate`` without running a calibration: a
result.json and a model.json (checked against station.record.model, as the engine's
own is), with the soft limits in plan.json or config.toml.

TILTED is a machine with gaps (0.15, −0.10, 0.12) mm, tilts (0.2, 0.1, −0.15) mrad and
a few µm of Δρ left after the offsets written; SQUARE one whose axes meet, square,
with nothing left. Each is also given as the 12-vector of PARAM_NAMES it means, for
the tests to compute where the tool goes by orthocal's kinematics themselves."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from result_builders import golden_result

from orthocal import PARAM_NAMES
from station.record.model import MachineModel

LEG, RHO_MIN, RHO_MAX = 310.25, -100.0, 60.0
#: The paper's machine's joints at its soft limits: every test posture with 10 mm spare.
SOFT = ([LEG + RHO_MIN - 10.0] * 3, [LEG + RHO_MAX + 10.0] * 3)

DRHO_NOW = {"drho_x": 0.002, "drho_y": -0.001, "drho_z": 0.0015}
TILTS = {"tilt_yx": 0.2, "tilt_zx": 0.1, "tilt_zy": -0.15}
GAPS = {"gap_xy": 0.15, "gap_xz": -0.10, "gap_yz": 0.12}
TILTED = np.array([*DRHO_NOW.values(), 0.0, 0.0, 0.0, *TILTS.values(), *GAPS.values()])
SQUARE = np.zeros(12)


def model_json(kind: str) -> dict:
    """model.json of a run that kept ``rho+tilt+gap`` (tilted) or ``rho`` (square)."""
    tilted = kind == "tilted"
    start = {"drho_x": 0.512, "drho_y": -0.311, "drho_z": 0.805}
    layout = {**TILTS, **GAPS} if tilted else {n: 0.0 for n in (*TILTS, *GAPS)}
    parameters = {**start, "dL_x": 0.0, "dL_y": 0.0, "dL_z": 0.0, **layout}
    estimated = [n for n in PARAM_NAMES if n.startswith("drho")
                 or (tilted and not n.startswith("dL"))]
    se = {n: 0.01 if n.startswith("tilt") else 0.002 for n in estimated}
    doc = {
        "format": "orthocal machine model 1",
        "geometry": {"leg_length_mm": LEG, "rho_min_mm": RHO_MIN, "rho_max_mm": RHO_MAX},
        "conventions": {"model": "docs/model.md (1')", "axes": "tilts ×1e-3",
                        "gaps": "midway", "drho": "o <- o - drho",
                        "parameters": "drho at the start"},
        "units": {"drho": "mm", "dL": "mm", "tilt": "mrad", "gap": "mm"},
        "model": "rho+tilt+gap" if tilted else "rho",
        "parameters": parameters,
        "estimated": estimated,
        "not_estimated": {n: "taken as 0" for n in PARAM_NAMES if n not in estimated},
        "std_errors": se,
        "covariance": {"names": estimated,
                       "matrix": np.diag([se[n] ** 2 for n in estimated]).tolist()},
        "std_errors_dof": 12.0,
        "drho_now": DRHO_NOW if tilted else {n: 0.0 for n in DRHO_NOW},
        "offsets_before": {"x": 0.0, "y": 0.0, "z": 0.0},
        "offsets_written": {a: -start[f"drho_{a}"] for a in "xyz"},
    }
    return MachineModel.model_validate(doc).model_dump(mode="json")


def stated_as(statement: list[dict], kind: str) -> list[dict]:
    """The golden run's statement with the geometry this run's model.json holds: the
    controller is told the statement's values (station.record.identified), so the two
    files of one run directory must tell one machine."""
    tilted = kind == "tilted"
    values = {**{f"{n}.as_left": (v if tilted else 0.0) for n, v in DRHO_NOW.items()},
              **{n: (v if tilted else 0.0) for n, v in {**TILTS, **GAPS}.items()},
              **{f"dl_{a}": 0.0 for a in "xyz"}}
    out = []
    for q in statement:
        if q["name"] in values:
            v = values[q["name"]]
            q = {**q, "value": v, "interval_95": [v - q["expanded"], v + q["expanded"]]}
        out.append(q)
    return out


def write_run(path: Path, kind: str = "tilted", *, status: str = "ok", model: bool = True,
              limits: str | None = "plan", soft: tuple = SOFT) -> Path:
    """A run directory at ``path``; ``limits``: where its soft limits are ("plan":
    plan.json, "config": config.toml only, None: nowhere)."""
    path.mkdir(parents=True)
    # a whole record (the golden run's): export reads result.json validated
    result = {**golden_result(), "run_dir": str(path), "status": status,
              "offsets_held_by": "controller"}
    result["machine"]["id"] = f"OG-{kind}"
    result["remaining"].update(std_errors={n: 0.001 for n in DRHO_NOW}, std_errors_dof=12.0)
    result["statement"] = stated_as(result["statement"], kind)
    if status != "ok":
        result["message"] = "the indicator on leg y stopped answering"
    (path / "result.json").write_text(json.dumps(result, indent=1))
    if model:
        (path / "model.json").write_text(json.dumps(model_json(kind), indent=1))
    lower, upper = soft
    (path / "plan.json").write_text(json.dumps(
        {"cycles": 2, "soft_limits": {"lower": lower, "upper": upper, "source": "registers"}
         if limits == "plan" else None}))
    if limits == "config":
        (path / "config.toml").write_text(f"[controller]\nsoft_min = {lower}\n"
                                          f"soft_max = {upper}\n")
    return path
