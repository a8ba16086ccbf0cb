"""The station's side of the Protocol-level fakes (drivers.sim.fake: FakeAxes,
FakeGauge, the rig of them): the rig as the engine takes it (its devices, a
virtual operator, the hidden machine as a journal header keeps it), the tests'
station config for it, and whole runs of the engine on it. The device fakes are
re-exported from here, where the tests have always imported them.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from builders import station_config

from drivers.indicators import IndicatorGroup
from drivers.sim import fake
from drivers.sim.fake import COUNT_MM, FakeAxes, FakeGauge, SteppedClock
from drivers.sim.specs import MachineTruth
from station.commands.run import exit_status
from station.commands.simulate.launch import SIM_PROCEDURE
from station.commands.simulate.station_setups import (
    ROOM_HELD_C,
    STRAIGHTNESS_READ_MM,
    joint_bound_um_per_m,
)
from station.config import StationConfig
from station.console.operator import VirtualOperator
from station.engine.devices import Devices
from station.engine.procedure import Run, execute
from station.plan.check import check_plan
from station.plan.checker import MotionChecker
from station.plan.steps import build_plan
from station.record import io
from station.record.journal_file import JOURNAL_NAME, Journal
from station.record.run_dir import new_run_dir, now_iso, reopen, write_run_files
from station.record.state import RunState

__all__ = ["COUNT_MM", "FakeAxes", "FakeGauge", "FakeRig", "SteppedClock", "fake_config",
           "resume_on", "run_on"]


class FakeRig(fake.FakeRig):
    """The device fakes' rig (drivers.sim.fake.FakeRig) with the two gauges A and B
    that the tests' station config (builders.BASE) moves from leg to leg, given its
    hidden machine as the simulated run's options name it, and handed to the
    engine: its devices, an operator with the rig's hands, the journal's header.
    ``plane_bow`` (each gauge plane's own sagitta, drivers.sim.specs.MachineTruth) and
    ``gauge_scale`` (A's and B's scale errors) go further than a simulated run's
    options; the header keeps the scales, not the planes' bows (the tests that bow
    the planes read them off the rig)."""

    def __init__(self, *, true_drho: Sequence[float] = (0.0, 0.0, 0.0),
                 true_tilt: Sequence[float] = (0.0, 0.0, 0.0),
                 true_gap: Sequence[float] = (0.0, 0.0, 0.0),
                 backlash: Sequence[float] = (0.0, 0.0, 0.0), mount_error_mm: float = 0.0,
                 leg_bow: Sequence[float] = (0.0, 0.0, 0.0), noise_mm: float = 0.0,
                 joint_lead: Sequence[float] = (0.0, 0.0, 0.0),
                 joint_pitch: Sequence[float] = (0.0, 0.0), seed: int = 1,
                 plane_bow: Sequence[float] = (0.0,) * 6,
                 gauge_scale: Sequence[float] = (0.0, 0.0)) -> None:
        truth = MachineTruth(drho=true_drho, tilt=true_tilt, gap=true_gap,
                             backlash=backlash, leg_bow=leg_bow, plane_bow=plane_bow,
                             joint_lead=joint_lead, joint_pitch=joint_pitch)
        self.gauge_scale = [float(v) for v in gauge_scale]
        super().__init__(truth, noise_mm=noise_mm, mount_error_mm=mount_error_mm, seed=seed,
                         scale=dict(zip(("A", "B"), self.gauge_scale, strict=True)))

    def devices(self) -> Devices:
        devices = Devices(self.axes, IndicatorGroup(list(self.gauges.values())))
        devices.stack.callback(devices.indicators.close)  # the group's reader threads
        return devices

    def operator(self) -> VirtualOperator:
        return VirtualOperator(self.mount, self.unmount, joint_hands=self)

    def simulation(self) -> dict[str, Any]:
        """The hidden machine as a simulated run's journal header keeps it
        (station.record.simulated): the result states it beside what was found."""
        t = self.truth
        return {"seed": self.seed, "true_drho": list(t.drho), "true_dl": list(t.dl),
                "true_tilt": list(t.tilt), "true_gap": list(t.gap),
                "noise_mm": self.noise_mm, "mount_error_mm": self.mount_error_mm,
                "backlash_mm": list(t.backlash), "leg_bow_mm": list(t.leg_bow),
                "joint_lead_um_per_m": list(t.joint_lead), "joint_pitch": list(t.joint_pitch),
                "gauge_scale": self.gauge_scale}


#: What the simulated station states of its hardware ([uncertainty]: the legs straight
#: to half a micrometre, the room held within a tenth of a degree;
#: station.commands.simulate.station_setups.SimulatedStation.stated_inputs).
STATED: dict[str, Any] = {"leg_straightness_mm": STRAIGHTNESS_READ_MM,
                          "temperature_change_c": ROOM_HELD_C,
                          "joint_positioning_um_per_m": joint_bound_um_per_m((0, 0, 0))}


def fake_config(*, uncertainty: dict[str, Any] | None = None,
                writeback: dict[str, Any] | None = None,
                joints: dict[str, Any] | None = None, **procedure: Any) -> StationConfig:
    """The tests' two-gauge station (builders.BASE), coordinated axes, no figures,
    no history store, and what a simulated run starts from (station.commands.
    simulation: SIM_PROCEDURE, offsets up to 3 mm) with these [procedure] keys, and
    [uncertainty], [writeback] and [joints] keys where given. The config states what a
    simulated station states of its straight legs and held room (:data:`STATED`),
    ``uncertainty``'s keys over them; ``uncertainty={}`` states nothing (every input
    assumed)."""
    stated = {} if uncertainty == {} else {**STATED, **(uncertainty or {})}
    sections: dict[str, Any] = {"uncertainty": stated}
    if joints is not None:
        sections["joints"] = joints
    return station_config(controller={"motion": "coordinated"},
                          procedure={**SIM_PROCEDURE, **procedure},
                          writeback={"max_abs_offset_mm": 3.0, **(writeback or {})},
                          report={"figures": False}, history={"enabled": False}, **sections)


def run_on(rig: FakeRig, out: Path, config: StationConfig) -> tuple[int, dict[str, Any]]:
    """A whole run of the engine (station.engine.procedure.execute) on the rig, as
    ``orthocal run`` starts one: the plan checked before anything moves, from where
    the axes stand, then the run directory and its journal. Returns the command's
    exit status (3: completed, the loop not converged) and the result."""
    plan, checker = _checked(rig, config, from_where_they_stand=True)
    run_dir = new_run_dir(out)
    write_run_files(run_dir, config, plan, rig.simulation())
    header = {"type": "header", "version": "test", "config": config.model_dump(),
              "plan": plan.to_json(), "simulation": rig.simulation(), "started": now_iso(),
              "argv": []}
    return _execute(rig, config, plan, checker, run_dir, header, None, now_iso())


def resume_on(rig: FakeRig, run_dir: Path, config: StationConfig
              ) -> tuple[int, dict[str, Any]]:
    """The rest of a run from its journal (``orthocal resume``'s engine part)."""
    run_dir, state = reopen(run_dir)
    plan, checker = _checked(rig, config, from_where_they_stand=False)
    return _execute(rig, config, plan, checker, run_dir,
                    {"type": "resumed", "version": "test", "argv": []}, state,
                    (state.header.started if state.header else None) or now_iso())


def _checked(rig: FakeRig, config: StationConfig, *, from_where_they_stand: bool
             ) -> tuple[Any, MotionChecker]:
    """The plan, checked before anything moves (and from where the axes stand, as a
    new run checks it), with the checker the run goes on with."""
    limits = rig.axes.soft_limits()
    plan = build_plan(config)
    checker = MotionChecker(config, limits)
    check_plan(plan, config, limits, checker=checker)
    if from_where_they_stand:
        check_plan(plan, config, limits, start=rig.axes.read_positions(), checker=checker)
    return plan, checker


def _execute(rig: FakeRig, config: StationConfig, plan: Any, checker: MotionChecker,
             run_dir: Path, first: dict[str, Any], state: RunState | None,
             started: str) -> tuple[int, dict[str, Any]]:
    """The engine on the rig's devices, its journal opened with ``first``: the
    command's exit status and the result."""
    devices = rig.devices()
    try:
        with Journal(run_dir / JOURNAL_NAME, state) as journal:
            journal.append(first)
            ctx = Run(run_dir, config, plan, journal, devices, rig.operator(),
                      rig.simulation(), started, checker=checker)
            code, result = execute(ctx)
            # the record as result.json holds it, JSON values the tests read by key
            return exit_status(result, code), io.jsonable(result)
    finally:
        devices.close()
