"""``orthocal run``, ``orthocal resume`` and ``orthocal rollback``.

A run directory holds everything needed to understand and to continue a run:
config.toml (the config it ran with), plan.txt / plan.json, journal.jsonl,
offsets_backup.json, result.json, report.html and, for a simulated run,
simulation.json (the hidden errors, to restart the virtual station on resume)
and controller_nvram.json (the virtual controller's non-volatile offsets).

Progress goes to stderr; stdout carries the summary or, with --json, one JSON
document.
"""

from __future__ import annotations

import argparse
import json
import math
import secrets
import sys
import threading
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from drivers.errors import DeviceError
from station.config import StationConfig, dump_toml, load_config, parse_config
from station.errors import BadInput, RunFailed
from station.journal import JOURNAL_NAME, Journal, JournalState, read_journal, replay
from station.operator import ConsoleOperator, Operator, VirtualOperator
from station.plan import MotionChecker, Plan, build_plan, check_plan, posture_label
from station.sequencer import Measurement, Sequencer, split_key
from station.writeback import WritebackOutcome, write_back
from station.writeback import rollback as do_rollback

AXES = ("x", "y", "z")
SIM_NAME = "simulation.json"
NVRAM_NAME = "controller_nvram.json"
DEFAULT_NOISE_MM = 0.002
DEFAULT_SIM_DRHO_MM = 2.0  # random hidden Δρ are drawn uniform in ±this
# Attempts after the first, per request, for the controller and each gauge. A run
# makes ~1000 controller requests and ~600 readings: on a bus where one request in
# seven fails (bench/soak.py: 5 % lost, 5 % garbled, 5 % busy) four attempts run
# out about once every two or three runs (0.14^4 x 1000), six once in a hundred
# (0.14^6 x 1000). The price: a dead device is declared after six timeouts, not four.
DEVICE_RETRIES = 5


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("orthocal")
    except Exception:
        return "unknown"


def _now_iso() -> str:
    return datetime.now(UTC).astimezone().isoformat(timespec="seconds")


def _err(*parts: object) -> None:
    print(*parts, file=sys.stderr, flush=True)


# --- progress ------------------------------------------------------------------------------


class Progress:
    """Run progress on stderr through station.console.RunProgress (a live bar on a
    terminal, plain lines in a log); one step per stop read."""

    def __init__(self, plan: Plan, verify: bool, enabled: bool = True) -> None:
        from station.console import RunProgress

        self.plan = plan
        per_phase = sum(1 + (len(sp.order) + 1) * plan.cycles for sp in plan.setups)
        self.bar = RunProgress(per_phase * (2 if verify else 1), enabled=enabled)
        self.steps = 0

    def __enter__(self) -> Progress:
        self.bar.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.bar.__exit__(None, None, None)

    def say(self, text: str) -> None:
        self.bar.message(text)

    def __call__(self, event: str, **info: Any) -> None:
        try:
            self._event(event, info)
        except Exception:
            pass  # a display glitch must never stop a run

    def _event(self, event: str, info: dict[str, Any]) -> None:
        phase = {"m": "measure", "v": "verify"}.get(info.get("phase", ""), "")
        if event == "read":
            self.steps += 1
            sp = self.plan.setups[info["setup"]]
            posture = posture_label(info["sign"], sp.leg)
            self.bar.total_steps = max(self.bar.total_steps, self.steps)
            self.bar.update(f"{sp.index + 1}/{len(self.plan.setups)} (leg {sp.leg}, {phase})",
                            posture, max(info["cycle"], 1), self.plan.cycles, self.steps)
        elif event == "cycle":
            devs = " ".join(f"{k} {v:+.4f}" for k, v in info["deviations"].items())
            self.say(f"{phase} setup {info['setup'] + 1} cycle {info['cycle']}: {devs} mm")
        elif event == "cycle_replayed":
            # Replayed cycles count as done for the time estimate.
            sp = self.plan.setups[info["setup"]]
            self.steps += len(sp.order) + 1 + (1 if info["cycle"] == 1 else 0)
            self.say(f"{phase} setup {info['setup'] + 1} cycle {info['cycle']}: "
                     "from the journal")
        elif event == "repeat":
            self.say(f"{phase} setup {info['setup'] + 1}: spread {info['spread']:.4f} mm "
                     "above repeatability_mm, repeating its cycles")
        elif event == "setup_done":
            o = info["outcome"]
            flag = " (FLAGGED: above repeatability_mm)" if o.flagged else ""
            self.say(f"{phase} setup {o.index + 1} done: {o.cycles_used} cycle(s), "
                     f"spread {o.spread_mm:.4f} mm{flag}")


# --- devices -------------------------------------------------------------------------------


@dataclass
class Devices:
    controller: Any
    indicators: Any  # IndicatorGroup
    station: Any = None  # VirtualStation when simulated
    stack: ExitStack = field(default_factory=ExitStack)

    def close(self) -> None:
        self.stack.close()


def build_controller(config: StationConfig, on_event: Callable[[dict], None] | None) -> Any:
    from drivers.axes import ModbusAxisController

    c = config.controller
    try:
        controller = ModbusAxisController(
            transport=c.transport, host=c.host, port=c.port, device_id=c.device_id,
            profile=c.profile,
            overrides={name: {"address": addr} for name, addr in c.registers.items()} or None,
            timeout_s=c.timeout_s, retries=DEVICE_RETRIES, baudrate=c.baudrate,
            on_event=on_event, acceleration_mm_s2=c.accel_mm_s2)
    except ValueError as exc:  # an unknown profile or a bad register override
        raise BadInput(f"controller: {exc}") from None
    return controller.connect()


def build_indicators(config: StationConfig, names: list[str] | None,
                     on_event: Callable[[dict], None] | None) -> Any:
    from drivers.indicators import IndicatorGroup, SerialIndicator, make_protocol

    opened: list[Any] = []
    try:
        for ind in config.indicators:
            if names is not None and ind.name not in names:
                continue
            overrides: dict[str, Any] = {}
            for key, target in (("baudrate", "baudrate"), ("bytesize", "bytesize"),
                                ("parity", "parity"), ("stopbits", "stopbits"),
                                ("request", "request"), ("terminator", "terminator"),
                                ("pattern", "reply_pattern"),
                                ("error_pattern", "error_pattern"), ("unit", "unit"),
                                ("scale", "scale")):
                value = getattr(ind, key)
                if value is not None:
                    overrides[target] = value
            try:
                protocol = make_protocol(ind.protocol, overrides or None)
            except ValueError as exc:
                raise BadInput(f"indicators.{ind.name}: {exc}") from None
            opened.append(SerialIndicator(ind.name, ind.port, protocol,
                                          timeout_s=ind.timeout_s, retries=DEVICE_RETRIES,
                                          on_event=on_event))
        return IndicatorGroup(opened)
    except BaseException:
        for ind in opened:
            ind.close()
        raise


def open_devices(config: StationConfig, on_event: Callable[[dict], None] | None,
                 station: Any = None) -> Devices:
    devices = Devices(None, None, station)
    try:
        devices.controller = build_controller(config, on_event)
        devices.stack.callback(devices.controller.close)
        used = sorted({n for s in config.setups for n in s.indicators})
        devices.indicators = build_indicators(config, used, on_event)
        devices.stack.callback(devices.indicators.close)
    except BaseException:
        devices.close()
        raise
    return devices


# --- simulation ----------------------------------------------------------------------------


def sim_params_from_args(args: argparse.Namespace) -> dict[str, Any]:
    seed = args.seed if args.seed is not None else secrets.randbelow(2**31)
    rng = np.random.default_rng(seed)
    drho = list(args.true_drho) if args.true_drho is not None else \
        [round(float(v), 4) for v in rng.uniform(-DEFAULT_SIM_DRHO_MM, DEFAULT_SIM_DRHO_MM, 3)]
    dl = list(args.true_dl) if args.true_dl is not None else [0.0, 0.0, 0.0]
    noise = args.noise if args.noise is not None else DEFAULT_NOISE_MM
    if not (math.isfinite(noise) and noise >= 0):
        raise BadInput(f"--noise: must be >= 0 mm, got {noise}")
    return {
        "seed": seed,
        "true_drho": drho,
        "true_dl": dl,
        "noise_mm": noise,
        # Test hooks (not on the command line): the six-indicator style, a procedure.
        "indicators": int(getattr(args, "sim_indicators", 2) or 2),
        "procedure": getattr(args, "sim_procedure", None),
        "writeback": getattr(args, "sim_writeback", None),
        "speed_mm_s": getattr(args, "sim_speed", None),
    }


def start_station(params: dict[str, Any], nvram: Path | None) -> Any:
    from drivers.sim.station import SIM_ACCEL_MM_S2, SIM_SPEED_MM_S, VirtualStation

    # A faster virtual machine (tests) keeps the default's speed/acceleration ratio,
    # so its moves stay physical: trapezoids, in-position waits, derived deadlines.
    speed = params.get("speed_mm_s") or SIM_SPEED_MM_S
    return VirtualStation(
        true_drho=params["true_drho"], true_dl=params["true_dl"],
        noise_mm=params["noise_mm"], seed=params["seed"],
        indicator_count=params["indicators"], nvram_path=nvram,
        procedure=params.get("procedure"), writeback=params.get("writeback"),
        speed_mm_s=speed, accel_mm_s2=SIM_ACCEL_MM_S2 * speed / SIM_SPEED_MM_S,
    )


def _station_hook(args: argparse.Namespace, station: Any) -> None:
    """Tests reach the running virtual station (to inject its faults) through
    ``args.sim_station_hook``; the command line never sets it."""
    hook = getattr(args, "sim_station_hook", None)
    if hook is not None:
        hook(station)


def _rebind(config: StationConfig, ports: dict[str, Any]) -> StationConfig:
    """The saved config of a simulated run, pointed at the restarted station's new ports."""
    data = config.model_dump(exclude_none=True)
    data["controller"]["port"] = ports["controller"]
    for ind in data["indicators"]:
        ind["port"] = ports["indicators"][ind["name"]]
    return parse_config(data, "virtual station config")


# --- the run -------------------------------------------------------------------------------


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


def _new_run_dir(out: Path) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    for n in range(1000):
        path = out / (f"run-{stamp}" if n == 0 else f"run-{stamp}-{n}")
        try:
            path.mkdir()
            return path
        except FileExistsError:
            continue
    raise RunFailed(f"cannot create a run directory under {out}")


def _operator(args: argparse.Namespace, station: Any) -> Operator:
    if station is not None:
        return VirtualOperator(station.mount, station.unmount, say=_err)
    return ConsoleOperator(yes=bool(args.yes))


def run(args: argparse.Namespace) -> int:
    with ExitStack() as stack:
        station = None
        sim = None
        if args.simulate:
            sim = sim_params_from_args(args)
            station = start_station(sim, None)
            stack.callback(station.close)
            _station_hook(args, station)
            config = parse_config(station.config(), "virtual station config")
        else:
            config = load_config(args.config)
            if not args.plan:
                ConsoleOperator.require_tty_or_yes(bool(args.yes))
        plan = build_plan(config)
        journal_box: list[Journal] = []

        def on_event(event: dict) -> None:
            if journal_box:
                journal_box[0].append({"type": "event", "event": event})

        if args.plan:
            # Listing needs the controller's soft limits, not the gauges.
            controller = build_controller(config, None)
            stack.callback(controller.close)
            check_plan(plan, config, controller.soft_limits(),
                       start=controller.read_positions())
            print(json.dumps(plan.to_json()) if args.json else plan.format())
            return 0
        devices = open_devices(config, on_event, station)
        stack.callback(devices.close)
        check_plan(plan, config, devices.controller.soft_limits(),
                   start=devices.controller.read_positions())

        run_dir = _new_run_dir(Path(args.out))
        if station is not None:
            station.persist_offsets(run_dir / NVRAM_NAME)
            (run_dir / SIM_NAME).write_text(json.dumps(sim, indent=2) + "\n")
        (run_dir / "config.toml").write_text(dump_toml(config))
        (run_dir / "plan.txt").write_text(plan.format() + "\n")
        (run_dir / "plan.json").write_text(json.dumps(plan.to_json(), indent=1) + "\n")
        journal = Journal(run_dir / JOURNAL_NAME)
        stack.callback(journal.close)
        journal_box.append(journal)
        journal.append({"type": "header", "version": _version(), "config": config.model_dump(),
                        "plan": plan.to_json(), "simulation": sim, "started": _now_iso(),
                        "argv": sys.argv[1:]})
        _err(f"orthocal: run directory {run_dir}")
        ctx = Run(run_dir, config, plan, journal, devices, _operator(args, station), sim, args,
                  JournalState(), [], _now_iso())
        return _execute(ctx)


def _reopen(args: argparse.Namespace) -> tuple[Path, list[dict[str, Any]], JournalState]:
    """The run directory named on the command line, its journal and replayed state."""
    run_dir = Path(args.run_dir)
    if not run_dir.is_dir():
        raise BadInput(f"{run_dir}: no such run directory")
    records = read_journal(run_dir / JOURNAL_NAME)
    return run_dir, records, replay(records)


def _restart_station(
    stack: ExitStack,
    args: argparse.Namespace,
    sim: dict[str, Any] | None,
    run_dir: Path,
    config: StationConfig,
) -> tuple[Any, StationConfig]:
    """For a simulated run (``sim`` from the journal header), the virtual station
    again — same hidden errors, offsets from its saved memory — and the config
    rebound to its new ports; for a real one, nothing to start."""
    if sim is None:
        return None, config
    station = start_station(sim, run_dir / NVRAM_NAME)
    stack.callback(station.close)
    _station_hook(args, station)
    return station, _rebind(config, station.ports())


def resume(args: argparse.Namespace) -> int:
    run_dir, records, state = _reopen(args)
    if state.header is None:
        raise BadInput(f"{run_dir / JOURNAL_NAME}: no run header (not a run journal)")
    if state.finished is not None:
        result_path = run_dir / "result.json"
        result = json.loads(result_path.read_text()) if result_path.exists() else {}
        _err(f"orthocal: {run_dir} already finished ({state.finished.get('status')})")
        _print_result(args, result)
        return 0 if state.finished.get("status") == "ok" else 1
    config = load_config(run_dir / "config.toml")
    sim = state.header.get("simulation")
    with ExitStack() as stack:
        station, config = _restart_station(stack, args, sim, run_dir, config)
        if station is None:
            ConsoleOperator.require_tty_or_yes(bool(args.yes))
        plan = build_plan(config)
        journal = Journal(run_dir / JOURNAL_NAME)
        stack.callback(journal.close)
        # First thing after reopening: a kill may have torn the last line, and the
        # reader accepts a torn line only when a session record follows it; a driver
        # retry journaled while the devices open must not be that record.
        journal.append({"type": "resumed", "version": _version(), "argv": sys.argv[1:]})

        def on_event(event: dict) -> None:
            journal.append({"type": "event", "event": event})

        devices = open_devices(config, on_event, station)
        stack.callback(devices.close)
        check_plan(plan, config, devices.controller.soft_limits())
        _err(f"orthocal: resuming {run_dir}")
        started = state.header.get("started") or _now_iso()
        ctx = Run(run_dir, config, plan, journal, devices, _operator(args, station), sim, args,
                  state, records, started)
        return _execute(ctx)


def rollback(args: argparse.Namespace) -> int:
    run_dir, _, state = _reopen(args)
    config = load_config(run_dir / "config.toml")
    sim = state.header.get("simulation") if state.header else None
    with ExitStack() as stack:
        station, config = _restart_station(stack, args, sim, run_dir, config)
        journal = Journal(run_dir / JOURNAL_NAME)
        stack.callback(journal.close)
        controller = build_controller(config, None)
        stack.callback(controller.close)
        operator = _operator(args, station)
        if station is None and not args.yes:
            ConsoleOperator.require_tty_or_yes(False)
        if not operator.confirm(f"Restore the offsets saved in {run_dir}?"):
            raise RunFailed("rollback declined by the operator; offsets unchanged")
        restored = do_rollback(controller, run_dir, journal)
    if args.json:
        print(json.dumps({"run_dir": str(run_dir), "status": "ok", "restored": restored}))
    else:
        print("orthocal rollback: offsets restored to " + ", ".join(
            f"{a} {restored[a]:+.4f}" for a in AXES) + " mm")
    return 0


# --- execution shared by run and resume -----------------------------------------------------


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


def _execute(ctx: Run) -> int:
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
    _print_result(ctx.args, result)
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
    result = _base_result(ctx)
    ctx.result = result
    try:
        measurement = seq.measure("m")
        ident = _identify(ctx, measurement)
        result.update(_measurement_fields(ctx, measurement, ident))
        if ctx.state.identification is None:
            ctx.journal.append({"type": "identification", **_ident_json(ident)})
        outcome = write_back(
            controller=ctx.devices.controller, identified=dict(ident.parameters),
            max_abs_offset_mm=ctx.config.writeback.max_abs_offset_mm, run_dir=ctx.run_dir,
            journal=ctx.journal, operator=ctx.operator, prior=ctx.state)
        _writeback_fields(result, outcome, ctx)
        status, message = _status_of(outcome)
        if outcome.status == "written" and ctx.config.procedure.verify:
            vm = seq.measure("v")
            vident = _identify(ctx, vm)
            vfields = _measurement_fields(ctx, vm, vident)
            result["verification"] = {
                "identified": vfields["identified"], "std_errors": vfields["std_errors"],
                "residual_rms_mm": vfields["residual_rms_mm"],
                "deviations_rms_mm": vfields["deviations_rms_mm"],
                "deviations": vfields["deviations"], "setups": vfields["setups"],
            }
            if ctx.state.verification is None:
                ctx.journal.append({"type": "verification", **_ident_json(vident),
                                    "deviations_rms_mm": vfields["deviations_rms_mm"]})
        result["status"], result["message"] = status, message
    except KeyboardInterrupt:
        message = (f"aborted by the operator (Ctrl-C); {_stopped(seq)}, journal kept. "
                   f"Continue with: orthocal resume {ctx.run_dir}")
        _finish(ctx, seq, result, "aborted", message, final=False)
        raise RunFailed(message) from None
    except (DeviceError, RunFailed) as exc:
        stopped = _stopped(seq)
        message = (f"{exc}. {stopped[0].upper()}{stopped[1:]}, journal kept; after fixing "
                   f"the cause continue with: orthocal resume {ctx.run_dir}")
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


def _identify(ctx: Run, m: Measurement) -> Any:
    import orthocal

    proc = ctx.config.procedure
    try:
        return orthocal.identify(m.for_identify(), ctx.config.machine.geometry(),
                                 model=proc.model, method=proc.method)
    except orthocal.IdentificationError as exc:
        raise RunFailed(f"identification failed: {exc}") from None


def _ident_json(ident: Any) -> dict[str, Any]:
    return {"model": ident.model, "method": ident.method,
            "parameters": {k: float(v) for k, v in ident.parameters.items()},
            "std_errors": {k: _num(v) for k, v in ident.std_errors.items()},
            "residual_rms_mm": _num(ident.residual_rms)}


def _num(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _measurement_fields(ctx: Run, m: Measurement, ident: Any) -> dict[str, Any]:
    stats = m.stats()
    deviations = {}
    for key, st in stats.items():
        model = ident.predicted.get(split_key(key))
        deviations[key] = {**st, "model": _num(model)}
    means = np.array([st["mean"] for st in stats.values()])
    noise = m.noise_mm
    # What the residual should be if the model explains the data: the standard
    # error of a deviation mean, from the cycle-to-cycle scatter (or, with one
    # cycle, from the scatter of readings at a stop), floored at the resolution.
    sems = [st["std"] / math.sqrt(st["n"]) for st in stats.values() if st["std"] is not None]
    expected = float(np.sqrt(np.mean(np.square(sems)))) if sems else (
        (noise or 0.0) * math.sqrt(1.5 / ctx.config.procedure.readings))
    resolution = min(ind.resolution_mm for ind in ctx.config.indicators)
    expected = max(expected, resolution)
    resid = float(ident.residual_rms)
    fit_ok = resid <= 3.0 * expected
    fit_note = (f"residual {resid:.4f} mm vs {expected:.4f} mm expected from the scatter: "
                + ("the model explains the data" if fit_ok else
                   "larger than the noise explains: errors outside the model (leg lengths, "
                   "play, a loose indicator?)"))
    corr = ident.correlation
    return {
        "model": ident.model, "method": ident.method,
        "identified": {k: float(v) for k, v in ident.parameters.items()},
        "std_errors": {k: _num(v) for k, v in ident.std_errors.items()},
        "correlation": {"names": list(ident.names),
                        "matrix": [[_num(x) for x in row] for row in np.asarray(corr)]},
        "residual_rms_mm": _num(resid), "sigma_mm": _num(ident.sigma),
        "condition_number": _num(ident.condition_number),
        "noise_mm": _num(noise), "fit_ok": bool(fit_ok), "fit_note": fit_note,
        "deviations": deviations,
        "deviations_rms_mm": float(np.sqrt(np.mean(means**2))) if means.size else None,
        "setups": [{"leg": o.leg, "indicators": o.indicators, "cycles_used": o.cycles_used,
                    "cycles_max": o.cycles_max, "repeats": o.repeats, "flagged": o.flagged,
                    "spread_mm": o.spread_mm} for o in m.setups],
    }


def _writeback_fields(result: dict[str, Any], outcome: WritebackOutcome, ctx: Run) -> None:
    result["writeback"] = outcome.to_json()
    result["offsets_before"] = outcome.before if outcome.before is not None else \
        {a: float(v) for a, v in zip(AXES, ctx.devices.controller.read_offsets(), strict=True)}
    result["offsets_written"] = outcome.written


def _base_result(ctx: Run) -> dict[str, Any]:
    m = ctx.config.machine
    sim = ctx.sim
    return {
        "run_dir": str(ctx.run_dir), "status": "failed", "message": None,
        "started": ctx.started_iso, "finished": None, "duration_s": None,
        "simulated": sim is not None,
        "simulation": None if sim is None else {
            "seed": sim["seed"], "true_drho": dict(zip(AXES, sim["true_drho"], strict=True)),
            "true_dl": dict(zip(AXES, sim["true_dl"], strict=True)),
            "noise_mm": sim["noise_mm"]},
        "machine": {"leg_length": m.leg_length, "rho_min": m.rho_min, "rho_max": m.rho_max},
        "model": ctx.config.procedure.model, "method": ctx.config.procedure.method,
        "identified": {}, "std_errors": {}, "offsets_before": None, "offsets_written": None,
        "writeback": None, "verification": None,
    }


def _finish(ctx: Run, seq: Sequencer, result: dict[str, Any], status: str,
            message: str | None, final: bool) -> None:
    result["status"], result["message"] = status, message
    result["finished"] = _now_iso()
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

    report.write_result(result, ctx.run_dir)
    try:
        report.write_html(result, ctx.run_dir)
    except Exception as exc:  # the report is a view; result.json and the journal are the record
        _err(f"orthocal: report.html not written ({type(exc).__name__}: {exc})")


def _print_result(args: argparse.Namespace, result: dict[str, Any]) -> None:
    if getattr(args, "json", False):
        from station.report import _jsonable

        print(json.dumps(_jsonable(result), allow_nan=False))
    else:
        from station import report

        print(report.summary_text(result))
