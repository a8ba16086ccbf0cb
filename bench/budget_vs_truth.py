"""The uncertainty budget against the truth: whole simulated runs through
the station (run --simulate in this process) on a machine whose legs are bowed by
``--leg-bow`` on every gauge plane, the config stating ``leg_straightness_mm``
(``--stated``, or none: the default), 1 µm noise, 3 cycles × 3 readings, model auto,
Δρ = (0.6, −0.4, 0.9) mm. Printed per run: the model, the statement's error
against the truth (µm per axis), the expanded uncertainty U (95 %, the budget) and
the scatter's own 95 % half-width (Type A alone), and whether each holds the truth
on every axis; then the fractions.

    python bench/budget_vs_truth.py [--runs 6] [--leg-bow 0.008] [--stated 0.010]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "helpers")]

from builders import FAST, simulated  # noqa: E402

from station.commands import run as cmd_run  # noqa: E402

TRUE = (0.6, -0.4, 0.9)
NAMES = ("drho_x", "drho_y", "drho_z")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=6)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--leg-bow", default="0.008")
    parser.add_argument("--stated", type=float, default=0.010,
                        help="leg_straightness_mm in the config (negative: not given)")
    args = parser.parse_args()
    procedure = {**FAST, "cycles": 3, "model": "auto", "max_extra_passes": 2}
    held, held_a = 0, 0
    for seed in range(args.seed, args.seed + args.runs):
        def hook(station, stated=args.stated):
            if stated >= 0:
                config = station.config
                station.config = lambda: {**config(),
                                          "uncertainty": {"leg_straightness_mm": stated}}

        out = io.StringIO()
        with tempfile.TemporaryDirectory() as d, contextlib.redirect_stdout(out), \
                contextlib.redirect_stderr(io.StringIO()):
            cmd_run.run(simulated(Path(d), seed=seed, noise=0.001, true_drho=TRUE,
                                  procedure=procedure, hook=hook, leg_bow=args.leg_bow))
        r = json.loads(out.getvalue())
        b = r["uncertainty_budget"]
        values = r["remaining"]["total"] if b["statement"] == "remaining.total" \
            else r["identified"]
        err = {n: 1000 * (values[n] - t) for n, t in zip(NAMES, TRUE, strict=True)}
        u = {n: 1000 * b["expanded_95_mm"][n] for n in NAMES}
        rem = r["remaining"] or {}
        se = rem.get("std_errors") or r["std_errors"]
        k = rem.get("coverage_factor_95") or 2.0
        a = {n: 1000 * k * se[n] for n in NAMES}
        inside = all(abs(err[n]) <= u[n] for n in NAMES)
        inside_a = all(abs(err[n]) <= a[n] for n in NAMES)
        held += inside
        held_a += inside_a
        print(f"seed {seed}: model {r['model']:<9} error " +
              " ".join(f"{err[n]:+6.2f}" for n in NAMES) + " µm   U " +
              " ".join(f"{u[n]:5.1f}" for n in NAMES) + "   scatter alone " +
              " ".join(f"{a[n]:4.1f}" for n in NAMES) +
              f"   holds: budget {inside}, scatter {inside_a}", flush=True)
    print(f"statement holds the truth on every axis: with the budget {held}/{args.runs}, "
          f"the scatter alone {held_a}/{args.runs}")


if __name__ == "__main__":
    main()
