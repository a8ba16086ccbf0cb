"""The run's flow, shared by ``orthocal run`` and ``orthocal resume``: measure, identify,
write back, verify, and again while the verification finds a significant correction
(the closed loop); replaying from the journal what a resumed run already did.

station.engine.closed_loop decides the next step from what happened so far (a pure state machine);
:class:`Flow` performs each step or, on resume, replays it from the journal.
"""

from __future__ import annotations

import threading
import time

from drivers.device_errors import DeviceError
from station.config import StationConfig
from station.console.progress import Progress
from station.engine import joint_station
from station.engine.closed_loop import LoopState, mountings_expected, next_step
from station.engine.flow import Flow, Run
from station.engine.recovery import resume_hint
from station.engine.run_record import RunRecord
from station.engine.sequencer import Sequencer
from station.errors import BadInput, RunFailed, StorageFull, say, storage_message
from station.plan.checker import MotionChecker
from station.plan.mounting import sheets_of
from station.plan.steps import Plan
from station.record import io
from station.record.result import RunResult, Setup, Status, Timing
from station.record.run_dir import now_iso
from station.record.state import RunState
from station.report.mounting_files import write_pictures


def _import_plotting(figures: bool) -> None:
    try:
        # The nonlinear identification's optimiser and the model test's and the loop's
        # distributions (~0.6 s of imports), likewise.
        import scipy.optimize
        import scipy.special  # noqa: F401
    except Exception:
        pass  # identification imports them again and reports any failure itself
    if not figures:
        return  # a report without figures ([report] figures = false) needs no matplotlib
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot
    except Exception:
        pass  # the report says so itself when it cannot plot


def execute(ctx: Run) -> tuple[int, RunResult]:
    """The whole flow of a run (or the rest of a resumed one): its exit status and
    record, as result.json holds it."""
    # The report's plots need matplotlib (~0.4 s of imports) and identification
    # scipy.optimize (~0.3 s), which would otherwise load after the last reading,
    # with the operator waiting; loaded now, they overlap the first moves, where
    # the main thread only waits on the drive.
    warm = threading.Thread(target=_import_plotting, args=(ctx.config.report.figures,),
                            name="orthocal-import-plotting", daemon=True)
    warm.start()
    try:
        with Progress(ctx.plan, ctx.config.procedure.verify) as progress:
            ctx.operator.attach(progress.say, progress.bar.paused)
            code, result = _execute_with(ctx, progress)
    finally:
        warm.join()
    return code, result


def _execute_with(ctx: Run, progress: Progress) -> tuple[int, RunResult]:
    # The plan check's checker, where the command made one: its routes and bounds
    # are the first cycle's (each sub-move decided again from where the axes stand).
    checker = ctx.checker or MotionChecker(ctx.config, ctx.devices.controller.soft_limits())
    draw_mountings(ctx)
    seq = Sequencer(
        config=ctx.config, plan=ctx.plan, controller=ctx.devices.controller,
        indicators=ctx.devices.indicators, journal=ctx.journal, operator=ctx.operator,
        checker=checker, progress=progress)
    seq.keeper.expected = expected_mountings(ctx.config, ctx.plan)
    record = RunRecord(ctx.run_dir, ctx.config, ctx.sim, ctx.started_iso)
    proc = ctx.config.procedure
    flow = Flow(ctx, seq, record)
    loop = LoopState(max_iterations=proc.max_iterations, verify=proc.verify,
                     max_extra_passes=proc.max_extra_passes)
    try:
        # The station's own test of the joints first: the identification and the
        # tool's statement rest on its tables (station.engine.joint_station).
        flow.joint_tests = joint_station.test_joints(ctx, seq, record, progress)
        # The whole flow: station.engine.closed_loop decides, Flow performs (or replays) the step.
        while (step := next_step(loop)).kind != "finish":
            if step.kind == "measure" and step.extra:
                loop.extended(flow.extend(step.phase or "v"))
            elif step.kind == "measure":
                loop.measured(flow.measure(step.phase or "m"))
            else:
                loop.wrote(flow.write(step.round))
        flow.stopped(step.reason or "converged")
        progress.finished()  # every reading taken: "done" said here, never before
    except KeyboardInterrupt:
        message = (f"aborted by the operator (Ctrl-C); {_stopped(seq)}, journal kept. "
                   f"Continue with: orthocal resume {ctx.run_dir}")
        _finish(ctx, seq, record, "aborted", message, final=False)
        raise RunFailed(message) from None
    except (DeviceError, RunFailed) as exc:
        stopped = _stopped(seq)
        message = (f"{exc}. {stopped[0].upper()}{stopped[1:]}, journal kept; "
                   f"{resume_hint(exc)} with: orthocal resume {ctx.run_dir}")
        _finish(ctx, seq, record, "failed", message, final=False)
        raise RunFailed(message) from exc
    except BadInput:
        _finish(ctx, seq, record, "failed", "refused by a runtime check", final=False)
        raise
    # the record as written (validated, in result.json's order), for the caller
    written = _finish(ctx, seq, record, record.result.status, record.result.message,
                      final=True)
    return (0 if written.status == "ok" else 1), written


def draw_mountings(ctx: Run) -> None:
    """Each setup's mounting picture into the run directory before the first prompt
    names one; a resumed run draws only those missing (its operator saw the others)."""
    try:
        write_pictures(ctx.run_dir, sheets_of(ctx.config, ctx.plan), missing_only=True)
    except OSError as exc:
        raise StorageFull(storage_message(ctx.run_dir, exc)) from None


def measured_setups(plan: Plan, state: RunState, cycles: int) -> list[Setup]:
    """The measurement's setups the journal holds as done (result.json's ``setups``),
    for a run that stopped before its identification listed them: its report then
    shows what was measured, not "nothing"."""
    out: list[Setup] = []
    for (phase, index), done in sorted(state.setups_done.items(), key=lambda kv: kv[0][1]):
        if phase != "m" or not 0 <= index < len(plan.setups):
            continue
        sp = plan.setups[index]
        out.append(Setup(leg=sp.leg, indicators=dict(sp.indicators),
                         cycles_used=len(done.cycles),
                         cycles_max=max(cycles, len(done.cycles)),
                         repeats=done.repeats or 0, flagged=bool(done.flagged),
                         spread_mm=done.spread_mm))
    return out


def expected_mountings(config: StationConfig, plan: Plan) -> dict[str, int]:
    """The mountings the run expects (closed_loop.mountings_expected), the station's own
    test of the joints' one per joint before them (``joint_test``, where it has one)."""
    proc = config.procedure
    counts = mountings_expected(len(plan.setups_of(0)), proc.max_iterations,
                                proc.max_extra_passes, proc.verify,
                                second=len(plan.setups_of(1)),
                                later=len(plan.setups_of(2)))
    tested = len(config.joints.station_test)
    if not tested:
        return counts
    return {**{k: v + (0 if k == "per_write_back" else tested) for k, v in counts.items()},
            "joint_test": tested}


def _stopped(seq: Sequencer) -> str:
    if seq.stop_error is None:
        return "axes stopped"
    # A silent controller cannot be told to stop: say so rather than claim it stopped.
    return ("the stop command did not reach the controller: make sure the axes are "
            "stopped")


def _since_last(ctx: Run, record: RunRecord) -> None:
    """What changed since the machine's last calibration (station.history), into the
    record before result.json and report.html are written: written once, not again."""
    from station.history.compare import since_last_run

    since = since_last_run(ctx.config, record.result, ctx.run_dir.parent)
    if since is not None:
        record.since_last(since)


def _finish(ctx: Run, seq: Sequencer, record: RunRecord, status: Status,
            message: str | None, final: bool) -> RunResult:
    """The run's end, however it ends: its facts into the ``record``, result.json and
    report.html written. The record as result.json holds it, validated once here."""
    record.status(status, message)
    wall = time.monotonic() - ctx.t0
    # The journal as saved so far, every session's (its state, not the file again).
    state = ctx.state
    # A resumed run lasts from its header, its sessions and the pauses between; a run
    # never resumed, this session's wall time.
    started = state.started if state.resumes else None
    record.finished(
        finished_iso=now_iso(),
        duration_s=round(time.time() - started, 3) if started else round(wall, 3),
        timing=Timing(wall_s=round(wall, 3), moves=seq.counters.moves,
                      readings=seq.counters.readings, retries=state.retries,
                      outliers_rejected=seq.counters.rejected,
                      # what the operator paid: each mounting and the time it took
                      mountings=state.mountings, operator_s=round(state.operator_s, 3)),
        # stopped before its identification: what it measured
        state=state, setups=measured_setups(ctx.plan, state, ctx.config.procedure.cycles),
        controller=ctx.devices.controller)
    if final:
        ctx.journal.append({"type": "finished", "status": status, "message": message})
        _since_last(ctx, record)
    else:
        try:
            ctx.journal.flush()
        except Exception:
            pass
    written = io.validated(record.result)
    try:
        io.write_result(written, ctx.run_dir)
    except OSError as exc:  # a full disk: the journal holds the run; say so and go on
        say(f"orthocal: result.json not written ({storage_message(ctx.run_dir, exc)})")
        return written
    from station import report

    try:
        report.write_html(written, ctx.run_dir,
                          figures=ctx.config.report.figures)
    except Exception as exc:  # the report is a view; result.json and the journal are the record
        say(f"orthocal: report.html not written ({type(exc).__name__}: {exc})")
    return written
