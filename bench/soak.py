"""Soak: many simulated calibrations back to back through flaky devices.

Each run is a whole ``orthocal run --simulate`` (measure, identify, write back,
verify) on a fresh virtual station with random hidden offsets, while every
device misbehaves at random: the controller drops, garbles and answers "busy"
to a fraction of its requests, the gauges drop and garble a fraction of their
replies. On top, the controller loses power once per run at a random
move (``--cut-s`` unreachable, then back unhomed with its count lost: the run
ends saying so and the soak answers ``orthocal resume --yes`` as an operator
would, which homes and checks Π0), and one gauge's USB adapter is pulled at a
random move and plugged back ``--unplug-s`` later behind its stable link.
It prints, over all runs:

* runs completed (status ok),
* retries (journaled by the drivers) against faults injected (the simulators'
  own count),
* wrong answers: a run that did not complete, or an identified Δρ more than
  ``--max-se`` standard errors from the hidden truth (target 0),
* lost readings: readings the sequencer took but the journal does not hold,
  plus stops a journaled cycle used without their full set of readings
  (target 0),
* internal errors: anything but a named fault or bad input escaping a command
  (target 0),
* power cuts and pulled adapters injected, resumes, setups redone after homing.

    python bench/soak.py [--runs 20] [--drop 0.05] [--garble 0.05] [--busy 0.05]
                         [--seed 1] [--cycles 3] [--readings 5] [--timeout 0.1]
                         [--cut-s 3] [--unplug-s 2] [--no-cuts] [--no-unplugs]

Faults draw from seeded RNGs, so a soak is reproducible up to thread timing.
Device timeouts are short (a lost reply costs one timeout) to keep it fast.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import random
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.device_errors import DeviceError
from station.commands import run as cmd_run
from station.commands.options import ResumeOptions, RunOptions, SimOptions
from station.errors import BadInput, RunFailed
from station.record.journal_file import read_journal

AXES = "xyz"


@dataclass
class Tally:
    runs: int = 0
    completed: int = 0
    wrong: int = 0
    retries: int = 0
    injected: int = 0
    readings: int = 0
    lost: int = 0
    internal: int = 0
    cuts: int = 0
    unplugs: int = 0
    reopened: int = 0
    resumes: int = 0
    redone: int = 0
    worst_se: float = 0.0
    failures: list[str] = field(default_factory=list)


def _at_move(station: Any, move: int, action: Any) -> None:
    """Run ``action`` when the virtual machine starts its ``move``-th move."""
    machine = station.machine
    start = machine.move_to
    count = [0]

    def move_to(targets: Any) -> float:
        count[0] += 1
        if count[0] == move:
            action()
        return start(targets)

    machine.move_to = move_to


def _faulty(args: argparse.Namespace, injected: list[Any], seed: int,
            first: bool = True):
    """The hook given the virtual station before the run derives its config. The
    power cut and the pulled adapter are for the first station (the run), not the
    one a resume restarts."""
    rng = random.Random(seed)
    # ~54 moves per run: the cut somewhere in it, the adapter pulled before it (the
    # run's station is gone after the cut)
    cut_at = rng.randint(12, 45)
    pull_at = rng.randint(3, cut_at - 3) if not args.no_cuts else rng.randint(3, 45)

    def hook(station: Any) -> None:
        if first and not args.no_cuts:
            f = station.controller.faults
            f.power_cut_s = args.cut_s
            f.power_cut_after_moves = cut_at
        if first and not args.no_unplugs:
            gauge = station.indicators[rng.choice(sorted(station.indicators))]

            def pull() -> None:
                injected.append("unplug")
                gauge.unplug_for(args.unplug_s)

            _at_move(station, pull_at, pull)
        c = station.controller.faults
        c.drop_rate, c.garble_rate, c.busy_rate = args.drop, args.garble, args.busy
        for sim in station.indicators.values():
            sim.faults.drop_rate, sim.faults.garble_rate = args.drop, args.garble
            # The gauges count requests and replies, not faults: count them here.
            sim.on_fault = injected.append
        injected.append(station.controller.stats)
        describe = station.config

        def config() -> dict[str, Any]:
            c = describe()
            c["controller"]["timeout_s"] = args.timeout
            for ind in c["indicators"]:
                ind["timeout_s"] = args.timeout
            return c

        station.config = config

    return hook


def _lost(records: list[dict[str, Any]], readings: int, taken: int) -> int:
    names = {(r["phase"], r["setup"]): list(r["indicators"]) for r in records
             if r["type"] == "setup"}
    have = {(r["stop"], r["indicator"]) for r in records
            if r["type"] == "reading" and len(r["values"]) == readings}
    missing = 0
    for r in records:
        if r["type"] == "cycle":
            p, s, c = r["phase"], r["setup"], r["cycle"]
            for stop in (f"{p}:{s}:{c - 1}:0", f"{p}:{s}:{c}:+", f"{p}:{s}:{c}:-",
                         f"{p}:{s}:{c}:0"):
                missing += sum(1 for n in names[(p, s)] if (stop, n) not in have)
    journaled = sum(len(r["values"]) for r in records if r["type"] == "reading")
    return missing + max(0, taken - journaled)


def _command(call: Any, ns: Any, tally: Tally) -> str | None:
    """Run one command quietly; the line it failed with, if it failed."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            call(ns)
        except (RunFailed, DeviceError, BadInput) as exc:
            return str(exc)
        except Exception as exc:  # what the CLI would call an internal error
            tally.internal += 1
            return f"INTERNAL {type(exc).__name__}: {exc}"
    return None


def one_run(args: argparse.Namespace, seed: int, out: Path, tally: Tally) -> str:
    injected: list[Any] = []
    ns = RunOptions(
        sim=SimOptions(seed=seed, noise=args.noise,
                       procedure={"cycles": args.cycles, "readings": args.readings,
                                  "settle_s": 0.0},
                       speed_mm_s=args.speed, station_hook=_faulty(args, injected, seed)),
        out=out, yes=True, json=True)
    t0 = time.monotonic()
    error = _command(cmd_run.run, ns, tally)
    tally.runs += 1
    (run_dir,) = list(out.glob("run-*"))
    resumes = 0
    # The operator's answer to a run that stopped on a named fault: resume (a few
    # times at most; each resume is a fresh process in real life).
    while error is not None and not error.startswith("INTERNAL") and resumes < 3:
        resumes += 1
        rns = ResumeOptions(run_dir=run_dir, yes=True, json=True,
                            station_hook=_faulty(args, injected, seed, first=False))
        error = _command(cmd_run.resume, rns, tally)
    tally.resumes += resumes
    result = json.loads((run_dir / "result.json").read_text())
    records = read_journal(run_dir / "journal.jsonl")
    stats = [x for x in injected if not isinstance(x, str)]
    tally.injected += (sum(1 for x in injected if x != "unplug"
                           and isinstance(x, str))
                       + sum(s.dropped + s.garbled + s.busy for s in stats))
    cuts = sum(s.power_cuts for s in stats)
    tally.cuts += cuts
    unplugs = injected.count("unplug")
    tally.unplugs += unplugs
    reopened = sum(1 for r in records if r["type"] == "event"
                   and r["event"].get("event") == "reopened")
    tally.reopened += reopened
    redone = sum(1 for r in records if r["type"] == "setup-redo")
    tally.redone += redone
    retries = sum(1 for r in records if r["type"] == "event"
                  and r["event"].get("event") == "retry")
    tally.retries += retries
    taken = (result.get("timing") or {}).get("readings", 0)
    # a resumed run's result counts only the resume's readings: count the journal's
    tally.readings += sum(len(r["values"]) for r in records if r["type"] == "reading")
    lost = _lost(records, args.readings, taken)
    tally.lost += lost
    worst = math.inf
    if result["status"] == "ok":
        tally.completed += 1
        truth = result["simulation"]["true_drho"]
        worst = max(abs(result["identified"][f"drho_{a}"] - truth[a])
                    / result["std_errors"][f"drho_{a}"] for a in AXES)
        tally.worst_se = max(tally.worst_se, worst)
    if result["status"] != "ok" or worst > args.max_se:
        tally.wrong += 1
        tally.failures.append(f"seed {seed}: {error or result.get('message') or worst}")
    return (f"run {tally.runs:3d} seed {seed:6d}: {result['status']:7s} "
            f"retries {retries:4d}  worst |Δρ−truth| {worst:5.2f} SE  lost {lost}  "
            f"cut {cuts} pulled {unplugs} reopened {reopened} resumes {resumes} "
            f"redone {redone}  {time.monotonic() - t0:5.1f} s")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--drop", type=float, default=0.05, help="fraction of replies lost")
    ap.add_argument("--garble", type=float, default=0.05, help="fraction of replies garbled")
    ap.add_argument("--busy", type=float, default=0.05,
                    help="fraction of controller requests answered busy")
    ap.add_argument("--seed", type=int, default=1, help="first run's seed")
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--readings", type=int, default=5)
    ap.add_argument("--noise", type=float, default=0.002, help="gauge noise sigma, mm")
    ap.add_argument("--speed", type=float, default=20000.0, help="axis speed, mm/s")
    ap.add_argument("--timeout", type=float, default=0.1, help="device timeouts, s")
    ap.add_argument("--max-se", type=float, default=4.0,
                    help="an identified Δρ further than this many SE from the truth is wrong")
    ap.add_argument("--cut-s", type=float, default=3.0,
                    help="how long the controller stays unreachable at its power cut, s")
    ap.add_argument("--unplug-s", type=float, default=2.0,
                    help="how long a pulled gauge adapter stays out, s")
    ap.add_argument("--no-cuts", action="store_true", help="no power cuts")
    ap.add_argument("--no-unplugs", action="store_true", help="no pulled adapters")
    ap.add_argument("--keep", metavar="DIR", help="keep the run directories here")
    args = ap.parse_args(argv)

    tally = Tally()
    t0 = time.monotonic()
    with contextlib.ExitStack() as stack:
        base = Path(args.keep) if args.keep else Path(
            stack.enter_context(tempfile.TemporaryDirectory(prefix="orthocal-soak-")))
        for i in range(args.runs):
            seed = args.seed + i
            out = base / f"soak-{seed}"
            print(one_run(args, seed, out, tally), flush=True)
    wall = time.monotonic() - t0
    print()
    print(f"soak: {args.runs} runs, faults drop {args.drop:.0%} garble {args.garble:.0%} "
          f"busy {args.busy:.0%}, {args.cycles} cycles x {args.readings} readings, "
          f"{wall:.0f} s")
    print(f"runs completed   {tally.completed} / {tally.runs}")
    print(f"retries          {tally.retries} (faults injected {tally.injected})")
    print(f"wrong answers    {tally.wrong}  (worst completed run {tally.worst_se:.2f} SE "
          f"from the truth; limit {args.max_se:g} SE)")
    print(f"lost readings    {tally.lost} of {tally.readings}")
    print(f"internal errors  {tally.internal}")
    print(f"power cuts       {tally.cuts} ({args.cut_s:g} s each); resumes {tally.resumes}; "
          f"setups redone after homing {tally.redone}")
    print(f"pulled adapters  {tally.unplugs} ({args.unplug_s:g} s each); reopened "
          f"{tally.reopened}")
    for line in tally.failures:
        print(f"  {line}")
    return 0 if tally.wrong == tally.lost == tally.internal == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
