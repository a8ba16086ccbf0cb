"""A result document as orthocal run writes it, built from the paper's
linearised model (no station, no devices): the report tests' input."""

from __future__ import annotations

import json
import math
import random
from pathlib import Path

import numpy as np

from station import report
from station.record.result import SCHEMA_VERSION

GOLDEN = Path(__file__).parents[1] / "data" / "golden_run"
L, RHO_MIN, RHO_MAX = 310.25, -100.0, 60.0
AXES = "xyz"
PAPER_BEFORE = dict(zip(
    ["+yx", "+xy", "-yx", "-xy", "+zx", "+xz", "-zx", "-xz", "+zy", "+yz", "-zy", "-yz"],
    [-0.19, 0.08, 0.22, -0.34, -0.29, -0.52, 0.08, 0.62, 0.02, -0.24, 0.20, 0.45],
    strict=True,
))


def _coefficients(sign: str) -> tuple[float, float, float]:
    """a, b, c of the linearised calibration equations (docs/model.md, system (7))."""
    s = (RHO_MAX if sign == "+" else RHO_MIN) / L
    alpha = math.asin(s)
    return s, (0.5 + s) * math.tan(alpha), (0.5 + s) / math.cos(alpha) - 0.5


def _jacobian(names: list[str]) -> np.ndarray:
    rows = []
    for key in report.DEVIATION_KEYS:
        sign, i, j = key
        a, b, c = _coefficients(sign)
        coef = {f"drho_{i}": b, f"drho_{j}": a, f"dL_{i}": -b, f"dL_{j}": -c}
        rows.append([coef.get(n, 0.0) for n in names])
    return np.array(rows)


def _fit(measured: dict[str, float], names: list[str]) -> dict:
    J = _jacobian(names)
    y = np.array([measured[k] for k in report.DEVIATION_KEYS])
    x, *_ = np.linalg.lstsq(J, y, rcond=None)
    model = J @ x
    n, p = J.shape
    sigma = math.sqrt(float(np.sum((y - model) ** 2)) / (n - p))
    cov = sigma**2 * np.linalg.inv(J.T @ J)
    se = np.sqrt(np.diag(cov))
    return {
        "identified": dict(zip(names, x.tolist(), strict=True)),
        "std_errors": dict(zip(names, se.tolist(), strict=True)),
        "correlation": {"names": names, "matrix": (cov / np.outer(se, se)).tolist()},
        "model": dict(zip(report.DEVIATION_KEYS, model.tolist(), strict=True)),
        "residual_rms_mm": float(np.sqrt(np.mean((y - model) ** 2))),
        "sigma_mm": sigma,
        "condition_number": float(np.linalg.cond(J)),
        "rms": float(np.sqrt(np.mean(y**2))),
    }


def _measure(truth: dict[str, float], rng: random.Random, noise: float, cycles: int) -> dict:
    J = _jacobian(list(truth))
    exact = J @ np.array(list(truth.values()))
    out = {}
    for key, value in zip(report.DEVIATION_KEYS, exact, strict=True):
        samples = [value + rng.gauss(0.0, noise) for _ in range(cycles)]
        out[key] = {"mean": sum(samples) / cycles, "std": float(np.std(samples, ddof=1)),
                    "n": cycles}
    return out


NO_GUARD_STOPS = {"stops": 0, "recovered": [], "retakes": 0, "refused": 0}


def simulation(seed: int, true_drho: dict[str, float], true_dl: dict[str, float],
               noise: float) -> dict:
    """result.json's ``simulation``: the hidden machine, no other error simulated."""
    zero = dict.fromkeys(AXES, 0.0)
    return {"seed": seed, "true_drho": true_drho, "true_dl": true_dl,
            "true_tilt": dict.fromkeys(("tilt_yx", "tilt_zx", "tilt_zy"), 0.0),
            "true_gap": dict.fromkeys(("gap_xy", "gap_xz", "gap_yz"), 0.0),
            "noise_mm": noise, "mount_error_mm": 0.0, "backlash_mm": zero,
            "leg_bow_mm": zero, "gauge_scale": {"A": 0.0, "B": 0.0}}


def make_result(
    *, model: str = "rho", seed: int = 7, noise: float = 0.004, verify: bool = True,
    measured: dict[str, float] | None = None, run_dir: str = "runs/2024-05-02T10-15-00",
) -> dict:
    """A result dict as cmd_run would produce it: simulated machine with hidden offsets,
    readings with noise, a least-squares fit, write-back and a verification run."""
    rng = random.Random(seed)
    true_drho = {"x": -0.48, "y": 0.49, "z": -1.67}
    true_dl = {"x": 0.0, "y": 0.0, "z": 0.0}
    truth = {f"drho_{a}": v for a, v in true_drho.items()} | {
        f"dL_{a}": v for a, v in true_dl.items()}
    names = {"rho": [f"drho_{a}" for a in AXES], "L": [f"dL_{a}" for a in AXES],
             "full": [f"drho_{a}" for a in AXES] + [f"dL_{a}" for a in AXES]}[model]
    devs = _measure(truth, rng, noise, 3)
    if measured is not None:
        for k, v in measured.items():
            devs[k]["mean"] = v
    fit = _fit({k: d["mean"] for k, d in devs.items()}, names)
    for k, d in devs.items():
        d["model"] = fit["model"][k]
    before = {"x": 0.125, "y": -0.040, "z": 0.310}
    written = {a: before[a] - fit["identified"].get(f"drho_{a}", 0.0) for a in AXES}
    result = {
        "schema_version": SCHEMA_VERSION,
        "run_dir": run_dir, "status": "ok", "message": None,
        "started": "2024-05-02T10:15:00+02:00", "finished": "2024-05-02T10:21:42+02:00",
        "duration_s": 402.3, "simulated": True,
        "simulation": simulation(seed, true_drho, true_dl, noise),
        "machine": {"id": None, "leg_length": L, "rho_min": RHO_MIN, "rho_max": RHO_MAX},
        "model": model, "method": "nonlinear",
        "identified": fit["identified"], "std_errors": fit["std_errors"],
        "correlation": fit["correlation"],
        "residual_rms_mm": fit["residual_rms_mm"], "sigma_mm": fit["sigma_mm"],
        "condition_number": fit["condition_number"], "noise_mm": noise,
        "fit_ok": fit["residual_rms_mm"] < 3 * noise,
        "fit_note": "residual at the indicator noise level"
        if fit["residual_rms_mm"] < 3 * noise else "residual well above the indicator noise",
        "deviations": devs, "deviations_rms_mm": fit["rms"],
        "setups": [{"leg": a, "indicators": {"A": b, "B": c}, "cycles_used": 3,
                    "cycles_max": 5, "repeats": 0, "flagged": False, "spread_mm": 0.006}
                   for a, b, c in (("x", "y", "z"), ("y", "x", "z"), ("z", "x", "y"))],
        "offsets_before": before, "offsets_written": written, "offsets_final": written,
        "offsets_held_by": "controller",
        "writeback": {"status": "written", "reason": None},
        "verification": None,
        "plunger_guard": NO_GUARD_STOPS,
        "timing": {"wall_s": 402.3, "moves": 74, "readings": 370, "retries": 1,
                   "outliers_rejected": 0, "mountings": 3, "operator_s": 60.0},
    }
    if verify:
        left = {n: truth[n] - fit["identified"].get(n, 0.0) for n in truth}
        vdevs = _measure(left, rng, noise, 3)
        vfit = _fit({k: d["mean"] for k, d in vdevs.items()}, names)
        for k, d in vdevs.items():
            d["model"] = vfit["model"][k]
            d["expected"] = 0.0  # the model's prediction once Δρ is written
        result["verification"] = {
            "identified": vfit["identified"], "std_errors": vfit["std_errors"],
            "std_errors_dof": None,
            "residual_rms_mm": vfit["residual_rms_mm"], "deviations_rms_mm": vfit["rms"],
            "expected_rms_mm": 0.0, "vs_expected_rms_mm": vfit["rms"], "noise_floor_mm": noise,
            "deviations": vdevs, "setups": result["setups"],
        }
    return result


def golden_result() -> dict:
    """The golden run's result.json (tests/data/golden_run) as a record the report
    takes: what tests/station/engine/test_unchanged.py took out as unrepeatable (the run directory,
    the times, the wall and operator time) put back, fixed."""
    result = json.loads((GOLDEN / "result.json").read_text(encoding="utf-8"))
    result.update(run_dir="RUN_DIR", started="2024-05-02T10:15:00+02:00",
                  finished="2024-05-02T10:21:42+02:00", duration_s=402.3)
    result["timing"].update(wall_s=402.3, operator_s=60.0)
    return result
