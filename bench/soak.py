"""Soak: many simulated calibrations back to back through flaky devices (issue 5).

Each run is a whole ``orthocal run --simulate`` (measure, identify, write back,
verify) on a fresh virtual station with random hidden offsets, while every
device misbehaves at random: the controller drops, garbles and answers "busy"
to a fraction of its requests, the gauges drop and garble a fraction of their
replies. It prints, over all runs:

* runs completed (status ok),
* retries (journaled by the drivers) against faults injected (the simulators'
  own count),
* wrong answers: a run that did not complete, or an identified Δρ more than
  ``--max-se`` standard errors from the hidden truth (target 0),
* lost readings: readings the sequencer took but the journal does not hold,
  plus stops a journaled cycle used without their full set of readings
  (target 0).

    python bench/soak.py [--runs 20] [--drop 0.05] [--garble 0.05] [--busy 0.05]
                         [--seed 1] [--cycles 3] [--readings 5] [--timeout 0.1]

Faults draw from seeded RNGs, so a soak is reproducible up to thread timing.
Device timeouts are short (a lost reply costs one timeout) to keep it fast.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from station import cmd_run
from station.errors import RunFailed
from station.journal import read_journal

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
    worst_se: float = 0.0
    failures: list[str] = field(default_factory=list)


def _faulty(args: argparse.Namespace, injected: list[Any]):
    """The hook given the virtual station before the run derives its config."""

    def hook(station: Any) -> None:
        c = station.controller.faults
        c.drop_rate, c.garble_rate, c.busy_rate = args.drop, args.garble, args.busy
        for sim in station.indicators.values():
            sim.faults.drop_rate, sim.faults.garble_rate = args.drop, args.garble
            # The gauges count requests and replies, not faults: count them here.
            take = sim._take

            def counting(rate: float, next_field: str, take: Any = take) -> bool:
                hit = take(rate, next_field)
                if hit:
                    injected.append(next_field)
                return hit

            sim._take = counting
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


def one_run(args: argparse.Namespace, seed: int, out: Path, tally: Tally) -> str:
    injected: list[Any] = []
    ns = argparse.Namespace(
        simulate=True, config=None, plan=False, seed=seed, true_drho=None, true_dl=None,
        noise=args.noise, out=str(out), yes=True, json=True, debug=False,
        sim_procedure={"cycles": args.cycles, "readings": args.readings, "settle_s": 0.0},
        sim_speed=args.speed, sim_station_hook=_faulty(args, injected))
    error = None
    t0 = time.monotonic()
    sink = io.StringIO()
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(io.StringIO()):
        try:
            cmd_run.run(ns)
        except RunFailed as exc:
            error = str(exc)
    tally.runs += 1
    (run_dir,) = list(out.glob("run-*"))
    result = json.loads((run_dir / "result.json").read_text())
    records = read_journal(run_dir / "journal.jsonl")
    stats = next(x for x in injected if not isinstance(x, str))
    tally.injected += (sum(1 for x in injected if isinstance(x, str))
                       + stats.dropped + stats.garbled + stats.busy)
    retries = sum(1 for r in records if r["type"] == "event"
                  and r["event"].get("event") == "retry")
    tally.retries += retries
    taken = (result.get("timing") or {}).get("readings", 0)
    tally.readings += taken
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
            f"{time.monotonic() - t0:5.1f} s")


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
    for line in tally.failures:
        print(f"  {line}")
    return 0 if tally.wrong == 0 and tally.lost == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
