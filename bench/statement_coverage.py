"""The statement's 95 % intervals against the truth over whole runs: N seeded runs of
the engine on the Protocol-level fakes (tests/helpers/coverage_runs.py) of machines
drawn at random (gaps, tilts, lost motion, each gauge plane's bow within the stated
straightness, half of it common to all planes, gauges' scale and plunger angles within
their stated MPE and angle, a temperature step within the stated change), each run's
statement judged against the hidden machine: how often the truth lies inside each kind
of interval (Δρ as left, the tilts, the gaps, the tool after: RMS and max), with the
exact binomial interval of that rate, and the distribution of |error|/U (U the
half-width on the truth's side: the truth is inside where it is ≤ 1). And on the
machines whose tilts and gaps the statement states and whose tool stays more than
10 µm off with the offsets alone (the truth after), how often the tool after's 95 %
interval lies within half and twice the truth, RMS and max.

The same runs as tests/station/statement/test_statement_coverage.py (seeds from 1),
more of them.

    python bench/statement_coverage.py [--runs 200] [--seed 1] [--jobs 2] [--rows rows.json]

``--rows``: every judged quantity (seed, name, truth, value, interval) as JSON.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "helpers")]

import coverage_runs as cr  # noqa: E402


def one(seed: int) -> tuple[list[cr.Judged], float]:
    """One run's judged quantities and its CPU seconds."""
    start = time.process_time()
    with tempfile.TemporaryDirectory(prefix="orthocal-coverage-") as tmp, \
            contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        judged = cr.run_and_judge(seed, Path(tmp))
    return judged, time.process_time() - start


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """The exact binomial interval of a rate k/n."""
    a = 1.0 - level
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


#: The tool's truth after beyond which its interval is judged against half and twice it.
FAR_MM = 0.010


def within_half_and_twice(judged: list[cr.Judged]) -> None:
    """Print, per tool figure after, how often its interval lies in [truth/2, 2·truth] on
    the runs whose statement holds every tilt and gap and whose true RMS after is beyond
    FAR_MM."""
    layout = set(cr.KINDS["tilts"]) | set(cr.KINDS["gaps"])
    stated: dict[int, set[str]] = {}
    for j in judged:
        stated.setdefault(j.seed, set()).add(j.name)
    far = {j.seed for j in judged if j.name == "tool.after.rms" and j.truth > FAR_MM
           and layout <= stated[j.seed]}
    for name in cr.KINDS["tool after"]:
        rows = [j for j in judged if j.name == name and j.seed in far]
        ok = [j for j in rows if j.truth / 2 <= j.interval[0] and j.interval[1] <= 2 * j.truth]
        lo = min((j.interval[0] / j.truth for j in rows), default=float("nan"))
        hi = max((j.interval[1] / j.truth for j in rows), default=float("nan"))
        print(f"    {name:17s} within half and twice the truth in {len(ok)}/{len(rows)} "
              f"runs (low end ≥ {lo:.2f}×, high end ≤ "
              f"{hi:.2f}× the truth)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--rows", type=Path, help="write every judged quantity here")
    args = parser.parse_args()
    seeds = range(args.seed, args.seed + args.runs)
    judged: list[cr.Judged] = []
    cpu = []
    with ProcessPoolExecutor(args.jobs) as pool:
        for js, seconds in pool.map(one, seeds):
            judged += js
            cpu.append(seconds)
    print(f"{args.runs} runs (seeds {args.seed}–{args.seed + args.runs - 1}), "
          f"{np.mean(cpu):.2f} s CPU per run (median {np.median(cpu):.2f})")
    for kind, rows in cr.by_kind(judged).items():
        n = len(rows)
        k = sum(j.inside for j in rows)
        lo, hi = clopper_pearson(k, n)
        r = np.array([j.ratio for j in rows])
        below = sum(j.truth < j.interval[0] for j in rows)
        print(f"{kind:13s} {k}/{n} inside = {k / n:.3f} (exact 95 %: {lo:.3f}–{hi:.3f}; "
              f"{below} below, {n - k - below} above); |e|/U median {np.median(r):.2f}, "
              f"90 % {np.quantile(r, 0.9):.2f}, max {r.max():.2f}")
        for name in cr.KINDS[kind]:
            one_name = [j for j in rows if j.name == name]
            print(f"    {name:17s} {sum(j.inside for j in one_name)}/{len(one_name)}")
    print(f"tool after, on the machines left more than {FAR_MM * 1000:.0f} µm RMS off "
          "with the offsets alone:")
    within_half_and_twice(judged)
    if args.rows is not None:
        args.rows.write_text(json.dumps([
            {"seed": j.seed, "name": j.name, "truth": j.truth, "value": j.value,
             "interval": list(j.interval)} for j in judged], indent=1))
    missing = {name for names in cr.KINDS.values() for name in names}
    counts = {name: sum(j.name == name for j in judged) for name in missing}
    short = {n: args.runs - c for n, c in counts.items() if c < args.runs}
    if short:
        print("not stated in some runs:", short)


if __name__ == "__main__":
    main()
