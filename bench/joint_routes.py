"""What each route into the machine does for the tool on a machine with screws, judged
by the hidden machine (docs/design.md, "Joint tables in the controller").

Whole simulated calibrations (``orthocal run --simulate`` in this process, the default
procedure, stands placed by eye, 1 µm of gauge noise, ``[uncertainty]
leg_straightness_mm = 0.002``) of the held-out machine (gaps (0.15, −0.10, 0.12) mm,
tilts (0.2, 0.1, −0.15) mrad, Δρ (0.6, −0.4, 0.9) mm) whose screws' leads are off
(+100, −80, +60) µm/m (``--joint-lead``), with a laser test of each joint given
(``[joints] tests``: 10 mm targets from 170 to 380 mm, read with a normal error of
0.25 µm, u_um = 0.5). For every run, against the hidden machine in the joint frame of
the offsets the run left, its joints erring by its screws (not by the tables), µm,
RMS / max over the run's own grid and frame:

* offsets only: the run's ``accuracy.after`` against the true field;
* the kinematics alone (orthoglidekins, no table): true;
* the kinematics and the joint tables (the LinuxCNC export): the run's
  ``accuracy.compensated`` (the geometry's share, as the run states it), the joints'
  share the tables leave ((J7), orthocal.joint_compensation.joint_residual: the 95 %
  bound's RMS), and the true field; beside it the same route with the geometry known
  exactly (θ_c = the truth): the tables' own share;
* a compensated program (``orthocal compensate``, the real command line, of
  bench/tool_with_geometry.py's program of lines, arcs in three planes, a helix and a
  G91 section) through a nominal controller: the true path, with the run's tables and
  with them taken out (the geometry alone).

``--know`` says how the run knows its joints (docs/design.md, "Joints"):

* ``test`` (default): the laser tests above;
* ``assumed``: no test, ``[uncertainty] joint_positioning_um_per_m = 120`` stated; then
  also whether the 95 % intervals of the tool after (RMS and max) and with the geometry
  in the controller (the kinematics alone: nothing compensates the joints) hold the
  truth, and the first screen's line on the joints;
* ``station``: the station's own test (``run --simulate --joint-test``, its gauge blocks);
  then also the leads it found.

    python bench/joint_routes.py              # 2 seeds
    python bench/joint_routes.py --runs 3 --seed 5
    python bench/joint_routes.py --know assumed --runs 5
    python bench/joint_routes.py --know station
    python bench/joint_routes.py --square       # exact joints: stated exact or assumed

``--square``: a square machine whose joints are exact (Δρ as above, no gap, tilt nor
lead), calibrated with its joints stated exact (``joint_positioning_um_per_m = 0``, as
before the joints were modelled) and with nothing stated (the assumed 170 µm/m): the
offsets written, the tool after (RMS and max, with their 95 % intervals) and how far the
two lie apart.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

# Runnable from a plain checkout, without the editable install.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.runs import run_json
from bench.tool_with_geometry import (
    PROGRAM,
    compensate_program,
    compensated_chords,
    geometry_of,
    path_error,
    pieces,
    truth_now,
)
from orthocal import AXES, JointErrors
from orthocal.accuracy import error_field, field_stats, fit_frame
from orthocal.compensation import landed
from orthocal.joint_compensation import joint_residual, table_compensated_error
from orthocal.joint_error import lead_table
from orthocal.kinematics import inverse
from station.commands.options import RunOptions, SimOptions
from station.record.controller_tables import controller_tables
from station.record.identified import identified_machine
from station.report import as_result

NOISE_MM = 0.001
STRAIGHTNESS_MM = 0.002
DRHO = (0.6, -0.4, 0.9)
TILT = (0.2, 0.1, -0.15)
GAP = (0.15, -0.10, 0.12)
LEAD = (100.0, -80.0, 60.0)
L = 310.25
TARGETS = np.arange(170.0, 381.0, 10.0)
LASER_U_UM = 0.5


def laser_tests(folder: Path, seed: int) -> dict[str, str]:
    """Each joint's ISO 230-2 test as a laser gives it: the screw's deviation, read with a
    normal error of U/2, and U."""
    rng = np.random.default_rng(seed)
    tests = {}
    for axis, k in zip(AXES, LEAD, strict=True):
        rows = ["target_mm,forward_um,reverse_um,u_um"]
        for t in TARGETS:
            dev = k * 1e-3 * (t - L)
            f, r = dev + rng.normal(0.0, LASER_U_UM / 2, 2)
            rows.append(f"{t:.3f},{f:.4f},{r:.4f},{LASER_U_UM:g}")
        path = folder / f"{axis}.csv"
        path.write_text("\n".join(rows) + "\n", encoding="utf-8")
        tests[axis] = str(path)
    return tests


#: ``--know assumed``: the bound stated ([uncertainty] joint_positioning_um_per_m).
ASSUMED_UM_PER_M = 120.0


def one_run(seed: int, out: Path, know: str = "test") -> dict[str, Any]:
    """``orthocal run --simulate`` of the held-out machine with screws, its joints known
    as ``know`` says."""
    out.mkdir(parents=True, exist_ok=True)
    uncertainty: dict[str, Any] = {"leg_straightness_mm": STRAIGHTNESS_MM}
    joints: dict[str, Any] = {}
    if know == "test":
        joints = {"tests": laser_tests(out, seed)}
    elif know == "assumed":
        uncertainty["joint_positioning_um_per_m"] = ASSUMED_UM_PER_M

    def hook(station: Any) -> None:  # what a user writes in the config
        config = station.config
        station.config = lambda: {**config(), "uncertainty": uncertainty,
                                  **({"joints": {**config().get("joints", {}), **joints}}
                                     if joints else {})}

    options = RunOptions(sim=SimOptions(seed=seed, true_drho=DRHO, true_tilt=TILT,
                                        true_gap=GAP, noise=NOISE_MM,
                                        joint_lead=",".join(f"{v:g}" for v in LEAD),
                                        joint_test=know == "station" or None,
                                        station_hook=hook),
                         out=out / "runs", yes=True, json=True)
    code, result = run_json(options)
    if code not in (0, 3):  # 3: completed, the loop not converged: still judged
        raise SystemExit(f"seed {seed}: the run failed (exit {code}): {result.get('message')}")
    result["exit_code"] = code
    return result


def square_run(seed: int, out: Path, stated: bool) -> dict[str, Any]:
    """A square machine with exact joints, its joints stated exact or left assumed."""
    def hook(station: Any) -> None:
        config = station.config

        def described() -> dict[str, Any]:
            said = dict(config())
            uncertainty = {**said["uncertainty"], "leg_straightness_mm": STRAIGHTNESS_MM}
            if not stated:
                uncertainty.pop("joint_positioning_um_per_m", None)
            return {**said, "uncertainty": uncertainty}

        station.config = described

    options = RunOptions(sim=SimOptions(seed=seed, true_drho=DRHO, noise=NOISE_MM,
                                        station_hook=hook),
                         out=out / ("stated" if stated else "assumed"), yes=True, json=True)
    code, result = run_json(options)
    if code not in (0, 3):
        raise SystemExit(f"seed {seed}: the run failed (exit {code}): {result.get('message')}")
    return result


def square(args: argparse.Namespace) -> None:
    """``--square``: the square machine with exact joints, stated exact against assumed."""
    print(f"square machine, exact joints, Δρ {DRHO} mm, noise {1000 * NOISE_MM:g} µm; "
          "µm: offsets written (x, y, z), tool after RMS (95 %), max (95 %)")
    with tempfile.TemporaryDirectory(prefix="orthocal-joint-square-") as tmp:
        for k in range(args.runs):
            seed = args.seed + k
            rows = {}
            for stated in (True, False):
                r = square_run(seed, Path(tmp) / f"seed-{seed}", stated)
                after = r["accuracy"]["after"]
                rows[stated] = (np.array([r["offsets_final"][a] for a in AXES]),
                                after["rms_mm"], after["rms_interval_95_mm"],
                                after["max_mm"], after["max_interval_95_mm"])
            for stated, (o, rms, rms_iv, mx, mx_iv) in rows.items():
                print(f"{seed} {'stated exact' if stated else 'assumed 170 '} | "
                      + " ".join(f"{1000 * v:+9.2f}" for v in o)
                      + f" | {1000 * rms:5.2f} ({1000 * rms_iv[0]:.2f}–{1000 * rms_iv[1]:.2f})"
                      f" | {1000 * mx:5.2f} ({1000 * mx_iv[0]:.2f}–{1000 * mx_iv[1]:.2f})")
            apart = 1000 * np.abs(rows[True][0] - rows[False][0]).max()
            print(f"{seed} apart: offsets {apart:.2f} µm, tool after RMS "
                  f"{1000 * abs(rows[True][1] - rows[False][1]):.2f} µm")


def true_screws(result: dict[str, Any]) -> JointErrors:
    """The simulator's screws in the joints commanded after the run: a lead k homed at
    Π0 before the run, the offsets the run wrote moving the carriage on it."""
    sim = result["simulation"]
    o = [result["offsets_final"][a] - result["offsets_before"][a] for a in AXES]
    return JointErrors(*(lead_table(sim["joint_lead_um_per_m"][a], (100.0, 450.0), L - o[i])
                         for i, a in enumerate(AXES)))


def grid_figures(result: dict[str, Any]) -> dict[str, Any]:
    acc = result["accuracy"]
    points = np.asarray(acc["field"]["points_mm"])
    frame = acc["frame"]
    g, truth, screws = geometry_of(result), truth_now(result), true_screws(result)
    found = identified_machine(result["run_dir"])
    told = found.theta_c()
    record = {k: v for k, v in result.items() if k != "exit_code"}
    tables = controller_tables(as_result(record)).errors()

    def stats(e: np.ndarray) -> tuple[float, float]:
        rms, mx = field_stats(fit_frame(points, e, frame))
        return 1000 * rms, 1000 * mx

    def landing(e: np.ndarray) -> tuple[float, float]:  # as the tool lands, no frame
        rms, mx = field_stats(e)
        return 1000 * rms, 1000 * mx

    only = error_field(points, g, truth, None, frame, joint_errors=screws)
    left = joint_residual(points, g, told, tables)
    c = acc["compensated"]
    kins_true = stats(table_compensated_error(points, g, truth, told, JointErrors(), screws,
                                              "forward"))
    return {
        "only_interval": (acc["after"]["rms_interval_95_mm"],
                          acc["after"]["max_interval_95_mm"]),
        "geometry_interval": (c["rms_interval_95_mm"], c["max_interval_95_mm"]),
        "route": c.get("route"),
        "only_pred": (1000 * acc["after"]["rms_mm"], 1000 * acc["after"]["max_mm"]),
        "only_true": (1000 * only.rms_mm, 1000 * only.max_mm),
        "kins_true": kins_true,
        "geometry_pred": (1000 * c["rms_mm"], 1000 * c["max_mm"]),
        "joints_pred": (1000 * left.bound_rms_mm, 1000 * left.bound_max_mm),
        "tables_true": stats(table_compensated_error(points, g, truth, told, tables, screws,
                                                     "forward")),
        "tables_landing": landing(table_compensated_error(points, g, truth, told, tables,
                                                          screws, "forward")),
        "tables_exact_geometry": stats(table_compensated_error(points, g, truth, truth,
                                                               tables, screws, "forward")),
    }


def path_figures(result: dict[str, Any], where: Path) -> dict[str, Any]:
    """The true path of the compensated program, with the tables and without."""
    g, truth, screws, paths = geometry_of(result), truth_now(result), \
        true_screws(result), pieces(PROGRAM)

    def tool_of(s: np.ndarray) -> np.ndarray:  # a nominal controller's counts, the screws
        counts = inverse(s, g)
        return landed(screws.joints(counts), g, truth)

    text, _ = compensate_program(result["run_dir"], where)
    bare = where / "geometry-alone"
    shutil.copytree(result["run_dir"], bare)
    doc = json.loads((bare / "result.json").read_text())
    doc["joints"] = {**doc["joints"], **{a: {**doc["joints"][a], "source": "assumed",
                                            "table": None, "bound_um_per_m": 170.0,
                                            "file": None} for a in AXES}}
    (bare / "result.json").write_text(json.dumps(doc))
    alone, _ = compensate_program(str(bare), where)
    return {"program": path_error(compensated_chords(text), tool_of, paths),
            "program_alone": path_error(compensated_chords(alone), tool_of, paths)}


def pair(v: tuple[float, float]) -> str:
    return f"{v[0]:6.2f} {v[1]:6.2f}"


def holds(interval: list[float], truth_um: float) -> str:
    lo, hi = (1000 * v for v in interval)
    return f"{lo:5.1f}–{hi:5.1f} {'yes' if lo <= truth_um <= hi else 'NO '}"


def joints_line(result: dict[str, Any]) -> str:
    """The first screen's line on what the tool's figures take the joints to be."""
    from station.report.first_screen import items

    record = {k: v for k, v in result.items() if k != "exit_code"}
    said = [i.text for i in items(as_result(record)) if i.label == "joints"]
    return said[0] if said else "(none)"


def print_knowledge(know: str, rows: list[tuple[int, str, dict[str, Any]]]) -> None:
    """What ``--know assumed`` and ``--know station`` add: the intervals against the
    truth, the first screen's line, the leads found."""
    if know == "assumed":
        print("\nThe 95 % intervals against the truth (µm; RMS, max):")
        print(f"{'seed':<6} | {'after RMS':^16} {'after max':^16} | "
              f"{'kinematics RMS':^16} {'kinematics max':^16}")
        for seed, _, r in rows:
            (ar, am), (cr, cm) = r["only_interval"], r["geometry_interval"]
            print(f"{seed:<6} | {holds(ar, r['only_true'][0])} {holds(am, r['only_true'][1])} "
                  f"| {holds(cr, r['kins_true'][0])} {holds(cm, r['kins_true'][1])}")
    if know == "station":
        print("\nThe leads the station's own test found (µm/m, 95 % interval):")
        for seed, _, r in rows:
            print(f"{seed:<6} | " + "; ".join(
                f"{a} {v:+.1f} [{lo:+.1f}, {hi:+.1f}] (true {t:+g})"
                for a, (v, (lo, hi)), t in zip(AXES, r["leads"], LEAD, strict=True)))
    for seed, _, r in rows[:1]:
        print(f"\nThe first screen (seed {seed}): {r['joints_line']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--know", choices=("test", "assumed", "station"), default="test",
                        help="how the run knows its joints")
    parser.add_argument("--time-scale", default="20",
                        help="the virtual station's clock against real time")
    parser.add_argument("--square", action="store_true",
                        help="a square machine with exact joints: stated exact or assumed")
    args = parser.parse_args()
    os.environ.setdefault("ORTHOCAL_SIM_TIME_SCALE", args.time_scale)
    if args.square:
        square(args)
        return
    t0 = time.monotonic()
    print(f"held-out machine with screws: gaps {GAP} mm, tilts {TILT} mrad, Δρ {DRHO} mm, "
          f"leads {LEAD} µm/m; noise {1000 * NOISE_MM:g} µm, legs stated straight to "
          f"{STRAIGHTNESS_MM} mm; the joints: " + {
              "test": f"laser tests, 10 mm targets, U = {LASER_U_UM} µm",
              "assumed": f"no test, stated within ±{ASSUMED_UM_PER_M:g} µm/m",
              "station": "the station's own test (gauge blocks)"}[args.know])
    rows = []
    with tempfile.TemporaryDirectory(prefix="orthocal-joint-routes-") as tmp:
        for k in range(args.runs):
            seed = args.seed + k
            where = Path(tmp) / f"seed-{seed}"
            result = one_run(seed, where, args.know)
            leads = [(result["joints"][a]["lead_um_per_m"],
                      result["joints"][a]["lead_interval_95_um_per_m"]) for a in AXES]
            rows.append((seed, result["loop"]["stopped"], {
                **grid_figures(result), **path_figures(result, where), "leads": leads,
                "joints_line": joints_line(result)}))
            print(f"  seed {seed} done ({time.monotonic() - t0:.0f} s)", file=sys.stderr)
    print("\nOver the run's grid (µm, RMS max, in the run's frame unless 'as it lands'; "
          "true: the hidden machine with its screws)")
    print(f"{'seed, loop':<20} | {'offsets only':^13} {'true':^13} | {'kins alone':^13} | "
          f"{'geometry pred':^13} {'joints (J7)':^13} {'kins+tables':^13} "
          f"{'as it lands':^13} {'exact geom.':^13}")
    for seed, stopped, r in rows:
        print(f"{f'{seed}, {stopped}':<20} | {pair(r['only_pred'])} {pair(r['only_true'])} | "
              f"{pair(r['kins_true'])} | {pair(r['geometry_pred'])} {pair(r['joints_pred'])} "
              f"{pair(r['tables_true'])} {pair(r['tables_landing'])} "
              f"{pair(r['tables_exact_geometry'])}")
    print("\nOn the program's path (µm, RMS by length, max; as the tool lands / in the "
          "translation frame)")
    print(f"{'seed':<6} | {'compensated, tables':^27} | {'geometry alone':^27}")
    for seed, _, r in rows:
        cells = [f"{e.rms_um:6.2f} {e.max_um:6.2f} / {e.frame_rms_um:6.2f} "
                 f"{e.frame_max_um:6.2f}" for e in (r["program"], r["program_alone"])]
        print(f"{seed:<6} | {cells[0]} | {cells[1]}")
    print_knowledge(args.know, rows)
    print(f"\n{time.monotonic() - t0:.0f} s")


if __name__ == "__main__":
    main()
