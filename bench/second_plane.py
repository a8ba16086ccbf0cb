"""Bowed legs on a tilted machine, with and without a second gauge plane per leg.

A uniform bow of the legs is exactly a tilt signature in the legs' middles, at any
strokes (docs/model.md, "Leg form against tilts and gaps"). Whole simulated
calibrations (``orthocal run --simulate`` in-process, the default procedure:
three cycles of five readings, model ``auto``, closed loop, stands placed by eye
up to 5 mm off, 1 µm of gauge noise, the default ``[uncertainty]``: legs straight
to 10 µm) of a machine tilted (0.2, 0.1, −0.15) mrad whose legs are bowed, with
``objective = "tool"``:

* ``middle``: the default setups, the gauges at the legs' middles;
* ``second``: each gauge also read at three quarters of its leg (``[[setups]] at =
  0.75``, three more setups per round; at 0.25 the carriage passes the plane at
  Π_i^−), so the fit takes each gauge plane's bow
  (``bow_xy`` … ``bow_zy``) beside the geometry.

For every run, from the hidden machine: the model kept, the loop's end, the tilts
and bows stated against the truth, and the tool error after calibration (true,
µm RMS) against the best any offsets reach.

    python bench/second_plane.py                  # 2 seeds, both setups
    python bench/second_plane.py --runs 3 --bow 0.008 --setups second
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.runs import run_json
from orthocal import AXES, BOW_NAMES, TILT_NAMES, Geometry
from orthocal.accuracy import error_field, optimal_offsets
from station.commands.options import RunOptions, SimOptions

NOISE_MM = 0.001
DRHO = (0.6, -0.4, 0.9)
TILT = (0.2, 0.1, -0.15)
SECOND = 0.75


def second_plane_setups(setups: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The simulator's setups, then each again at ``SECOND`` of its leg."""
    return [*setups, *({**s, "at": SECOND} for s in setups)]


def one_run(seed: int, bow: float, setups: str, out: Path) -> dict[str, Any]:
    def hook(station: Any) -> None:
        if setups == "second":
            config = station.config
            station.config = lambda: {**config(),
                                      "setups": second_plane_setups(config()["setups"])}

    options = RunOptions(sim=SimOptions(seed=seed, true_drho=DRHO, true_tilt=TILT,
                                        true_gap=(0.0, 0.0, 0.0), noise=NOISE_MM,
                                        leg_bow=f"{bow}", writeback={"objective": "tool"},
                                        station_hook=hook),
                         out=out, yes=True, json=True)
    code, result = run_json(options)
    result["exit_code"] = code
    return result


def judge(result: dict[str, Any], bow: float) -> dict[str, Any]:
    """The run's statements against the hidden machine."""
    m = result["machine"]
    geometry = Geometry(leg_length=m["leg_length"], rho_min=m["rho_min"], rho_max=m["rho_max"])
    acc = result["accuracy"]
    points = np.asarray(acc["field"]["points_mm"], dtype=float)
    truth = np.array([*DRHO, 0.0, 0.0, 0.0, *TILT, 0.0, 0.0, 0.0])
    final = result["offsets_final"]
    o = np.array([final[a] - result["offsets_before"][a] for a in AXES])
    true_after = error_field(points, geometry, truth, o, acc["frame"]).rms_mm
    best = optimal_offsets(points, geometry, truth, acc["frame"]).field.rms_mm
    tilts = acc.get("tilts") or {}
    last = result["iterations"][-1] if result.get("iterations") else {}
    stated = {**(result.get("identified") or {}), **(last.get("identified") or {})}
    bows = [stated[n] for n in BOW_NAMES if n in stated]
    return {
        "model": result["model"], "stopped": result["loop"]["stopped"],
        "detail": result["loop"].get("detail"), "exit": result["exit_code"],
        "mountings": result["timing"]["mountings"],
        "tilt_err": max(abs(tilts.get(n, 0.0) - t) for n, t in zip(TILT_NAMES, TILT, strict=True)),
        "bow_err_um": 1000 * max(abs(b - bow) for b in bows) if bows else float("nan"),
        "true_um": 1000 * true_after, "best_um": 1000 * best,
        "predicted_um": 1000 * acc["after"]["rms_mm"],
        "interval_um": [1000 * v for v in acc["after"].get("rms_interval_95_mm") or []],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--bow", type=float, default=0.008, help="each leg's sagitta, mm")
    parser.add_argument("--setups", choices=["middle", "second", "both"], default="both")
    args = parser.parse_args()
    print(f"tilts {TILT} mrad, legs bowed {1000 * args.bow:g} µm, Δρ {DRHO} mm, noise "
          f"{1000 * NOISE_MM:g} µm, objective tool, default procedure and [uncertainty], "
          "stands by eye")
    kinds = ["middle", "second"] if args.setups == "both" else [args.setups]
    with tempfile.TemporaryDirectory(prefix="orthocal-plane-") as tmp:
        for kind in kinds:
            for k in range(args.runs):
                t0 = time.monotonic()
                r = judge(one_run(args.seed + k, args.bow, kind, Path(tmp)), args.bow)
                print(f"  {kind}, seed {args.seed + k}: model {r['model']}, loop {r['stopped']} "
                      f"(exit {r['exit']}); tilts off by ≤ {r['tilt_err']:.3f} mrad, bows ≤ "
                      f"{r['bow_err_um']:.1f} µm; tool after {r['true_um']:.1f} µm RMS true "
                      f"({r['predicted_um']:.1f} predicted, 95 % "
                      f"{' … '.join(f'{v:.1f}' for v in r['interval_um']) or '—'}), best offsets "
                      f"{r['best_um']:.1f} "
                      f"({r['true_um'] / r['best_um']:.2f}×); {r['mountings']} mountings; "
                      f"{time.monotonic() - t0:.0f} s")
                if r["stopped"] != "converged":
                    print(f"    {r['detail']}")


if __name__ == "__main__":
    main()
