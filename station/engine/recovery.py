"""Resuming after the controller lost its reference (a power cut): homing, then the
Π0 check that decides whether the interrupted setup's cycles can be kept.

Every cycle is measured from Π0 (its deviations are readings at Π_i^± minus the
Π0 readings that bracket it), so the cycles of a setup measured before the power
cut stay valid only if homing found the same reference. The gauges of that setup
are still on the machine; at Π0 they must read what the journal says they read
there, within what the gauges' noise and the setup's own Π0 drift explain:

    tol = K · sqrt(σ²/n_now + σ²/n_then + s_Π0²),  floored at 3 × the resolution,

with σ the pooled scatter of single readings within the setup's stops, n the
readings averaged now and then, s_Π0 the standard deviation of the setup's Π0
stop means across its cycles (drift, temperature). A larger difference means
the new reference differs: the setup's cycles are dropped and it is redone (the
journal's ``setup-redo`` record says so: the run state, station.record.state, voids
that setup's cycles when it is journaled, so the setup is measured again from its
first cycle).

Only the setup the power cut interrupted can be checked (its gauges are the
mounted ones: the run state's live setup, with its journaled readings). A reference
that moved also invalidates setups finished before the cut; homing switches repeat
to a few µm, which is what this check confirms for the axes the mounted gauges see.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Protocol

import numpy as np

from drivers.base import Alarms, AxisReadout, GaugeReadings, Homing
from station.config import StationConfig
from station.console.operator import Operator
from station.engine.mover import MoverAxes
from station.errors import RunFailed
from station.plan.checker import MotionChecker
from station.plan.steps import Plan, stop_id
from station.record.journal_file import Journal

K_SIGMA = 4.0  # a false redo costs a setup; a kept bad setup costs the answer


class Rehoming(AxisReadout, Homing, Alarms, Protocol):
    """What homing after a lost reference asks of the controller; ``name``: the device
    the journal names."""

    @property
    def name(self) -> str: ...


def home_if_needed(controller: Rehoming, config: StationConfig, journal: Journal | None,
                   operator: Operator, say: Callable[[str], None]) -> bool:
    """Home the machine if it lost its reference (HOMED clear), with the operator's
    consent. True if it was homed now. ``journal``: None before a run has one."""
    status = controller.read_status()
    if status.homed:
        return False
    say("orthocal: the controller is not homed (its reference was lost, e.g. by a power "
        "cut): positions it counts cannot be used until it is homed")
    if journal is not None:
        journal.append({"type": "event", "event": {"event": "not-homed",
                                                   "device": controller.name}})
    if not operator.confirm("Home the machine now (COMMAND 3)? The axes move to their home "
                            "switches; gauges may stay mounted"):
        raise RunFailed("the machine must be homed before the run can go on; homing "
                        "declined, nothing moved")
    if status.alarm:
        controller.reset_alarm()  # e.g. alarm 83: a move was refused while unhomed
    t0 = time.monotonic()
    controller.home(timeout_s=config.controller.home_timeout_s)
    position = [float(v) for v in controller.read_positions()]
    if journal is not None:
        journal.append({"type": "homed", "position": position,
                        "elapsed_s": round(time.monotonic() - t0, 3)})
    say(f"orthocal: homed in {time.monotonic() - t0:.1f} s")
    return True


def check_reference(controller: MoverAxes, indicators: GaugeReadings, config: StationConfig,
                    plan: Plan, journal: Journal, say: Callable[[str], None]) -> None:
    """After homing: move to Π0 with the interrupted setup's gauges still mounted and
    compare their readings with the journaled Π0 readings. If the reference moved,
    the journaled ``setup-redo`` drops the setup's cycles from the journal's state,
    which the run resumes from."""
    live = journal.state.live
    if live is None:
        journal.append({"type": "reference-check", "result": "no setup in progress"})
        return
    phase, index, mounted = live.phase, live.setup, dict(live.indicators)
    cycles = sorted(c for p, s, c in journal.state.cycles if (p, s) == (phase, index))
    if not cycles:
        journal.append({"type": "reference-check", "phase": phase, "setup": index,
                        "result": "no cycle to keep"})
        return
    readings = dict(live.readings)
    names = list(mounted)
    sp = plan.setups[index]
    # The journaled Π0 stops of the kept cycles (cycle c ends at stop c:0).
    p0 = [c for c in [0, *cycles] if all((stop_id(phase, index, c, "0"), n) in readings
                                         for n in names)]
    if not p0:
        journal.append({"type": "reference-check", "phase": phase, "setup": index,
                        "result": "no Π0 reading journaled"})
        return
    move = sp.move("0")  # approached as the journaled Π0 stops were
    start = np.asarray(controller.read_positions(), dtype=float)
    legs = MotionChecker(config, controller.soft_limits()).route(
        start, move.targets, "Π0 (reference check)", sp, mounted, approach=move.approach)
    here = start
    for leg in legs:  # waypoints where a single COMMAND 1 could take a plunger too far
        here = controller.move_and_wait(list(leg), speed_mm_s=config.controller.speed_mm_s,
                                        start=here)
    if plan.settle_s > 0:
        time.sleep(plan.settle_s)
    now = indicators.read(plan.readings, names)
    verdicts: dict[str, dict[str, float]] = {}
    ok = True
    for name in names:
        stops = [readings[(stop_id(phase, index, c, "0"), name)] for c in p0]
        # pooled within-stop scatter of this gauge over every stop of the setup
        own = [v for (stop, n), v in readings.items() if n == name and
               stop.startswith(live.prefix) and len(v) > 1]
        dof = sum(len(v) - 1 for v in own)
        sigma = math.sqrt(sum(float(np.sum((np.asarray(v) - np.mean(v)) ** 2)) for v in own)
                          / dof) if dof else 0.0
        means = [float(np.mean(v)) for v in stops]
        drift = float(np.std(means, ddof=1)) if len(means) > 1 else 0.0
        then = stops[-1]
        resolution = config.indicator(name).resolution_mm
        tol = max(K_SIGMA * math.sqrt(sigma**2 / len(now[name]) + sigma**2 / len(then)
                                      + drift**2), 3.0 * resolution)
        diff = float(np.mean(now[name]) - np.mean(then))
        verdicts[name] = {"now_mm": float(np.mean(now[name])), "then_mm": float(np.mean(then)),
                          "difference_mm": diff, "tolerance_mm": tol}
        ok = ok and abs(diff) <= tol
    journal.append({"type": "reference-check", "phase": phase, "setup": index,
                    "result": "same" if ok else "moved", "gauges": verdicts,
                    "cycles": cycles})
    worst = max(verdicts.items(), key=lambda kv: abs(kv[1]["difference_mm"]) /
                kv[1]["tolerance_mm"])
    detail = (f"gauge {worst[0]} at Π0 differs by {worst[1]['difference_mm']:+.4f} mm "
              f"(tolerance {worst[1]['tolerance_mm']:.4f} mm)")
    if ok:
        say(f"orthocal: same reference after homing ({detail}): keeping the "
            f"{len(cycles)} cycle(s) of setup {index + 1} measured before")
        return
    journal.append({"type": "setup-redo", "phase": phase, "setup": index,
                    "reason": f"reference moved by homing: {detail}",
                    "cycles_dropped": cycles})
    say(f"orthocal: the reference moved with homing ({detail}): setup {index + 1} is "
        f"redone; its {len(cycles)} earlier cycle(s) are dropped")


def resume_hint(exc: BaseException) -> str:
    """What the operator does before ``orthocal resume``, for the fault that ended a run."""
    from drivers.device_errors import ControllerNotHomed
    from station.errors import StorageFull

    if isinstance(exc, ControllerNotHomed):
        return "resume homes it (after asking) and checks Π0 before going on"
    if isinstance(exc, StorageFull):
        return "free some disk space, then continue"
    return "after fixing the cause continue"
