"""What a calibration costs the operator: mountings, and the whole run's time.

Whole simulated calibrations (``orthocal run --simulate`` in-process, stands placed
by eye up to 5 mm off, the default procedure: three cycles of five readings, model
``auto``, closed loop) over seeds. For every run: how the loop stopped, its
write-backs, the mountings the journal records (``timing.mountings``) against the
bound of 3 × (write-backs + 1) (one per leg in each measurement), the joint error
the offsets leave against the hidden truth (µm), the machine's wall time, and the
whole calibration's time with each mounting costed at ``--mount-s`` seconds of the
operator's. The gauges of a pass's last setup stay on for the next pass's first
(station.engine.kept): the bound is 3 + 2 × write-backs (``--second-plane``, every
setup again at 0.75 of its leg: the run's second pass measures both planes, every other
one the legs' middles alone, carrying the bows, 3 + 5 + 2 × (write-backs − 1) = 6 + 2 ×
write-backs, station.plan.steps.Plan.setups_of). ``before`` prints
the figures measured on the code before (9 mountings for two write-backs; 30 with a
second plane, then 16 while every round measured both planes).

    python bench/mountings.py                     # seeds 1-5, 1 µm noise
    python bench/mountings.py --noise 0.002 --runs 10
    python bench/mountings.py --in-mounting 3     # without more cycles per mounting
    python bench/mountings.py --drive-profile cosine --runs 3   # a held-out controller
    python bench/mountings.py --second-plane --runs 2   # [[setups]] at 0.75 as well
    python bench/mountings.py --recheck --runs 3  # then each machine again: writes nothing
    python bench/mountings.py --recheck --runs 3 --seed 7 --tilt 0.2,0.1,-0.15 \\
        --gap 0.15,-0.10,0.12 --stated 0.002    # the held-out machine, then again
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.runs import run_json
from orthocal import AXES
from station.commands.options import DriveOptions, RunOptions, SimOptions

#: The figures of the code before the gauges stayed on (BENCHMARKS.md as it stood,
#: 2026-12-02, and the request's own runs on the held-out cosine drive;
#: bench/second_plane.py): (mountings, write-backs) per run.
BEFORE = {"1 µm": [(9, 2)] * 6, "held-out cosine drive": [(9, 2), (6, 1), (9, 2)],
          "second plane": [(30, 2)], "second plane, both planes every round": [(16, 2)]}


def one_run(seed: int, args: argparse.Namespace, out: Path,
            true_drho: tuple[float, float, float] | None = None) -> dict[str, Any]:
    """One whole simulated calibration of the machine ``args`` describe (``true_drho``:
    its joints' error instead of the seed's)."""
    procedure = None if args.in_mounting is None else \
        {"max_cycles_in_mounting": args.in_mounting}

    def hook(station: Any) -> None:
        config = station.config
        if procedure is not None:  # what a user writes in the config's [procedure]
            station.config = lambda: {**config(), "procedure": {
                **config().get("procedure", {}), **procedure}}
        if args.stated is not None:  # the config's [uncertainty]
            stated = station.config
            station.config = lambda: {**stated(), "uncertainty": {
                "leg_straightness_mm": args.stated}}
        if args.second_plane:  # each setup again at three quarters of its leg
            setups = station.config
            station.config = lambda: {**setups(), "setups": [
                *setups()["setups"], *({**x, "at": 0.75} for x in setups()["setups"])]}

    # A drive of its own timing (the station is told nothing of it): a held-out controller.
    drive = DriveOptions(profile=args.drive_profile)
    options = RunOptions(sim=SimOptions(seed=seed, noise=args.noise, station_hook=hook,
                                        drive=drive, true_drho=true_drho, true_gap=args.gap,
                                        true_tilt=_triple(args.tilt)),
                         out=out, yes=True, json=True)
    code, result = run_json(options)
    result["exit_code"] = code
    return result


def _triple(text: str | None) -> tuple[float, float, float] | None:
    if text is None:
        return None
    x, y, z = (float(v) for v in text.split(","))
    return x, y, z


def judge(result: dict[str, Any], mount_s: float, first: int = 3,
          later: int = 3) -> dict[str, Any]:
    """The run's figures; ``first``: the plan's setups, ``later``: those every later
    pass measures (the bound is ``first``, then ``later`` − 1 per write-back: one
    setup's gauges stay on)."""
    truth = np.array([result["simulation"]["true_drho"][a] for a in AXES])
    o = np.array([result["offsets_final"][a] - result["offsets_before"][a] for a in AXES])
    timing = result["timing"]
    writes = result["loop"]["write_backs"]
    return {
        "stopped": result["loop"]["stopped"], "write_backs": writes,
        "mountings": timing["mountings"], "bound": first + (later - 1) * writes,
        "left_um": 1000 * float(np.abs(truth + o).max()),
        "wall_s": timing["wall_s"],
        "whole_s": timing["wall_s"] + mount_s * timing["mountings"],
    }


def recheck(args: argparse.Namespace, seed: int, out: Path, first: dict[str, Any]) -> str:
    """The machine ``first`` calibrated, run again: its joints' error is now what the
    offsets written left (true Δρ + offsets), as a shop's periodic check finds it."""
    x, y, z = (first["simulation"]["true_drho"][a] + first["offsets_final"][a]
               - first["offsets_before"][a] for a in AXES)
    again = one_run(seed, args, out, true_drho=(x, y, z))
    changed = max(abs(again["offsets_final"][a] - again["offsets_before"][a]) for a in AXES)
    return (f"recheck: {again['loop']['stopped']} (exit {again['exit_code']}), "
            f"{again['loop']['write_backs']} write-back(s), offsets changed by "
            f"{1000 * changed:.1f} µm, {again['timing']['mountings']} mountings, "
            f"{len(again['iterations'][0].get('passes') or ['m'])} pass(es)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--noise", type=float, default=0.001, help="gauge noise σ, mm")
    parser.add_argument("--in-mounting", type=int, default=None,
                        help="[procedure] max_cycles_in_mounting (default: the config's)")
    parser.add_argument("--drive-profile", default=None,
                        help="the virtual drive's own motion profile (e.g. cosine)")
    parser.add_argument("--mount-s", type=float, default=60.0,
                        help="the operator's time per mounting, s")
    parser.add_argument("--second-plane", action="store_true",
                        help="every setup again at 0.75 of its leg ([[setups]] at)")
    parser.add_argument("--tilt", default=None, help="the axes' tilts X,Y,Z, mrad")
    parser.add_argument("--gap", default=None, help="the axes' gaps XY,XZ,YZ, mm")
    parser.add_argument("--stated", type=float, default=None,
                        help="[uncertainty] leg_straightness_mm (default: the assumed)")
    parser.add_argument("--recheck", action="store_true",
                        help="then run the same machine again from the offsets it was left "
                             "with (run --offsets-from): it should write nothing")
    args = parser.parse_args()
    for name, runs in BEFORE.items():
        print(f"before, {name}: " + ", ".join(f"{m} mountings for {w} write-back(s) "
                                              f"({m * args.mount_s / 60:.0f} min at the "
                                              "machine)" for m, w in runs))
    print(f"noise {1000 * args.noise:g} µm, default procedure, stands by eye, "
          f"max_cycles_in_mounting {args.in_mounting or 'default'}, "
          f"{args.mount_s:g} s per mounting, drive profile {args.drive_profile or 'default'}"
          f"{', a second plane at 0.75' if args.second_plane else ''}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="orthocal-mount-") as tmp:
        for k in range(args.runs):
            first = one_run(args.seed + k, args, Path(tmp))
            r = judge(first, args.mount_s, 6 if args.second_plane else 3)
            rows.append(r)
            print(f"  seed {args.seed + k}: {r['stopped']}, {r['write_backs']} write-back(s), "
                  f"{r['mountings']} mountings (bound {r['bound']}), offsets leave "
                  f"≤ {r['left_um']:.1f} µm, machine {r['wall_s']:.0f} s, whole "
                  f"calibration {r['whole_s'] / 60:.1f} min")
            if args.recheck:
                print("    " + recheck(args, args.seed + k, Path(tmp), first))
    mounts = [r["mountings"] for r in rows]
    print(f"mountings: mean {np.mean(mounts):.1f}, max {max(mounts)}; within the bound in "
          f"{sum(r['mountings'] <= r['bound'] for r in rows)} of {len(rows)}; converged in "
          f"{sum(r['stopped'] == 'converged' for r in rows)} of {len(rows)}; whole "
          f"calibration mean {np.mean([r['whole_s'] for r in rows]) / 60:.1f} min")


if __name__ == "__main__":
    main()
