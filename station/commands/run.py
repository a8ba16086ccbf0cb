"""``orthocal run``, ``orthocal resume`` and ``orthocal rollback``.

The commands open what a run needs (config, virtual station, devices, run directory,
journal) and hand it to station.engine.procedure, which runs the flow; station.record.run_dir says
what a run directory holds.

Progress goes to stderr; stdout carries the summary or, with --json, one JSON
document.
"""

from __future__ import annotations

import argparse
import json
import sys
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from drivers.base import Moves
from station import report
from station.commands.given_paths import folder_to_write
from station.commands.options import ResumeOptions, RunOptions
from station.commands.simulate.file_options import run_options
from station.config import load_config, parse_config
from station.console.operator import ConsoleOperator, Operator, VirtualOperator
from station.engine.devices import build_controller, open_devices
from station.engine.procedure import Run, execute, expected_mountings
from station.engine.recovery import check_reference, home_if_needed
from station.engine.results import AXES
from station.engine.rolled_back import (
    change_text,
    nothing_to_undo,
    record_rollback,
    when_rolled_back,
)
from station.engine.writeback import rollback as do_rollback
from station.engine.writeback import rollback_values
from station.errors import BadInput, RunFailed, StorageFull, say, storage_message
from station.plan.check import check_plan
from station.plan.checker import MotionChecker
from station.plan.ports import check_ports
from station.plan.steps import build_plan
from station.record import io
from station.record.journal_file import JOURNAL_NAME, Journal
from station.record.lock import MachineLock, acquire, taken_over_message, update_run_dir
from station.record.migrate import migrate
from station.record.result import RunResult
from station.record.result_base import JsonObject
from station.record.run_dir import (
    NVRAM_NAME,
    new_run_dir,
    now_iso,
    reopen,
    version,
    write_run_files,
)
from station.record.state import RunState


def _operator(yes: bool, station: Any) -> Operator:
    if station is not None:
        return VirtualOperator(station.mount, station.unmount, say=say, place_fn=station.place,
                               joint_hands=station)
    return ConsoleOperator(yes=yes)


def _lock(stack: ExitStack, config: Any, command: str, run_dir: Path | None) -> MachineLock:
    """One station per machine: hold the controller's lock until the command ends."""
    c = config.controller
    lock = acquire(c.transport, c.host, c.port, c.device_id, command=command, run_dir=run_dir)
    stack.callback(lock.release)
    note = taken_over_message(lock)
    if note is not None:
        say(f"orthocal: {note}")
    return lock


def run_command(args: argparse.Namespace) -> int:
    return run(run_options(args))


def resume_command(args: argparse.Namespace) -> int:
    return resume(ResumeOptions.from_args(args))


def rollback_command(args: argparse.Namespace) -> int:
    return rollback(ResumeOptions.from_args(args))


def run(options: RunOptions) -> int:
    if not options.plan:  # --plan writes nothing
        folder_to_write("--out", options.out)  # before anything starts: bad input, exit 2
    with ExitStack() as stack:
        station = None
        sim = None
        if options.sim is not None:
            # The virtual station (a Modbus server, pseudo-terminals: ~0.3 s of imports)
            # only where one runs; a run against real devices never loads it.
            from station.commands.simulate import launch as simulation

            sim = simulation.sim_params(options.sim)
            station = simulation.start_station(sim, None)
            stack.callback(station.close)
            if options.sim.station_hook is not None:
                options.sim.station_hook(station)
            config = parse_config(simulation.station_config(station, sim),
                                  "virtual station config")
        else:
            if options.config is None:
                raise BadInput("run: give --config FILE or --simulate")
            config = load_config(options.config)
            check_ports(config)  # --plan too: a gauge that is not there is bad input
            if not options.plan:
                ConsoleOperator.require_tty_or_yes(options.yes)
        if options.offsets_from is not None:
            config = offsets_from(config, options.offsets_from)
        config = with_operator(config, options.operator)
        plan = build_plan(config)
        journal_box: list[Journal] = []

        def on_event(event: dict) -> None:
            if journal_box:
                journal_box[0].append({"type": "event", "event": event})

        if options.plan:
            # Listing needs the controller's soft limits, not the gauges.
            controller = build_controller(config, None)
            stack.callback(controller.close)
            check_plan(plan, config, controller.soft_limits(),
                       start=controller.read_positions())
            # The experiment's quality and time before anything moves (orthocal design).
            from station.commands.design_command import design_summary, format_summary

            summary = design_summary(config, config.procedure.model,
                                     controller_limits=controller.soft_limits())
            mounts = _mountings(config, plan)
            pictures = plan_pictures(config, plan, options.out)
            print(json.dumps({**plan.to_json(), "mountings": mounts, "design": summary,
                              "pictures": [str(p) for p in pictures]})
                  if options.json else plan.format() + "\n" + report.mountings_line(mounts)
                  + "\n" + format_summary(summary))
            return 0
        lock = _lock(stack, config, "run", None)
        devices = open_devices(config, on_event, station)
        stack.callback(devices.close)
        operator = _operator(options.yes, station)
        limits = devices.controller.soft_limits()
        # One checker for both checks: the second finds the first's routes and bounds.
        checker = MotionChecker(config, limits)
        check_plan(plan, config, limits, checker=checker)  # every posture, before anything moves
        # A controller that lost its reference (power cut before the run) counts
        # positions from nowhere: home it first, with the operator's consent.
        home_if_needed(devices.controller, config, None, operator, say)
        check_plan(plan, config, limits, start=devices.controller.read_positions(),
                   checker=checker)

        try:
            run_dir = new_run_dir(options.out)
        except OSError as exc:  # --out was checked: the disk filled, or it was taken away
            raise StorageFull(f"{storage_message(options.out, exc)}; nothing moved") from None
        update_run_dir(lock, run_dir)
        try:
            if station is not None:
                station.persist_offsets(run_dir / NVRAM_NAME)
            write_run_files(run_dir, config, plan, sim)
        except OSError as exc:
            raise StorageFull(f"{storage_message(run_dir, exc)}; nothing moved") from None
        journal = Journal(run_dir / JOURNAL_NAME)
        stack.callback(journal.close)
        journal_box.append(journal)
        journal.append({"type": "header", "version": version(), "config": config.model_dump(),
                        "plan": plan.to_json(), "simulation": sim, "started": now_iso(),
                        "argv": sys.argv[1:]})
        say(f"orthocal: run directory {run_dir}")
        say(f"orthocal: {report.mountings_line(_mountings(config, plan))}")
        ctx = Run(run_dir, config, plan, journal, devices, operator, sim, now_iso(),
                  checker=checker)
        code, result = execute(ctx)
        record_history(config, result, run_dir.parent)
        return _report(options.json, code, result, options.verbose)


#: Where ``run --plan`` draws the mounting pictures, under ``--out``: the next run
#: draws the same into its own run directory.
PLAN_PICTURES = "mountings"


def plan_pictures(config: Any, plan: Any, out: Path) -> list[Path]:
    """``run --plan``: each setup's mounting picture into ``out``/mountings (replaced:
    they are the config's, drawn again), said on stderr; one line, exit 2, where the
    folder cannot be written (``--out`` is the user's)."""
    from station.plan.mounting import sheets_of
    from station.report.joint_picture import write_joint_pictures
    from station.report.mounting_files import write_pictures

    folder = out / PLAN_PICTURES
    try:
        folder.mkdir(parents=True, exist_ok=True)
        paths = write_pictures(folder, sheets_of(config, plan))
        joints = [] if plan.station_test is None else \
            write_joint_pictures(folder, plan.station_test, config)
    except OSError as exc:
        raise BadInput(f"--out {storage_message(folder, exc)}; nothing moved") from None
    say(f"orthocal: mounting pictures, one per setup, in {folder}: "
        + ", ".join(p.name for p in paths)
        + ("" if not joints else "; the joints' own test's: "
           + ", ".join(p.name for p in joints)))
    return paths + joints


def _mountings(config: Any, plan: Any) -> dict[str, int]:
    return expected_mountings(config, plan)


def print_result(as_json: bool, result: RunResult | JsonObject, verbose: bool = False) -> None:
    """One JSON document, or the summary, on stdout: the record as result.json holds
    it, or a result.json read back (``{}``: lost); the summary's first screen, all of
    it with ``verbose`` (--verbose)."""
    if as_json:
        doc = io.jsonable(result) if isinstance(result, RunResult) else result
        print(json.dumps(report.jsonable_value(doc), allow_nan=False))
    elif not result:  # a finished run whose result.json is lost: no record to sum up
        print("orthocal run: UNKNOWN")
    else:
        print(report.summary_text(result, verbose=verbose))


def exit_status(result: RunResult | JsonObject, code: int | None = None) -> int:
    """The exit status of a finished run (station.commands.cli): 0 completed, its
    closed loop converged or off; 3 completed but the loop did not converge
    (``loop.stopped`` "not-converged" or "max_iterations"); 4 completed, converged,
    and the tool not shown within [acceptance] at 95 % (``acceptance.outcome`` fail or
    undecided); 1 anything else. ``code``:
    the flow's own (0 completed, 1 not), else taken from the result's status."""
    from station.commands.cli import (
        EXIT_FAILED,
        EXIT_NOT_CONVERGED,
        EXIT_OK,
        EXIT_OUT_OF_TOLERANCE,
    )

    if code is None:
        status = result.status if isinstance(result, RunResult) else result.get("status")
        code = EXIT_OK if status == "ok" else EXIT_FAILED
    # a result.json that is lost ({}) has no loop to judge: the flow's code stands
    if code == EXIT_OK and result and report.not_converged(result):
        return EXIT_NOT_CONVERGED
    if code == EXIT_OK and result and report.not_accepted(result):
        return EXIT_OUT_OF_TOLERANCE
    return code


def record_history(config: Any, result: RunResult, runs_dir: Path) -> None:
    """The run into the machine's history (station.history): one line, never a failed
    run, when the store cannot take it (the run directory is the record). What changed
    since the machine's last run was read before, into the result (the run's finish)."""
    if not config.history.enabled:
        return
    from station.history.entry import entry_of
    from station.history.store import HistoryStore, default_url

    url = config.history.url or default_url(runs_dir)
    try:
        with HistoryStore(url) as store:
            store.record(entry_of(result, config.controller.profile))
    except Exception as exc:  # any database error: said, and the run stands
        say(f"orthocal: not recorded in the history at {url} ({type(exc).__name__}: {exc});"
            f" orthocal history --rebuild {runs_dir} makes it again from the run directories")


def _report(as_json: bool, code: int, result: RunResult, verbose: bool = False) -> int:
    """The summary (or the JSON document) on stdout, and the exit status."""
    print_result(as_json, result, verbose)
    return exit_status(result, code)


def resume(options: ResumeOptions) -> int:
    run_dir, state = reopen(options.run_dir)
    if state.header is None:
        raise BadInput(f"{run_dir / JOURNAL_NAME}: no run header (not a run journal)")
    back = when_rolled_back(state)
    if state.finished is not None:
        result_path = run_dir / "result.json"
        found = migrate(json.loads(result_path.read_text())) if result_path.exists() else {}
        # a rolled-back run's summary no longer describes the machine: said first
        then = "" if back is None else f", then rolled back on {back}: the machine is " \
            "back as found"
        say(f"orthocal: {run_dir} already finished ({state.finished.status}){then}")
        print_result(options.json, found, options.verbose)
        return exit_status(found, 0 if state.finished.status == "ok" else 1)
    if back is not None:
        # Its journal holds write-backs the controller no longer holds: resumed, the
        # loop would measure the machine as found and write its correction a second
        # time on top of what it believes is written.
        raise BadInput(f"{run_dir} was rolled back on {back}: the machine is back as found "
                       "and the run cannot go on from its journal; start a new run "
                       "(orthocal run) to calibrate it")
    config = _held_offsets(load_config(run_dir / "config.toml"), state)
    sim = _simulation(state)
    with ExitStack() as stack:
        station, config = _restart_station(stack, options, sim, run_dir, config)
        if station is None:
            check_ports(config)  # before homing or the Π0 check moves anything
            ConsoleOperator.require_tty_or_yes(options.yes)
        _lock(stack, config, "resume", run_dir)
        plan = build_plan(config)
        journal = Journal(run_dir / JOURNAL_NAME, state)  # goes on folding into it
        stack.callback(journal.close)
        # First thing after reopening: a kill may have torn the last line, and the
        # reader accepts a torn line only when a session record follows it; a driver
        # retry journaled while the devices open must not be that record.
        journal.append({"type": "resumed", "version": version(), "argv": sys.argv[1:]})

        def on_event(event: dict) -> None:
            journal.append({"type": "event", "event": event})

        devices = open_devices(config, on_event, station)
        stack.callback(devices.close)
        checker = MotionChecker(config, devices.controller.soft_limits())
        check_plan(plan, config, devices.controller.soft_limits(), checker=checker)
        say(f"orthocal: resuming {run_dir}")
        operator = _operator(options.yes, station)
        try:
            if home_if_needed(devices.controller, config, journal, operator, say):
                check_reference(devices.controller, devices.indicators, config, plan,
                                journal, say)
        except BaseException:
            _stop_quietly(devices.controller)
            raise
        started = state.header.started or now_iso()
        ctx = Run(run_dir, config, plan, journal, devices, operator, sim, started,
                  checker=checker)
        code, result = execute(ctx)
        record_history(config, result, run_dir.parent)
        return _report(options.json, code, result, options.verbose)


def _held_offsets(config: Any, state: RunState) -> Any:
    """Where the station holds the offsets (a map without OFFSET registers), a resumed
    run or a rollback starts from what its journal says they are."""
    from drivers.map_files import load_map

    if load_map(config.controller.profile).has_role("OFFSET"):
        return config
    held = state.held_offsets(config.controller.offsets)
    if held is None:
        return config
    return config.model_copy(update={
        "controller": config.controller.model_copy(update={"offsets": held})})


def with_operator(config: Any, name: str | None) -> Any:
    """``--operator NAME`` over the config's ``[station] operator``: one line, exit 2,
    for a name the config would refuse (empty, longer than 100 characters)."""
    if name is None:
        return config
    if not 0 < len(name.strip()) <= 100:
        raise BadInput("--operator: give a name of 1 to 100 characters")
    return config.model_copy(update={"station": config.station.model_copy(
        update={"operator": name.strip()})})


def offsets_from(config: Any, run_dir: Path) -> Any:
    """``--offsets-from RUN_DIR``: start from the offsets that run ended with (a station
    holding them); BadInput where there are none to take or the drive holds its own."""
    from drivers.map_files import load_map

    if load_map(config.controller.profile).has_role("OFFSET"):
        raise BadInput(f"--offsets-from: the drive holds its own zero offsets (map "
                       f"{config.controller.profile!r} has OFFSET registers)")
    done, state = reopen(Path(run_dir))
    start = state.header.config.controller.offsets if state.header else None
    held = state.held_offsets(start)
    if held is None:
        raise BadInput(f"--offsets-from: {done} wrote no offsets")
    say(f"orthocal: starting from the offsets {done} ended with: "
        + ", ".join(f"{a} {v:+.4f}" for a, v in zip(AXES, held, strict=True)) + " mm")
    return config.model_copy(update={
        "controller": config.controller.model_copy(update={"offsets": held})})


def _simulation(state: RunState) -> dict[str, Any] | None:
    """A simulated run's parameters as its header holds them (None: real devices)."""
    sim = None if state.header is None else state.header.simulation
    return None if sim is None else sim.as_json()


def _restart_station(stack: ExitStack, options: ResumeOptions, sim: dict[str, Any] | None,
                     run_dir: Path, config: Any) -> tuple[Any, Any]:
    """The virtual station of a simulated run, started again (None and the config
    unchanged for a run on real devices, which never loads the simulator)."""
    if sim is None:
        return None, config
    from station.commands.simulate import launch as simulation

    return simulation.restart_station(stack, options.station_hook, sim, run_dir, config)


def _stop_quietly(controller: Moves) -> None:
    """Axes stopped on any fault of homing or of the Π0 check."""
    try:
        controller.stop()
    except Exception:
        pass  # the fault being raised says what went wrong


def _warn_later(run_dir: Path, config: Any, state: RunState, consequence: str) -> None:
    """The machine's later runs in the history, named before a rollback changes what
    they left (station.history.later)."""
    from station.history.later import later_warning

    started = state.header.started if state.header is not None else None
    line = later_warning(run_dir, config.machine.id, started, consequence)
    if line is not None:
        say(line)


def rollback(options: ResumeOptions) -> int:
    run_dir, state = reopen(options.run_dir)
    config = _held_offsets(load_config(run_dir / "config.toml"), state)
    sim = _simulation(state)
    with ExitStack() as stack:
        station, config = _restart_station(stack, options, sim, run_dir, config)
        _lock(stack, config, "rollback", run_dir)
        journal = Journal(run_dir / JOURNAL_NAME, state)
        stack.callback(journal.close)
        controller = build_controller(config, None)
        stack.callback(controller.close)
        operator = _operator(options.yes, station)
        if station is None and not options.yes:
            ConsoleOperator.require_tty_or_yes(False)
        current, backup = rollback_values(controller, run_dir)
        refused = nothing_to_undo(run_dir, state, current, backup,
                                  controller.offset_resolution_mm())
        if refused is not None:
            raise BadInput(refused)
        _warn_later(run_dir, config, state, "rolling this run back writes the offsets from "
                    "before it over what they left")
        if not operator.confirm(f"Restore the offsets saved in {run_dir}: "
                                f"{change_text(current, backup)}?"):
            raise RunFailed("rollback declined by the operator; offsets unchanged")
        restored = do_rollback(controller, run_dir, journal)
    # one time for the rollback: the journal's record of it (result.json, the history
    # and a later refusal all say that second)
    at = when_rolled_back(journal.state) or now_iso()  # journaled by do_rollback
    result = record_rollback(run_dir, current, restored, at, figures=config.report.figures)
    if result is not None and result.finished:
        record_history(config, result, run_dir.parent)  # the entry says "rolled back"
    if options.json:
        print(json.dumps({"run_dir": str(run_dir), "status": "ok", "restored": restored,
                          "replaced": current}))
    else:
        print(f"orthocal rollback: rolled back, offsets {change_text(current, restored)} "
              "(restored)")
    return 0
