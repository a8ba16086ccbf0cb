"""The run's flow, shared by ``orthocal run`` and ``orthocal resume``: measure, identify,
write back, verify, finish; replaying from the journal what a resumed run already did."""

from __future__ import annotations

import argparse
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.errors import DeviceError
from station.config import StationConfig
from station.devices import Devices
from station.errors import BadInput, RunFailed, say, storage_message
from station.journal import JOURNAL_NAME, Journal, JournalState, read_journal
from station.operator import ConsoleOperator, Operator, VirtualOperator
from station.plan import MotionChecker, Plan
from station.progress import Progress
from station.recovery import resume_hint
from station.results import (
    base_result,
    ident_json,
    measurement_fields,
    print_result,
    writeback_fields,
)
from station.rundir import now_iso
from station.sequencer import Measurement, Sequencer
from station.writeback import WritebackOutcome, write_back


@dataclass
class Run:
    run_dir: Path
    config: StationConfig
    plan: Plan
    journal: Journal
    devices: Devices
    operator: Operator
    sim: dict[str, Any] | None
    args: argparse.Namespace
    state: JournalState
    records: list[dict[str, Any]]
    started_iso: str
    t0: float = field(default_factory=time.monotonic)
    result: dict[str, Any] = field(default_factory=dict)


def _done_cycles(records: list[dict[str, Any]]) -> dict[tuple[str, int, int], dict[str, Any]]:
    return {(r["phase"], int(r["setup"]), int(r["cycle"])): r
            for r in records if r["type"] == "cycle"}


def _import_plotting() -> None:
    try:
        # The nonlinear identification's optimiser (~0.3 s of imports), likewise.
        import scipy.optimize  # noqa: F401
    except Exception:
        pass  # identification imports it again and reports any failure itself
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot
    except Exception:
        pass  # the report says so itself when it cannot plot


def execute(ctx: Run) -> int:
    # The report's plots need matplotlib (~0.4 s of imports) and identification
    # scipy.optimize (~0.3 s), which would otherwise load after the last reading,
    # with the operator waiting; loaded now, they overlap the first moves, where
    # the main thread only waits on the drive.
    warm = threading.Thread(target=_import_plotting, name="orthocal-import-plotting",
                            daemon=True)
    warm.start()
    try:
        with Progress(ctx.plan, ctx.config.procedure.verify) as progress:
            if isinstance(ctx.operator, VirtualOperator):
                ctx.operator._say = progress.say
            elif isinstance(ctx.operator, ConsoleOperator):
                ctx.operator.pause = progress.bar.paused
            code, result = _execute_with(ctx, progress)
    finally:
        warm.join()
    print_result(ctx.args, result)
    return code


def _execute_with(ctx: Run, progress: Progress) -> tuple[int, dict[str, Any]]:
    checker = MotionChecker(ctx.config, ctx.devices.controller.soft_limits())
    seq = Sequencer(
        config=ctx.config, plan=ctx.plan, controller=ctx.devices.controller,
        indicators=ctx.devices.indicators, journal=ctx.journal, operator=ctx.operator,
        checker=checker, done_cycles=_done_cycles(ctx.records),
        done_setups={(r["phase"], int(r["setup"])) for r in ctx.records
                     if r["type"] == "setup_done"},
        progress=progress)
    result = base_result(ctx.run_dir, ctx.config, ctx.sim, ctx.started_iso)
    ctx.result = result
    try:
        measurement = seq.measure("m")
        ident = _identify(ctx, measurement)
        result.update(measurement_fields(ctx.config, measurement, ident))
        if ctx.state.identification is None:
            ctx.journal.append({"type": "identification", **ident_json(ident)})
        outcome = write_back(
            controller=ctx.devices.controller, identified=dict(ident.parameters),
            max_abs_offset_mm=ctx.config.writeback.max_abs_offset_mm, run_dir=ctx.run_dir,
            journal=ctx.journal, operator=ctx.operator, prior=ctx.state)
        writeback_fields(result, outcome, ctx.devices.controller)
        status, message = _status_of(outcome)
        if outcome.status == "written" and ctx.config.procedure.verify:
            vm = seq.measure("v")
            vident = _identify(ctx, vm, model=ident.model)  # auto chose it: verify it
            vfields = measurement_fields(ctx.config, vm, vident)
            result["verification"] = {
                "identified": vfields["identified"], "std_errors": vfields["std_errors"],
                "residual_rms_mm": vfields["residual_rms_mm"],
                "deviations_rms_mm": vfields["deviations_rms_mm"],
                "deviations": vfields["deviations"], "setups": vfields["setups"],
            }
            if ctx.state.verification is None:
                ctx.journal.append({"type": "verification", **ident_json(vident),
                                    "deviations_rms_mm": vfields["deviations_rms_mm"]})
        result["status"], result["message"] = status, message
    except KeyboardInterrupt:
        message = (f"aborted by the operator (Ctrl-C); {_stopped(seq)}, journal kept. "
                   f"Continue with: orthocal resume {ctx.run_dir}")
        _finish(ctx, seq, result, "aborted", message, final=False)
        raise RunFailed(message) from None
    except (DeviceError, RunFailed) as exc:
        stopped = _stopped(seq)
        message = (f"{exc}. {stopped[0].upper()}{stopped[1:]}, journal kept; "
                   f"{resume_hint(exc)} with: orthocal resume {ctx.run_dir}")
        _finish(ctx, seq, result, "failed", message, final=False)
        raise RunFailed(message) from exc
    except BadInput:
        _finish(ctx, seq, result, "failed", "refused by a runtime check", final=False)
        raise
    _finish(ctx, seq, result, result["status"], result["message"], final=True)
    return (0 if result["status"] == "ok" else 1), result


def _stopped(seq: Sequencer) -> str:
    if seq.stop_error is None:
        return "axes stopped"
    # A silent controller cannot be told to stop: say so rather than claim it stopped.
    return ("the stop command did not reach the controller: make sure the axes are "
            "stopped")


def _status_of(outcome: WritebackOutcome) -> tuple[str, str | None]:
    if outcome.status in ("written", "skipped"):
        return "ok", None
    if outcome.status == "refused":
        return "refused", f"write-back {outcome.reason}"
    if outcome.status == "declined":
        return "aborted", f"write-back {outcome.reason}"
    return "failed", outcome.reason


def _identify(ctx: Run, m: Measurement, model: str | None = None) -> Any:
    from station.models import identify_measurement

    ident, selection = identify_measurement(ctx.config, m, model)
    if selection is not None:
        ctx.result["model_selection"] = selection
    return ident


def _finish(ctx: Run, seq: Sequencer, result: dict[str, Any], status: str,
            message: str | None, final: bool) -> None:
    result["status"], result["message"] = status, message
    result["finished"] = now_iso()
    wall = time.monotonic() - ctx.t0
    started = ctx.state.started
    result["duration_s"] = round(time.time() - started, 3) if started else round(wall, 3)
    retries = 0
    try:
        records = read_journal(ctx.run_dir / JOURNAL_NAME)
        retries = sum(1 for r in records if r["type"] == "event"
                      and r.get("event", {}).get("event") == "retry")
    except BadInput:
        pass
    result["timing"] = {"wall_s": round(wall, 3), "moves": seq.counters.moves,
                        "readings": seq.counters.readings, "retries": retries,
                        "outliers_rejected": seq.counters.rejected}
    if final:
        ctx.journal.append({"type": "finished", "status": status, "message": message})
    else:
        try:
            ctx.journal.flush()
        except Exception:
            pass
    from station import report

    try:
        report.write_result(result, ctx.run_dir)
    except OSError as exc:  # a full disk: the journal holds the run; say so and go on
        say(f"orthocal: result.json not written ({storage_message(ctx.run_dir, exc)})")
        return
    try:
        report.write_html(result, ctx.run_dir)
    except Exception as exc:  # the report is a view; result.json and the journal are the record
        say(f"orthocal: report.html not written ({type(exc).__name__}: {exc})")
