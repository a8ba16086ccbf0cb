"""Lost motion: what a joint's reversal does to the identification, before and after
the one-side approach.

Each run is one measurement of the station's procedure (three setups, two gauges
each, 3 cycles × 5 readings, a reversal stop per cycle), simulated reading by
reading on the exact model: hidden Δρ uniform in ±1.5 mm, every stand by eye (±5
mm off the leg's middle), gauges of 1 µm noise quantised to 1 µm, and every
joint's carriage following its count through a dead band of B (a play operator,
docs/model.md "Lost motion"). "before": the stops in the paper's order (the joints
reach them from either side, approach "as-planned"); "after": every stop
approached from below after a 0.05 mm overrun, Δρ moved to the middle of the band
with the reversal the run measured. Identified by the station's own code
(station.analysis.model_choice with model auto, the stands modelled), the reversal by
station.analysis.reversal.

Printed per case: the worst axis's Δρ error (RMS over runs, µm; against the middle
of the band), how often auto took a model with tilts (on a square machine: false
alarms; on the tilted one the tilt error RMS, mrad) and the reversal error (RMS, µm).

    python bench/lost_motion_runs.py [--runs 40] [--seed 1]

The time the approach costs is a whole run's: ``python bench/cycle.py --approach
as-planned`` against ``python bench/cycle.py`` (BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import orthocal
from orthocal.lost_motion import band_middle, reversal_gain
from station.analysis import reversal
from station.analysis.model_choice import identify_measurement
from station.analysis.statistics import Measurement, SetupOutcome
from station.config import parse_config

G = orthocal.Geometry()
SETUPS = (("x", ("y", "z")), ("y", ("x", "z")), ("z", ("x", "y")))
CYCLES, READINGS, NOISE, RESOLUTION, OVERRUN = 3, 5, 0.001, 0.001, 0.05
TILTED = (0.3, -0.2, 0.25)


def config(approach: str):
    return parse_config({
        "indicators": [{"name": f"{leg}{d}", "port": f"/dev/{leg}{d}"}
                       for leg, dirs in SETUPS for d in dirs],
        "setups": [{"leg": leg, "indicators": {f"{leg}{d}": d for d in dirs}}
                   for leg, dirs in SETUPS],
        "procedure": {"cycles": CYCLES, "readings": READINGS, "approach": approach,
                      "approach_overrun_mm": OVERRUN}})


def measure(rng: np.random.Generator, drho: np.ndarray, tilt: np.ndarray, band: np.ndarray,
            approach: str) -> Measurement:
    """One measurement, reading by reading (module docstring)."""
    half = band / 2
    deviations: dict[str, list[float]] = {}
    rev: dict[str, list[float]] = {}
    carriage = orthocal.posture("0", None, G) - half  # last arrived from below
    gain = reversal_gain("x", "y", G)

    def go(target: np.ndarray, side: int) -> None:
        nonlocal carriage
        if side:  # the last leg from OVERRUN beyond, on that side
            over = target + side * OVERRUN
            carriage = np.clip(carriage, over - half, over + half)
        carriage = np.clip(carriage, target - half, target + half)

    def read(leg: str, direction: str, plane: float) -> float:
        value = float(orthocal.leg_reading(carriage, leg, direction, G, drho, mount=plane,
                                           tilt=tilt))
        raw = value + rng.normal(0.0, NOISE, READINGS)
        return float(np.mean(np.round(raw / RESOLUTION) * RESOLUTION))

    side = {"below": -1, "above": 1, "as-planned": 0}[approach]
    outcomes = []
    for index, (leg, dirs) in enumerate(SETUPS):
        planes = {d: G.mount_plane + rng.uniform(-5.0, 5.0) for d in dirs}
        postures = {s: orthocal.posture(s, leg, G) for s in ("0", "+", "-")}
        go(postures["0"], side)
        zero = {d: read(leg, d, planes[d]) for d in dirs}
        for _ in range(CYCLES):
            at = {}
            for s in ("+", "-"):
                go(postures[s], side)
                at[s] = {d: read(leg, d, planes[d]) for d in dirs}
            go(postures["0"], side)
            end = {d: read(leg, d, planes[d]) for d in dirs}
            go(postures["0"], 1 if side <= 0 else -1)  # the reversal stop, the other side
            other = {d: read(leg, d, planes[d]) for d in dirs}
            for d in dirs:
                for s in ("+", "-"):
                    deviations.setdefault(f"{s}{leg}{d}", []).append(
                        at[s][d] - 0.5 * (zero[d] + end[d]))
                rev.setdefault(d, []).append((1 if side <= 0 else -1)
                                             * (other[d] - end[d]) / gain)
            zero = end
        outcomes.append(SetupOutcome(index, leg, {f"{leg}{d}": d for d in dirs}, CYCLES,
                                     CYCLES, 0, False, 0.0, list(range(1, CYCLES + 1))))
    return Measurement("m", deviations, outcomes, [NOISE] * 10, rev)


def one_run(seed: int, b_mm: float, tilted: bool, approach: str) -> dict[str, float]:
    rng = np.random.default_rng([seed, int(b_mm * 1e6), tilted])
    drho = rng.uniform(-1.5, 1.5, 3)
    tilt = np.array(TILTED if tilted else (0.0, 0.0, 0.0))
    cfg = config(approach)
    m = measure(rng, drho, tilt, np.full(3, b_mm), approach)
    ident, _ = identify_measurement(cfg, m)
    rev = reversal.estimate(cfg, [m])
    ident = band_middle(ident, rev, approach)
    err = max(abs(ident.parameters[f"drho_{a}"] - drho[i]) for i, a in enumerate("xyz"))
    tilts = [ident.parameters.get(n) for n in ("tilt_yx", "tilt_zx", "tilt_zy")]
    with_tilt = tilts[0] is not None
    tilt_err = float(np.sqrt(np.mean(np.square(np.array(tilts) - tilt)))) if with_tilt \
        else float(np.sqrt(np.mean(np.square(tilt))))
    b_err = max(abs((rev.value[a] or 0.0) - b_mm) for a in "xyz")
    return {"err_um": 1000 * err, "tilt": float(with_tilt), "tilt_err": tilt_err,
            "b_err_um": 1000 * b_err}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    print(f"{args.runs} runs per case; 3 cycles × 5 readings, 1 µm noise, stands ±5 mm, "
          f"model auto; B on every joint")
    print(f"{'machine':>8} {'B µm':>5} {'approach':>11} {'Δρ err RMS µm':>14} "
          f"{'with tilts':>10} {'tilt err mrad':>13} {'B err RMS µm':>12}")
    for tilted in (False, True):
        for b_um in (0, 5, 10, 20):
            for approach in ("as-planned", "below"):
                rows = [one_run(args.seed + k, b_um / 1000, tilted, approach)
                        for k in range(args.runs)]

                def rms(key: str, rows: list[dict[str, float]] = rows) -> float:
                    return float(np.sqrt(np.mean([r[key] ** 2 for r in rows])))

                share = sum(r["tilt"] for r in rows) / len(rows)
                print(f"{'tilted' if tilted else 'square':>8} {b_um:>5} {approach:>11} "
                      f"{rms('err_um'):>14.2f} {100 * share:>9.0f}% "
                      f"{rms('tilt_err'):>13.3f} {rms('b_err_um'):>12.2f}", flush=True)


if __name__ == "__main__":
    main()
