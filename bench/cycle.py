"""Whole-calibration cycle time against the physical floor.

A virtual station with realistic timing runs in this process (100 mm/s,
1000 mm/s², six Mitutoyo gauges at 9600 baud with line time emulated, all
mounted, as ``orthocal sim`` stands them); the station runs as the operator
would start it, ``orthocal run --config FILE --yes --json``, in a subprocess
timed from spawn to exit, so process start, imports and connecting count.

The floor is what the physics of the run that actually happened costs:

* each move between consecutive stops, timed with the simulator's own motion
  profile (``drivers.profiles.move_time``, its trapezoid's duration: coordinated or
  independent, a move lasts as long as a rest-to-rest trapezoid over its
  longest axis), in the machine's own scale, so the move that a write-back's
  new offsets cause is counted; waypoints are not part of the floor, they are
  what independent axes cost; nor are the approach's overruns and the reversal
  stop's trip beyond Π0 and back (``--approach as-planned`` runs without);
* the settle time at every stop;
* at every stop, the serial line time of its readings: readings × (request +
  reply characters) × bits per character / baud; the gauges of a stop are read
  in parallel, so a stop costs one gauge's line time.

The stops come from the run's journal, the postures from its plan.json. The
moves the simulator actually started are timed too ("machine moves"): if they
exceed the floor's moves, the station moved more than its stops needed.

On a drive the station is not told about (``--drive-profile``: its own profile
shape, the plan for any axis timing) the floor that counts is the drive's own:
every move the controller actually made, waypoints included, at the duration its
own profile gave it, plus the same settle and line time ("drive floor"); wall over
it is the time the station spends between and around the moves.

    python bench/cycle.py [--cycles 3] [--target-se MM] [--noise 0.005] [--seed 1]
    python bench/cycle.py --compare --target-se 0.002 --cycles 6   # adaptive vs fixed
    python bench/cycle.py --profile /tmp/run.prof                  # cProfile the station
    python bench/cycle.py --strokes 60,30,-50,-100                 # four stops per leg
    python bench/cycle.py --drive-profile cosine --readings 3 --cycles 2 --repeat 2
                                          # a drive of its own timing: wall over the
                                          # drive floor (a held-out controller's)
    python bench/cycle.py --path-cost     # the plan for any axis timing against a
                                          # coordinated controller, on drives of every
                                          # kind, and what the plunger guard costs

Target: wall / floor ≤ 1.05.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.floor import (
    Timing,
    first_cycle_extra_s,
    idle_between_moves,
    line_time_per_reading,
    own_setup_events,
    physical_floor,
)
from drivers.sim.drive_motion import DriveMotion
from drivers.sim.specs import DriveSpec, GaugeSpec, MachineTruth
from orthocal import AXES
from station.commands.simulate import launch as simulation
from station.commands.simulate.station_setups import SimulatedStation, gauges_for
from station.config.toml import toml_text
from station.record.journal_file import read_journal


@dataclass
class Outcome:
    wall_s: float
    floor_s: float
    floor_moves_s: float
    floor_settle_s: float
    floor_line_s: float
    machine_moves_s: float
    machine_moves: int
    stops: int
    result: dict[str, Any]
    true_drho: list[float]
    # Seconds from spawn to the journal's header, to its first and last reading, to exit.
    timeline: dict[str, float]
    clamped: int = 0
    # Moves that drove a plunger of the setup in progress past an end of its stroke,
    # read or not (simulator); and those of gauges on the other legs, which stand
    # mounted only because all six are (as orthocal sim stands them: an operator
    # removes them, the station's prompt says so).
    out_of_stroke: int = 0
    foreign_out_of_stroke: int = 0
    # Mean extra seconds per stop of a mounting's first cycle (move + settle + read)
    # against the same stop of later cycles, and how many stops it averages: the
    # plunger guard's cost, paired within one run (same load, same moves).
    first_cycle_extra: tuple[float, int] = (0.0, 0)
    # The drive idle between the end of one move and the start of the next (s):
    # after a move to a stop (settle and the readings included) and after a waypoint.
    idle_after_stop: list[float] | None = None
    idle_after_waypoint: list[float] | None = None

    @property
    def ratio(self) -> float:
        return self.wall_s / self.floor_s

    @property
    def drive_floor_s(self) -> float:
        """Every move the drive made at its own timing, plus settle and line time."""
        return self.machine_moves_s + self.floor_settle_s + self.floor_line_s

    @property
    def drive_ratio(self) -> float:
        return self.wall_s / self.drive_floor_s

    @property
    def errors_um(self) -> list[float]:
        ident = self.result["identified"]
        return [1000 * (ident[f"drho_{a}"] - t) for a, t in zip(AXES, self.true_drho, strict=True)]

    @property
    def std_errors_um(self) -> list[float]:
        return [1000 * self.result["std_errors"][f"drho_{a}"] for a in AXES]

    def cycles_used(self, phase: str = "m") -> list[int]:
        block = self.result if phase == "m" else (self.result.get("verification") or {})
        return [s["cycles_used"] for s in block.get("setups", [])]


def station_config(station: SimulatedStation, timing: Timing, cycles: int,
                   target_se: float | None, strokes: list[float] | None = None
                   ) -> dict[str, Any]:
    config = simulation.station_config(station, {})
    config["controller"].update(speed_mm_s=timing.speed_mm_s, accel_mm_s2=timing.accel_mm_s2)
    config["procedure"].update(cycles=cycles, readings=timing.readings,
                               settle_s=timing.settle_s, plunger_guard=timing.guard)
    if timing.approach is not None:
        config["procedure"]["approach"] = timing.approach
    if strokes:
        config["procedure"]["strokes"] = strokes
    if target_se is not None:
        config["procedure"]["target_std_error_mm"] = target_se
    return config


def station_command(profile: str | None) -> list[str]:
    if profile:
        return [sys.executable, "-m", "cProfile", "-o", profile, "-m", "station"]
    script = Path(sys.executable).with_name("orthocal")
    return [str(script)] if script.exists() else [sys.executable, "-m", "station"]


def run_once(*, seed: int, noise_mm: float, cycles: int, target_se: float | None,
             timing: Timing, out: Path, profile: str | None = None,
             true_drho: list[float] | None = None, quiet: bool = True,
             mount_error_mm: float = 0.0,
             strokes: list[float] | None = None) -> Outcome:
    rng = np.random.default_rng(seed)
    drho = true_drho if true_drho is not None else \
        [round(float(v), 4) for v in rng.uniform(-2.0, 2.0, 3)]
    drive = DriveSpec(motion=timing.motion, speed_mm_s=timing.speed_mm_s,
                      accel_mm_s2=timing.accel_mm_s2, actual_accel_mm_s2=timing.drive_accel)
    gauges = gauges_for(6, GaugeSpec(protocol=timing.protocol, baud=timing.baud,
                                     line_time=True, noise_mm=noise_mm,
                                     mount_error_mm=mount_error_mm), mounted=True)
    with SimulatedStation(MachineTruth(drho=drho), drive, gauges, seed=seed) as station:
        machine = station.machine
        started: list[float] = []
        began: list[float] = []
        targets_of: list[np.ndarray] = []
        move_to = machine.move_to

        def recording_move_to(targets: Any) -> float:
            began.append(machine.now())
            duration = move_to(targets)
            started.append(duration)
            targets_of.append(np.asarray(targets, dtype=float))
            return duration

        machine.move_to = recording_move_to  # type: ignore[method-assign]
        start_m = machine.actual() + machine.offsets
        cfg_path = out / f"station-{seed}.toml"
        cfg_path.write_text(toml_text(station_config(station, timing, cycles, target_se,
                                                     strokes), "bench/cycle.py"))
        cmd = [*station_command(profile), "run", "--config", str(cfg_path), "--yes", "--json",
               "--out", str(out / "runs")]
        spawned = time.time()  # the journal stamps records with time.time()
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        # Readings a gauge gave at an end of its stroke (stops and the guard's polls),
        # and every move that drove a plunger past an end, read or not.
        clamped = sum(sim.clamped for sim in station.indicators.values())
        out_of_stroke, foreign = own_setup_events(station.out_of_stroke, targets_of)
    # 3: completed, the closed loop did not converge (it says why): still a whole
    # calibration's time, which is what this measures
    if proc.returncode not in (0, 3):
        sys.stderr.write(proc.stderr[-4000:])
        raise SystemExit(f"station run failed (exit {proc.returncode})")
    if not quiet:
        sys.stderr.write(proc.stderr)
    result = json.loads(proc.stdout)
    run_dir = Path(result["run_dir"])
    moves, settle, line, stops = physical_floor(run_dir, start_m, timing)
    records = read_journal(run_dir / "journal.jsonl")
    readings = [r["t"] for r in records if r["type"] == "reading"]
    timeline = {"header": records[0]["t"] - spawned, "first reading": readings[0] - spawned,
                "last reading": readings[-1] - spawned, "exit": wall}
    first_cycle_extra = first_cycle_extra_s(records)
    postures = [np.asarray(v, dtype=float) for sp in
                json.loads((run_dir / "plan.json").read_text())["setups"]
                for v in sp["postures"].values()]
    after_stop, after_waypoint = idle_between_moves(began, started, targets_of, postures)
    return Outcome(wall, moves + settle + line, moves, settle, line, float(sum(started)),
                   sum(1 for d in started if d > 0), stops, result, drho, timeline, clamped,
                   out_of_stroke, foreign, first_cycle_extra, after_stop, after_waypoint)


def report(label: str, o: Outcome) -> None:
    t = o.result.get("timing", {})
    print(f"{label}: wall {o.wall_s:.2f} s, floor {o.floor_s:.2f} s "
          f"(moves {o.floor_moves_s:.2f} + settle {o.floor_settle_s:.2f} + "
          f"line {o.floor_line_s:.2f}; {o.stops} stops), ratio {o.ratio:.3f}")
    print(f"    drive floor (every move the drive made at its own timing + settle + "
          f"line) {o.drive_floor_s:.2f} s: ratio {o.drive_ratio:.3f}")
    print(f"    machine moves: {o.machine_moves} started, {o.machine_moves_s:.2f} s "
          f"(floor's moves {o.floor_moves_s:.2f} s); station's own wall_s "
          f"{t.get('wall_s')} s; readings at a stroke end {o.clamped}, moves past a stroke "
          f"end {o.out_of_stroke} (and {o.foreign_out_of_stroke} of the other legs' gauges, "
          "mounted only because all six are)")
    for what, idle in (("stop", o.idle_after_stop), ("waypoint", o.idle_after_waypoint)):
        if idle:
            longest = ", ".join(f"{1000 * v:.0f}" for v in sorted(idle)[::-1][:6])
            print(f"    drive idle after a {what}: median {1000 * np.median(idle):.0f} ms, "
                  f"mean {1000 * np.mean(idle):.0f} ms, total {sum(idle):.2f} s "
                  f"({len(idle)} moves; longest {longest} ms)")
    extra, n = o.first_cycle_extra
    print(f"    first cycle after mounting: {1000 * extra:+.1f} ms per stop against later "
          f"cycles ({n} stops)")
    print("    timeline from spawn: " + ", ".join(f"{k} {v:.2f} s" for k, v in o.timeline.items()))
    print(f"    cycles used: measurement {o.cycles_used('m')}, verification "
          f"{o.cycles_used('v')}; Δρ error "
          + ", ".join(f"{e:+.2f}" for e in o.errors_um) + " µm, reported SE "
          + ", ".join(f"{s:.2f}" for s in o.std_errors_um) + " µm")
    its = o.result.get("iterations") or []
    if its:
        print(f"    closed loop: {sum(1 for i in its if i.get('offsets_written'))} write-back(s),"
              f" phases {' '.join(i['phase'] for i in its)}, converged "
              f"{o.result.get('converged')}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", type=int, default=3, help="cycles per setup (the cap)")
    parser.add_argument("--target-se", type=float, default=None, metavar="MM",
                        help="procedure.target_std_error_mm (adaptive cycles)")
    parser.add_argument("--noise", type=float, default=0.005, metavar="MM")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--repeat", type=int, default=1, help="runs (seeds seed, seed+1, ...)")
    parser.add_argument("--settle", type=float, default=0.05)
    parser.add_argument("--readings", type=int, default=5)
    parser.add_argument("--speed", type=float, default=100.0)
    parser.add_argument("--accel", type=float, default=1000.0)
    parser.add_argument("--compare", action="store_true",
                        help="adaptive (--target-se, up to --cycles) against fixed cycles "
                             "(--fixed-cycles) on the same machines")
    parser.add_argument("--fixed-cycles", type=int, default=3)
    parser.add_argument("--profile", metavar="FILE", help="run the station under cProfile")
    parser.add_argument("--mount-error", type=float, default=0.0, metavar="MM",
                        help="stands off the legs' middles by up to this: the closed loop "
                             "then takes more than one write-back")
    parser.add_argument("--verbose", action="store_true", help="show the station's stderr")
    parser.add_argument("--strokes", type=lambda t: [float(v) for v in t.split(",")],
                        default=None, metavar="A,B,..",
                        help="[procedure] strokes (stops per leg, mm)")
    parser.add_argument("--motion", choices=["coordinated", "independent"],
                        default="coordinated", help="how the virtual controller moves")
    parser.add_argument("--drive-profile", choices=["trapezoid", "scurve", "cosine"],
                        default=None,
                        help="the drive's own profile shape, axes independent (the station "
                             "is told nothing: its plan holds for any axis timing)")
    parser.add_argument("--approach", choices=["below", "above", "as-planned"], default=None,
                        help="[procedure] approach (default: the station's, below)")
    parser.add_argument("--no-guard", action="store_true",
                        help="procedure.plunger_guard = false")
    parser.add_argument("--path-cost", action="store_true",
                        help="same machines on drives of every kind (bench.cycle.PATH_CASES)"
                             ": the plan for any axis timing against a coordinated "
                             "controller, and coordinated without the plunger guard")
    args = parser.parse_args()
    motion: str | DriveMotion = args.motion if args.drive_profile is None else \
        DriveMotion(shape=args.drive_profile)
    timing = Timing(speed_mm_s=args.speed, accel_mm_s2=args.accel, settle_s=args.settle,
                    readings=args.readings, motion=motion, guard=not args.no_guard,
                    approach=args.approach)
    print(f"timing: {timing.speed_mm_s:g} mm/s, {timing.accel_mm_s2:g} mm/s², "
          f"{timing.protocol} at {timing.baud} baud "
          f"({1000 * line_time_per_reading(timing.protocol, timing.baud):.2f} ms per reading), "
          f"settle {timing.settle_s:g} s, {timing.readings} readings per stop; "
          f"noise {1000 * args.noise:g} µm")
    with tempfile.TemporaryDirectory(prefix="orthocal-cycle-") as tmp:
        out = Path(tmp)
        if args.path_cost:
            path_cost(args, timing, out)
            return
        if not args.compare:
            ratios, drive_ratios = [], []
            for k in range(args.repeat):
                o = run_once(seed=args.seed + k, noise_mm=args.noise, cycles=args.cycles,
                             target_se=args.target_se, timing=timing, out=out,
                             profile=args.profile, quiet=not args.verbose,
                             mount_error_mm=args.mount_error, strokes=args.strokes)
                report(f"seed {args.seed + k}", o)
                ratios.append(o.ratio)
                drive_ratios.append(o.drive_ratio)
            if len(ratios) > 1:
                print(f"ratio wall/floor: median {np.median(ratios):.3f}, "
                      f"max {max(ratios):.3f} over {len(ratios)} runs")
                print(f"ratio wall/drive floor: median {np.median(drive_ratios):.3f}, "
                      f"max {max(drive_ratios):.3f} over {len(drive_ratios)} runs")
            return
        if args.target_se is None:
            parser.error("--compare needs --target-se")
        fixed, adaptive = [], []
        for k in range(args.repeat):
            seed = args.seed + k
            f = run_once(seed=seed, noise_mm=args.noise, cycles=args.fixed_cycles,
                         target_se=None, timing=timing, out=out)
            report(f"seed {seed} fixed {args.fixed_cycles}", f)
            a = run_once(seed=seed, noise_mm=args.noise, cycles=args.cycles,
                         target_se=args.target_se, timing=timing, out=out)
            report(f"seed {seed} adaptive ≤{args.cycles}", a)
            fixed.append(f)
            adaptive.append(a)

        def rms(xs: list[Outcome], attr: str) -> float:
            return float(np.sqrt(np.mean([np.square(getattr(o, attr)) for o in xs])))

        wf = float(np.mean([o.wall_s for o in fixed]))
        wa = float(np.mean([o.wall_s for o in adaptive]))
        cyc = [c for o in adaptive for c in o.cycles_used("m")]
        print(f"fixed {args.fixed_cycles} cycles: mean wall {wf:.2f} s, Δρ error RMS "
              f"{rms(fixed, 'errors_um'):.2f} µm, reported SE RMS "
              f"{rms(fixed, 'std_errors_um'):.2f} µm")
        print(f"adaptive (target {1000 * args.target_se:g} µm, ≤ {args.cycles}): mean wall "
              f"{wa:.2f} s, cycles per setup {np.mean(cyc):.2f} (min {min(cyc)}, max {max(cyc)}),"
              f" Δρ error RMS {rms(adaptive, 'errors_um'):.2f} µm, reported SE RMS "
              f"{rms(adaptive, 'std_errors_um'):.2f} µm")
        print(f"time saved: {wf - wa:.2f} s per calibration ({100 * (wf - wa) / wf:.0f} %)")


# --path-cost: the same calibrations on drives that disagree with the station. The
# config tells the station "coordinated" only for the coordinated drive; for every
# other one it says nothing, so the plan holds for any axis timing (the default).
PATH_CASES: dict[str, dict[str, Any]] = {
    "coordinated (the config says so)": {"motion": "coordinated"},
    "any timing: trapezoid drive": {"motion": "independent"},
    "any timing: S-curve, axes 5 ms apart, 60 % of the acceleration": {
        "motion": DriveMotion(shape="scurve", start_delay_s=(0.0, 0.005, 0.010)),
        "drive_accel": 600.0},
    "any timing: one axis after another (z, y, x)": {"motion": DriveMotion(sequence="zyx")},
    "coordinated, no guard": {"motion": "coordinated", "guard": False},
}


def path_cost(args: argparse.Namespace, base: Timing, out: Path) -> None:
    """Wall time of the same calibrations on each drive of PATH_CASES: what the plan
    for any axis timing costs against a coordinated controller (waypoints, and on
    slower drives the drive itself), that no plunger ever left its stroke, and what
    the plunger guard costs (coordinated with and without it)."""
    cases = {label: replace(base, **kw) for label, kw in PATH_CASES.items()}
    walls: dict[str, list[float]] = {k: [] for k in cases}
    moves: dict[str, list[int]] = {k: [] for k in cases}
    motion_s: dict[str, list[float]] = {k: [] for k in cases}
    extra: dict[str, list[float]] = {k: [] for k in cases}
    outside: dict[str, int] = dict.fromkeys(cases, 0)
    for k in range(args.repeat):
        seed = args.seed + k
        for label, timing in cases.items():
            o = run_once(seed=seed, noise_mm=args.noise, cycles=args.cycles, target_se=None,
                         timing=timing, out=out)
            report(f"seed {seed} {label}", o)
            walls[label].append(o.wall_s)
            moves[label].append(o.machine_moves)
            motion_s[label].append(o.machine_moves_s)
            extra[label].append(o.first_cycle_extra[0])
            outside[label] += o.out_of_stroke
    mean = {k: float(np.mean(v)) for k, v in walls.items()}
    reference = "coordinated (the config says so)"
    for label in cases:
        print(f"{label}: mean wall {mean[label]:.2f} s "
              f"({100 * (mean[label] / mean[reference] - 1):+.1f} % against coordinated), "
              f"machine moves {np.mean(moves[label]):.0f} ({np.mean(motion_s[label]):.2f} s "
              f"of motion), moves past a stroke end {outside[label]}, first-cycle stops "
              f"{1000 * np.mean(extra[label]):+.1f} ms each")
    g = mean[reference] - mean["coordinated, no guard"]
    e = float(np.mean(extra[reference]) - np.mean(extra["coordinated, no guard"]))
    print(f"plunger guard: {g:+.2f} s wall per calibration; paired within runs, a "
          f"watched stop takes {1000 * e:+.1f} ms more ({18 * e:+.2f} s over the 18 "
          f"stops of the six first cycles)")


if __name__ == "__main__":
    main()
