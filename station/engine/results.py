"""The run's result document (result.json and ``--json``) as the record's models
(station.record.result.RunResult): its fields from a measurement, an identification
and a write-back."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

import numpy as np

import orthocal
from drivers.base import ZeroOffsets
from orthocal import AXES, Identification, coverage_factor
from orthocal.loop import WRITABLE, predicted_after_correction
from orthocal.numbers import finite
from station.analysis import joints
from station.analysis.statistics import Measurement, split_key
from station.analysis.verdict import Judgement
from station.config import StationConfig
from station.engine.writeback import WritebackOutcome
from station.record.result import (
    SCHEMA_VERSION,
    Correlation,
    Deviation,
    Gauge,
    Iteration,
    Machine,
    Remaining,
    RunResult,
    Setup,
    Simulation,
    Verification,
    VerifiedDeviation,
    Writeback,
)
from station.record.result_base import Closed, JsonObject, Params
from station.record.result_sections import StandEstimate
from station.record.simulated import SimulationParams
from station.record.state import RunState


def ident_json(ident: Identification) -> JsonObject:
    """A round's identification as its journal record states it."""
    return {"model": ident.model, "method": ident.method,
            "parameters": {k: float(v) for k, v in ident.parameters.items()},
            "std_errors": {k: num(v) for k, v in ident.std_errors.items()},
            "std_errors_dof": num(ident.std_error_dof),
            "residual_rms_mm": num(ident.residual_rms)}


num = finite  # the result document's numbers: finite, or null


class Measured(Closed):
    """A round's measurement and its identification as result.json states them: the
    first round's at the top level (RunResult's fields of the same names:
    station.engine.run_record.RunRecord.first_round),
    and what a round's ``iterations`` entry and a ``verification`` take of them."""

    model: str
    method: Literal["linear", "nonlinear"]
    identified: Params
    std_errors: Params
    std_errors_dof: float | None
    correlation: Correlation
    residual_rms_mm: float | None
    sigma_mm: float | None
    condition_number: float | None
    noise_mm: float | None
    noise_floor_mm: float | None
    fit_ok: bool
    fit_note: str
    deviations: dict[str, Deviation]
    not_identifiable: list[str]
    deviations_rms_mm: float | None
    stands: dict[str, StandEstimate] | None
    setups: list[Setup]

    def iteration(self, phase: str, judged: Judgement) -> Iteration:
        """The round's entry in ``iterations`` and its verdict, nothing written after
        it yet."""
        return Iteration(
            phase=phase, model=self.model, identified=self.identified,
            std_errors=self.std_errors, std_errors_dof=self.std_errors_dof,
            offsets_written=None, writeback=None, deviations_rms_mm=self.deviations_rms_mm,
            residual_rms_mm=self.residual_rms_mm, noise_floor_mm=self.noise_floor_mm,
            fit_ok=self.fit_ok, significant=judged.significant,
            shown_within_95_mm=judged.shown(), verdict=judged.verdict)


def measurement_fields(config: StationConfig, m: Measurement, ident: Identification
                       ) -> Measured:
    stats = m.stats()
    deviations = {key: Deviation(mean=st["mean"], std=st["std"], n=st["n"],
                                 model=num(ident.predicted.get(split_key(key))))
                  for key, st in stats.items()}
    means = np.array([st["mean"] for st in stats.values()])
    noise = m.noise_mm
    # What the residual should be if the model explains the data: the standard
    # error of a deviation mean, from the cycle-to-cycle scatter (or, with one
    # cycle, from the scatter of readings at a stop), floored at the resolution.
    sems = [st["std"] / math.sqrt(st["n"]) for st in stats.values() if st["std"] is not None]
    expected = float(np.sqrt(np.mean(np.square(sems)))) if sems else (
        (noise or 0.0) * math.sqrt(1.5 / config.procedure.readings))
    resolution = min(ind.resolution_mm for ind in config.indicators)
    expected = max(expected, resolution)
    resid = float(ident.residual_rms)
    fit_ok = resid <= 3.0 * expected
    fit_note = (f"residual {1000 * resid:.1f} µm vs {1000 * expected:.1f} µm expected from "
                "the scatter: "
                + ("the model explains the data" if fit_ok else
                   "larger than the noise explains: errors outside the model (leg lengths, "
                   "play, a loose indicator?)"))
    corr = ident.correlation
    return Measured(
        model=ident.model, method=ident.method,
        identified={k: float(v) for k, v in ident.parameters.items()},
        std_errors={k: num(v) for k, v in ident.std_errors.items()},
        # with few cycles the noise behind the standard errors is itself uncertain:
        # an interval of k standard errors takes k from Student's t with these dof
        std_errors_dof=num(ident.std_error_dof),
        correlation=Correlation(names=list(ident.names),
                                matrix=[[num(x) for x in row] for row in np.asarray(corr)]),
        residual_rms_mm=num(resid), sigma_mm=num(ident.sigma),
        condition_number=num(ident.condition_number),
        noise_mm=num(noise), noise_floor_mm=num(expected), fit_ok=bool(fit_ok),
        fit_note=fit_note,
        deviations=deviations,
        # said in every report, never silently fixed
        not_identifiable=orthocal.cannot_identify(
            ident.keys, config.machine.geometry(), "full+tilt+gap"),
        deviations_rms_mm=float(np.sqrt(np.mean(means**2))) if means.size else None,
        # Where each indicator stand was, mm off the leg's middle (L/2), when the
        # stands were modelled (orthocal.stands): the operator learns where each stood.
        stands={name: StandEstimate.model_validate(est.to_dict())
                for name, est in ident.stands.items()} or None,
        setups=[Setup.model_validate(o.model_dump()) for o in m.setups],
    )


def verification_fields(config: StationConfig, fields: Measured, before: Identification,
                        target: dict[str, float],
                        edge: dict[str, float] | None = None) -> Verification:
    """The verification block of a round's ``fields`` (measurement_fields), judged
    against what the model predicts once the Δρ of ``before`` (the identification
    whose correction it verifies) are written toward ``target``: ΔL and tilts cannot
    be, and still show; nor the lost motion (``edge``: where every stop's one
    approach puts each joint against the middle of its band, ±B/2)."""
    geometry = config.machine.geometry()
    keys = [split_key(k) for k in fields.deviations]  # "+xy", "+30xy"
    aim = {n: target.get(n, 0.0) + (edge or {}).get(n, 0.0) for n in WRITABLE}
    predicted = predicted_after_correction(keys, geometry, before.parameters, aim)
    deviations = {k: VerifiedDeviation(mean=v.mean, std=v.std, n=v.n, model=v.model,
                                       expected=float(p))
                  for (k, v), p in zip(fields.deviations.items(), predicted, strict=True)}
    gaps = [v.mean - v.expected for v in deviations.values()]
    return Verification(
        identified=fields.identified, std_errors=fields.std_errors,
        std_errors_dof=fields.std_errors_dof,
        residual_rms_mm=fields.residual_rms_mm,
        deviations_rms_mm=fields.deviations_rms_mm,
        expected_rms_mm=float(np.sqrt(np.mean(np.square(predicted))))
        if len(keys) else None,
        vs_expected_rms_mm=float(np.sqrt(np.mean(np.square(gaps)))) if gaps else None,
        noise_floor_mm=fields.noise_floor_mm,
        deviations=deviations, setups=fields.setups,
    )


def known(values: Params) -> dict[str, float]:
    """The numbers of a map the engine filled from a fit (the record allows null)."""
    return {k: v for k, v in values.items() if v is not None}


def remaining_fields(iterations: list[Iteration], result: RunResult) -> Remaining | None:
    """What the last measurement says is left of Δρ on the machine as it now stands,
    not written (below k standard errors or converge_mm, the loop's limit, or a
    write-back refused). The loop stops on a correction too small to be worth a
    round, not on none at all. ``total``: the machine's Δρ at the start of the run
    as the whole run measured it, the correction the controller really holds
    (offsets read back, rounded to its count) plus what is left; the truth lies
    within k95 of its standard errors. None when the last correction was written
    and nothing measured after it (verify off)."""
    if not iterations or iterations[-1].offsets_written is not None:
        return None
    last = iterations[-1]
    found = known(last.identified)
    names = [n for n in WRITABLE if n in found]
    before, now = known(result.offsets_before or {}), known(result.offsets_written or {})
    applied = {f"drho_{a}": before[a] - now[a] for a in before} \
        if result.offsets_before is not None and result.offsets_written is not None else {}
    dof = last.std_errors_dof
    return Remaining(
        phase=last.phase, round=len(iterations),
        estimate={n: found[n] for n in names},
        total={n: applied.get(n, 0.0) + found[n] for n in names},
        std_errors={n: last.std_errors.get(n) for n in names},
        std_errors_dof=dof,
        coverage_factor_95=num(coverage_factor(dof)) if dof else None,
    )


def offsets_now(result: RunResult, controller: ZeroOffsets, state: RunState
                ) -> tuple[Literal["controller", "station"], dict[str, float] | None, str | None]:
    """Where the offsets live and what they are when the run stops (docs/design.md,
    "Offsets held by the station"): "controller" | "station", the offsets final (the
    journal's last write-back or rollback, else the offsets before), and for a station
    that holds them what to do with them (None otherwise)."""
    held_by = controller.held_by
    before = None if result.offsets_before is None else known(result.offsets_before)
    start = [before[a] for a in AXES] if before is not None else None
    final = state.held_offsets(start)
    finals = None if final is None else {a: float(v) for a, v in zip(AXES, final, strict=True)}
    if held_by != "station":
        return held_by, finals, None
    reg_map = getattr(controller, "map", None)
    why = (getattr(reg_map, "unsupported", {}) or {}).get("offsets", "")
    line = "" if final is None else ", ".join(f"{v:.4f}" for v in final)
    return held_by, finals, (
        "the drive holds no zero offset it can be told over Modbus, so these offsets "
        "live in this station run only: "
        + (f"{why.rstrip().rstrip('.')}; " if why else "enter them in the drive's own "
           "home-offset parameter; ")
        + f"a later run starts from them with [controller] offsets = [{line}] or "
        f"--offsets-from {result.run_dir}")


def writeback_record(outcome: WritebackOutcome, round: int | None = None) -> Writeback:
    """result.json's ``writeback`` of a write-back's ``outcome`` (``round``: from 1)."""
    record = Writeback(status=outcome.status, reason=outcome.reason)
    if round is not None:
        record.round = round
    return record


def _simulation(sim: SimulationParams, gauges: list[str]) -> Simulation:
    """result.json's ``simulation``: the hidden machine, named for the report."""
    return Simulation(
        seed=sim.seed, true_drho=dict(zip(AXES, sim.true_drho, strict=True)),
        true_dl=dict(zip(AXES, sim.true_dl, strict=True)),
        true_tilt=dict(zip(("tilt_yx", "tilt_zx", "tilt_zy"), sim.true_tilt, strict=True)),
        # how far the axes pass each other (mm)
        true_gap=dict(zip(("gap_xy", "gap_xz", "gap_yz"), sim.true_gap, strict=True)),
        noise_mm=sim.noise_mm,
        # stands placed by eye: each mounting off the leg's middle by up to this
        mount_error_mm=sim.mount_error_mm,
        # each joint's lost motion (ISO 230-2's reversal value), mm
        backlash_mm=dict(zip(AXES, sim.backlash_mm, strict=True)),
        # each leg's bow (sagitta at its middle, mm) and each gauge's scale error
        leg_bow_mm=dict(zip(AXES, sim.leg_bow_mm, strict=True)),
        gauge_scale=dict(zip(gauges, sim.gauge_scales(len(gauges)), strict=True)),
        # the joints' screws: lead errors (µm/m from home) and one periodic error
        joint_lead_um_per_m=dict(zip(AXES, sim.joint_lead_um_per_m, strict=True)),
        joint_pitch_um=sim.joint_pitch[0], joint_pitch_period_mm=sim.joint_pitch[1])


def base_result(run_dir: Path, config: StationConfig, sim: JsonObject | None,
                started_iso: str) -> RunResult:
    """The record as a run starts it: failed until it says otherwise. Built without
    validation: the fields every run writes at its end (timing, the plunger guard,
    the offsets) are set there, and result.json is validated as it is written
    (station.record.io)."""
    m = config.machine
    return RunResult.model_construct(  # type: ignore[call-arg]  # the rest at the end
        # the record's schema (station.record.result; orthocal schema result)
        schema_version=SCHEMA_VERSION,
        run_dir=str(run_dir), status="failed", message=None,
        started=started_iso, finished=None, duration_s=None,
        simulated=sim is not None,
        simulation=None if sim is None else _simulation(
            SimulationParams.from_header(sim), [i.name for i in config.indicators]),
        machine=Machine(id=m.id, leg_length=m.leg_length, rho_min=m.rho_min,
                        rho_max=m.rho_max),
        operator=config.station.operator,
        gauges=[Gauge(name=g.name, protocol=g.protocol, serial=g.serial)
                for g in config.indicators],
        model=config.procedure.model, method=config.procedure.method,
        identified={}, std_errors={}, offsets_before=None, offsets_written=None,
        writeback=None, verification=None,
        # each joint's positioning error as the shop stated it (the run's measured
        # lost motion replaces a table's reversal once measured: flow's reversal)
        joints=joints.fields(joints.of_run_config(config)),
    )
