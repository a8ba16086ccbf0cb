"""What drawing report.html costs: CPU seconds of ``station.report.render_html`` for
the results the station ships as samples (tests/data/result_tilted_*.json: a
simulated machine with offsets and tilted axes, four figures each), with and
without its figures ([report] figures). The operator waits for this at the end of
every run.

    python bench/report_cost.py [--repeat 6]

Prints, per result, the best and the median of ``--repeat`` renderings (after one
to warm matplotlib up), in CPU seconds of this process."""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from station import report

SAMPLES = Path(__file__).resolve().parents[1] / "tests" / "data"


def cpu_of(result: dict, figures: bool, repeat: int) -> list[float]:
    report.render_html(result, figures=figures)  # matplotlib imported, fonts cached
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        report.render_html(result, figures=figures)
        times.append(time.process_time() - t0)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=6)
    args = parser.parse_args()
    print(f"{'result':<28} {'figures':>7} {'best s':>8} {'median s':>9} {'<svg':>5}")
    for path in sorted(SAMPLES.glob("result_tilted_*.json")):
        result = json.loads(path.read_text())
        for figures in (True, False):
            times = cpu_of(result, figures, args.repeat)
            svgs = report.render_html(result, figures=figures).count("<svg")
            print(f"{path.name:<28} {figures!s:>7} {min(times):8.3f} "
                  f"{statistics.median(times):9.3f} {svgs:5d}")


if __name__ == "__main__":
    main()
