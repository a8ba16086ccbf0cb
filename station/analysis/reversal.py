"""The joints' lost motion in a run: measured from its reversal stops, stated in the
result, checked against the approach's overrun, and what it leaves at the tool
(docs/design.md, "Lost motion (reversal)"; orthocal.lost_motion has the maths)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

import orthocal
from orthocal.lost_motion import (
    Reversal,
    estimate_reversal,
    reversal_gain,
    standing_out,
    tool_reversal_mm,
)
from orthocal.numbers import finite
from station.analysis.statistics import Measurement
from station.config import StationConfig
from station.errors import RunFailed
from station.record import result_sections
from station.record.result_accuracy import ToolReversal

#: Beyond this reversal (mm) a joint's lost motion is worth repairing (a worn screw,
#: nut or belt), not only compensating: ISO 230-2 reports the value, the advice is
#: the station's (a quarter of the default converge_mm's 8 µm per axis at the tool).
REPAIR_ABOVE_MM = 0.02
#: A reversal above this fraction of approach_overrun_mm: the overrun may no longer
#: take up the play with margin (it must exceed the reversal).
OVERRUN_FRACTION = 0.5

METHOD = ("every cycle, Π0 read approached from one side (the cycle's closing Π0) and "
          "again from the other (its reversal stop); the gauge along j on leg i sees a "
          "shift of joint j through the leg (gain {gain:.3f} at the leg's middle, "
          "nominal model: a stand 5 mm off the middle changes it by 3 %); each joint's "
          "reversal the mean of those differences over the gain, over cycles, setups "
          "and rounds, its standard error from their scatter pooled over the joints")


def estimate(config: StationConfig, measurements: Sequence[Measurement]) -> Reversal:
    """Each joint's reversal from every cycle of every round so far (the joints do
    not change from round to round), floored at the gauges' quantisation: the
    difference of two stop means of ``readings`` quantised readings, over the gain."""
    samples: dict[str, list[float]] = {}
    for m in measurements:
        for axis, values in m.reversal.items():
            samples.setdefault(axis, []).extend(values)
    proc = config.procedure
    resolution = min(ind.resolution_mm for ind in config.indicators)
    floor = resolution / math.sqrt(6.0 * proc.readings) / gain(config)
    return estimate_reversal(samples, floor)


def gain(config: StationConfig) -> float:
    """What of a joint's shift its gauges see at Π0 (the same for every leg: 0.5)."""
    return reversal_gain("x", "y", config.machine.geometry())


def check_overrun(config: StationConfig, rev: Reversal) -> None:
    """The approach takes up a joint's play only if its overrun exceeds the reversal:
    a reversal above half of approach_overrun_mm is an error that says so (before
    anything is written)."""
    proc = config.procedure
    if proc.approach == "as-planned":
        return
    limit = OVERRUN_FRACTION * proc.approach_overrun_mm
    big = {a: v for a, v in rev.value.items() if v is not None and v > limit}
    if big:
        worst = max(big.values())
        raise RunFailed(
            "lost motion: " + ", ".join(f"joint {a} reverses by {1000 * v:.1f} µm"
                                        for a, v in big.items())
            + f", more than half of [procedure] approach_overrun_mm "
            f"({1000 * proc.approach_overrun_mm:g} µm): the approach may not take up the "
            f"play; set approach_overrun_mm to at least {2.5 * worst:.3f} mm and run again "
            "(nothing was written)")


def fields(config: StationConfig, rev: Reversal) -> result_sections.Reversal:
    """The run JSON's ``reversal`` (docs/design.md)."""
    proc = config.procedure
    side = {"below": "from below", "above": "from above"}.get(proc.approach)
    return result_sections.Reversal(
        value_mm={a: finite(v) for a, v in rev.value.items()},
        std_errors_mm={a: finite(v) for a, v in rev.std_errors.items()},
        std_errors_dof=finite(rev.dof), n=dict(rev.n),
        approach=proc.approach, approach_overrun_mm=proc.approach_overrun_mm,
        method=METHOD.format(gain=gain(config)),
        stated=_stated(proc.approach, side, rev),
    )


def _stated(approach: str, side: str | None, rev: Reversal) -> str:
    if side is None:
        return ("as planned: the joints reach the stops from either side, their "
                "reversal enters the deviations and Δρ is not corrected for it")
    edge = "lower" if approach == "below" else "upper"
    if all(v is None for v in rev.value.values()):
        return (f"every stop approached {side}: Δρ is the band's {edge} edge, off its "
                "middle by half each joint's reversal, which this run did not measure "
                "([procedure] measure_reversal = false)")
    return ("Δρ for the middle of each joint's band (ISO 230-2's mean bidirectional "
            f"position): every stop approached {side}, the fits found the band's {edge} "
            "edge, shifted by half the reversal")


def at_the_tool(config: StationConfig, rev: Reversal, points: np.ndarray) -> ToolReversal:
    """What the reversal leaves where the side a point is reached from is not known:
    each joint off by up to ±B/2, through the machine's Jacobian, worst over the
    workspace grid; and what to do (the run JSON's ``accuracy.reversal``)."""
    geometry = config.machine.geometry()
    rho = np.asarray(orthocal.inverse(np.asarray(points, dtype=float), geometry), dtype=float)
    h = 1e-3
    cols = []
    for j in range(3):
        step = np.zeros(3)
        step[j] = h
        cols.append((orthocal.forward(rho + step, geometry)
                     - orthocal.forward(rho - step, geometry)) / (2 * h))
    jac = np.stack(cols, axis=-1)  # (n, 3 xyz, 3 joints)
    tool = tool_reversal_mm(jac, rev.value)
    return ToolReversal(
        value_mm={a: finite(v) for a, v in rev.value.items()},
        tool_max_mm=finite(tool), repair_above_mm=REPAIR_ABOVE_MM, advice=advice(rev),
        assumes=("a point reached from an unknown side: each joint off by up to half its "
                 "reversal beyond the field, through the nominal kinematics, worst over "
                 "the workspace grid and the sides"))


def advice(rev: Reversal) -> str:
    """What to do about the joints' lost motion: only for a joint whose reversal
    stands out of its noise (orthocal.lost_motion.standing_out); repair beyond REPAIR_ABOVE_MM."""
    measured = {a: v for a, v in rev.value.items() if v is not None}
    if not measured:
        return "not measured"
    k = orthocal.coverage_factor(rev.dof)
    big = standing_out(rev.value, rev.std_errors, rev.dof)
    if not big:
        said = ", ".join(f"joint {a} {1000 * v:+.1f}".replace("-", "−")
                         + (f" ± {1000 * k * se:.1f}" if (se := rev.std_errors.get(a))
                            is not None else "") for a, v in measured.items())
        return (f"nothing to compensate: no joint's reversal stands out of its noise "
                f"({said} µm, 95 %)")
    if max(big.values()) > REPAIR_ABOVE_MM:
        return ("repair the mechanics of joint(s) "
                + ", ".join(a for a, v in big.items() if v > REPAIR_ABOVE_MM)
                + f" (reversal above {1000 * REPAIR_ABOVE_MM:g} µm: a worn screw, nut or "
                "belt), and meanwhile compensate it in the controller's backlash "
                "parameter")
    rest = [a for a in measured if a not in big]
    return ("compensate it in the controller's backlash (reversal) parameter: "
            + ", ".join(f"joint {a} {1000 * v:.1f} µm" for a, v in big.items())
            + (f" (joint(s) {', '.join(rest)}: not beyond the noise, leave at zero)"
               if rest else ""))

