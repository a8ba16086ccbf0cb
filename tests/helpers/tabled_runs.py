"""Joint tables for the tests of the routes into the machine (imported by the export and
compensate tests): a screw's ISO 230-2 test as the CSV a shop gives ([joints] tests),
and a result.json's ``joints`` section holding tables, as the run writes it.

The screws are stated here on their own: ε(ρ) = k·1e-6·(ρ − L) (homed at Π0, model.md
(J2)) plus, for a table with a dead band B, ∓B/2 forward / reverse; a laser's reading
adds a seeded normal draw of U/2 (U the test's expanded uncertainty)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

L = 310.25
#: 10 mm targets over the travel the paper's workspace and postures need (176 to 370 mm).
TARGETS = np.arange(170.0, 381.0, 10.0)


def screw_um(lead_um_per_m: float, targets=TARGETS, band_um: float = 0.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """(forward, reverse) deviations, µm, of a lead ``lead_um_per_m`` with a dead band."""
    mean = lead_um_per_m * 1e-3 * (np.asarray(targets) - L)
    return mean - band_um / 2.0, mean + band_um / 2.0


def laser_csv(path: Path, lead_um_per_m: float, u_um: float = 0.5, seed: int = 0,
              targets=TARGETS) -> Path:
    """An ISO 230-2 test of a screw as a shop's laser gives it: the deviations read with
    a normal error of U/2 (seeded), and ``u_um`` = U, the test's uncertainty at 95 %."""
    rng = np.random.default_rng(seed)
    forward, reverse = screw_um(lead_um_per_m, targets)
    rows = ["target_mm,forward_um,reverse_um,u_um"]
    for t, f, r in zip(targets, forward, reverse, strict=True):
        fe, re_ = rng.normal(0.0, u_um / 2.0, 2)
        rows.append(f"{t:.3f},{f + fe:.4f},{r + re_:.4f},{u_um:g}")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def table_record(lead_um_per_m: float, band_um: float = 0.0, u_um: float | None = 0.5,
                 targets=TARGETS) -> dict[str, Any]:
    """result.json's ``joints.<axis>.table`` of a screw (referred to Π0: 0 at L)."""
    forward, reverse = screw_um(lead_um_per_m, targets, band_um)
    return {"targets_mm": [float(t) for t in targets],
            "forward_um": [float(v) for v in forward],
            "reverse_um": [float(v) for v in reverse],
            "u95_um": None if u_um is None else [u_um] * len(targets),
            "shift_um": 0.0, "reversal_from": "test"}


def with_tables(doc: dict[str, Any], tables: dict[str, dict[str, Any]],
                bound_um_per_m: float = 170.0) -> dict[str, Any]:
    """``doc`` (a result.json) whose ``joints`` holds ``tables`` (axis → table record,
    source test, file ``<axis>.csv``); the other joints assumed within the bound."""
    joints = dict(doc["joints"])
    for axis in "xyz":
        if axis in tables:
            joints[axis] = {"source": "test", "file": f"/shop/{axis}.csv",
                            "lead_um_per_m": 0.0, "lead_interval_95_um_per_m": [-1.0, 1.0],
                            "bound_um_per_m": None, "table": tables[axis]}
        else:
            joints[axis] = {"source": "assumed", "file": None, "lead_um_per_m": 0.0,
                            "lead_interval_95_um_per_m": [-0.95 * bound_um_per_m,
                                                          0.95 * bound_um_per_m],
                            "bound_um_per_m": bound_um_per_m, "table": None}
    return {**doc, "joints": joints}
