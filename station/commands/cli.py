"""The ``orthocal`` command line (also ``python -m station``).

Exit status: 0 success (a run's closed loop converged, or the loop is off);
1 the run failed or was aborted, with everything recorded so far kept; 2 bad
input (config, CSV, arguments), with a message that names the offending field
or line; 3 the run completed but its closed loop did not converge (the
summary's first line says why); 4 the run completed and converged but the tool
is not shown within the config's [acceptance] limit at 95 % (FAIL, or not
decided). Every fault is one line on stderr (docs/design.md, "Exit status"): a bad
argument value names the option (station.commands.arg_types), a path the user gave
that cannot be used names it (station.commands.given_paths), and a stdout whose reader
has gone ends the command quietly (exit 1). No traceback reaches the operator unless
``--debug`` is given.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from station.commands.arg_types import (
    ArgumentsRefused,
    Parser,
    json_table,
    not_negative,
    number,
    positive,
    triple,
    whole,
)
from station.commands.sim_arguments import add_sim_options

# orthocal.MODELS, spelled out: the command line is parsed before numpy is loaded
# (tests/orthocal/test_gaps.py checks that the two agree).
_BASE_MODELS = ("rho", "L", "full", "rho+tilt", "full+tilt", "rho+gap", "rho+tilt+gap",
                "full+tilt+gap")
# each also with the legs' bows fitted ("+form": needs a second gauge plane per leg)
MODEL_NAMES = (*_BASE_MODELS, *(m + "+form" for m in _BASE_MODELS))

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_NOT_CONVERGED = 0, 1, 2, 3
EXIT_OUT_OF_TOLERANCE = 4  # completed, the tool not shown within [acceptance] at 95 %

# Each command lives in its own module, imported only when used, so that
# `orthocal identify` does not pay for pymodbus and `orthocal --help` is instant.
_COMMANDS = {
    "run": "station.commands.run:run_command",
    "resume": "station.commands.run:resume_command",
    "rollback": "station.commands.run:rollback_command",
    "sim": "station.commands.sim:main",
    "identify": "station.commands.identify:main",
    "probe": "station.commands.probe:main",
    "init": "station.commands.init:main",
    "design": "station.commands.design_command:main",
    "schema": "station.commands.schema:main",
    "history": "station.commands.history:history_main",
    "compare": "station.commands.history:compare_main",
    "export": "station.commands.export:export_main",
    "report": "station.commands.report:main",
    "compensate": "station.commands.compensate:main",
}


def _verbose(p: argparse.ArgumentParser) -> None:
    p.add_argument("--verbose", action="store_true",
                   help="print the whole summary, not its first screen only")


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", metavar="DIR", default="runs", help="where run directories go")
    p.add_argument("--yes", action="store_true", help="answer yes to every operator prompt")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument("--debug", action="store_true", help="show tracebacks of failures")


def _probe_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("ports", nargs="*", metavar="PORT",
                   help="serial ports to probe (default: every port the system lists)")
    p.add_argument("--controller", metavar="HOST:PORT",
                   help="Modbus TCP controller to probe (or a serial device: Modbus RTU)")
    p.add_argument("--device-id", type=whole(0, 247), default=1,
                   help="Modbus device id (default 1)")
    p.add_argument("--profile", metavar="MAP", default=None,
                   help="the controller's register map: a built-in name or a .toml file "
                        "(docs/design.md, Register-map files; default orthocal-generic)")
    p.add_argument("--baudrate", type=whole(1), default=19200,
                   help="RTU line speed (default 19200)")
    p.add_argument("--timeout", type=positive, default=0.5, metavar="S",
                   help="wait per protocol tried on a port (default 0.5 s)")


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="orthocal",
        description="Calibration station for Orthoglide-type parallel machines.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser("run", help="calibrate: measure, identify, write back, verify")
    src = run.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--simulate", nargs="?", const=True, default=None, metavar="SIM.toml",
        help="run against the in-process virtual station; SIM.toml: a file whose "
             "[simulation] table describes it (its keys are the options below without "
             "their dashes; an option given here wins)"
    )
    src.add_argument("--config", metavar="FILE", help="station config (TOML)")
    run.add_argument("--plan", action="store_true", help="print the checked plan and exit")
    run.add_argument("--operator", metavar="NAME", default=None,
                     help="who calibrates, recorded in the run and its report (over the "
                          "config's [station] operator)")
    run.add_argument("--offsets-from", metavar="RUN_DIR", default=None,
                     help="a drive whose offsets the station holds: start from the offsets "
                          "that run ended with")
    add_sim_options(run)
    # Hidden: the [procedure] of the virtual station as a JSON table and its axis
    # speed (mm/s), so that tests driving the real command line in a subprocess
    # (Ctrl-C, kill -9 and resume) can make a simulated run short. Both are saved
    # with the run, so resume reuses them.
    run.add_argument("--sim-procedure", type=json_table, default=None,
                     help=argparse.SUPPRESS)
    run.add_argument("--sim-speed", type=positive, default=None, help=argparse.SUPPRESS)
    _common(run)
    _verbose(run)

    resume = sub.add_parser("resume", help="continue an interrupted run from its journal")
    resume.add_argument("run_dir", metavar="RUN_DIR")
    _common(resume)
    _verbose(resume)

    rollback = sub.add_parser("rollback", help="restore the offsets saved before write-back")
    rollback.add_argument("run_dir", metavar="RUN_DIR")
    _common(rollback)

    sim = sub.add_parser("sim", help="run the virtual station until stopped")
    sim.add_argument(
        "--config-out",
        metavar="FILE",
        required=True,
        help="write a station config pointing at the virtual station",
    )
    sim.add_argument("--port", type=whole(0, 65535), default=0,
                     help="Modbus TCP port (0: any free one)")
    sim.add_argument("--transport", choices=["tcp", "rtu"], default="tcp",
                     help="Modbus TCP on 127.0.0.1, or RTU over a pseudo-terminal pair")
    sim.add_argument("--speed", type=positive, default=None, help="axis speed, mm/s")
    sim.add_argument(
        "--protocol",
        default="mitutoyo",
        choices=["mitutoyo", "sylvac", "mahr"],
        help="indicator protocol",
    )
    add_sim_options(sim)
    sim.add_argument("--debug", action="store_true", help="show tracebacks of failures")

    probe = sub.add_parser("probe", help="bring-up: which port is which gauge, what the "
                           "controller reports (reads only, never moves)")
    _probe_options(probe)
    probe.add_argument("--config", metavar="FILE",
                       help="probe the controller (and, without PORTs, the indicator ports) "
                       "of a station config")
    probe.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    probe.add_argument("--debug", action="store_true", help="show tracebacks of failures")

    init = sub.add_parser("init", help="write a commented starter config from what probe finds")
    init.add_argument("--out", metavar="FILE", required=True, help="the config to write "
                      "(never overwritten)")
    _probe_options(init)
    # As probe's --config (station.commands.probe.gather probes the same devices); the
    # config written points at its controller, with its map, machine and soft limits.
    init.add_argument("--config", metavar="FILE",
                      help="probe the controller (and, without PORTs, the indicator ports) "
                      "of a station config, and write the starter config around them")
    init.add_argument("--machine-id", metavar="ID", help="the machine's serial ([machine] id)")
    init.add_argument("--debug", action="store_true", help="show tracebacks of failures")

    ident = sub.add_parser("identify", help="identify parameters from a READINGS.csv")
    ident.add_argument("csv", metavar="READINGS.csv")
    ident.add_argument(
        "--model", choices=[*MODEL_NAMES, "auto"], default="rho",
        help="parameters to identify; auto: the smallest model the data's cycle scatter "
        "supports (needs a cycle column)")
    ident.add_argument("--method", choices=["linear", "nonlinear"], default="nonlinear")
    ident.add_argument("--leg-length", type=positive, default=310.25, metavar="L",
                       help="leg length, mm (default 310.25, the paper's machine)")
    ident.add_argument("--rho-min", type=number, default=-100.0, metavar="A",
                       help="the stroke of Π_i^-: mm from the zero posture Π0, negative (a "
                            "stroke, not a joint coordinate; default -100)")
    ident.add_argument("--rho-max", type=number, default=60.0, metavar="B",
                       help="the stroke of Π_i^+: mm from Π0 (default 60)")
    # 5 mm: [procedure] stand_tolerance_mm's default, orthocal.stands.DEFAULT_TOLERANCE
    # (spelled out: numpy is not loaded to parse;
    # tests/station/commands/test_cli_identify.py checks it)
    ident.add_argument(
        "--mount-error", type=not_negative, default=5.0, metavar="MM",
        help="how far off the leg's middle the indicator stands may have been placed "
             "(mm, +-; default 5, a run's stands placed by eye): a CSV carries no stand "
             "positions, so they are modelled, and no tilt or gap they could make is "
             "claimed; 0: placed exactly, not modelled")
    ident.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    ident.add_argument("--debug", action="store_true", help="show tracebacks of failures")

    design = sub.add_parser(
        "design", help="before anything moves: how well the planned postures determine a "
        "model, the run time, and better strokes")
    design.add_argument("--config", metavar="FILE", help="station config (TOML)")
    design.add_argument("--model", default=None,
                        help="model to design for (default: the config's [procedure] model, "
                             "else auto, designed for the largest model the stops identify)")
    design.add_argument("--strokes", metavar="A,B,C", default=None,
                        help="stops per leg in mm, replacing [procedure] strokes")
    design.add_argument("--leg-length", type=positive, default=310.25)
    design.add_argument("--rho-min", type=number, default=-100.0)
    design.add_argument("--rho-max", type=number, default=60.0)
    design.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    design.add_argument("--debug", action="store_true", help="show tracebacks of failures")

    schema = sub.add_parser(
        "schema", help="print the JSON Schema of result.json, of a journal.jsonl line or "
                       "of model.json")
    schema.add_argument("kind", choices=["result", "journal", "model"])

    history = sub.add_parser("history", help="a machine's calibrations, oldest first")
    history.add_argument("--machine", metavar="ID", help="only runs of [machine] id ID")
    history.add_argument("--out", default="runs", metavar="RUNS_DIR",
                         help="where the runs and their history.sqlite are (default runs/)")
    history.add_argument("--db", metavar="URL", help="a history database URL instead "
                         "(sqlite:///FILE, postgresql://…), as [history] url")
    history.add_argument("--rebuild", metavar="RUNS_DIR",
                         help="record every finished run under RUNS_DIR again first")
    history.add_argument("--json", action="store_true", help="print one JSON document")
    history.add_argument("--plot", metavar="FILE", help="also draw the machine's parameters "
                         "over its runs, with their drift per month (FILE.png or FILE.svg)")

    compare = sub.add_parser("compare", help="what changed between two runs of one machine")
    compare.add_argument("run_a", metavar="RUN_A", help="the earlier run's directory")
    compare.add_argument("run_b", metavar="RUN_B", help="the later run's directory")
    compare.add_argument("--json", action="store_true", help="print one JSON document")

    report = sub.add_parser("report", help="draw a run's report.html again from its "
                            "result.json, figures included")
    report.add_argument("run_dir", metavar="RUN_DIR")
    report.add_argument("--no-figures", action="store_true", help="without its figures "
                        "(refused over a report with figures unless --force)")
    report.add_argument("--out", metavar="FILE", default=None,
                        help="write the report here instead of RUN_DIR/report.html (an "
                             "existing FILE is refused unless --force)")
    report.add_argument("--force", action="store_true",
                        help="replace what --out or --no-figures would otherwise refuse")

    export = sub.add_parser("export", help="a run's final offsets in a controller's terms")
    export.add_argument("run_dir", metavar="RUN_DIR")
    export.add_argument("--to", choices=["linuxcnc", "twincat", "csv"], required=True)
    export.add_argument("--ini", metavar="FILE", help="the machine's LinuxCNC INI (its "
                        "HOME_OFFSETs: the export writes the new value beside the old)")
    export.add_argument("--joints", default="0,1,2", metavar="I,J,K",
                        help="the LinuxCNC joints of axes x,y,z (default 0,1,2)")
    export.add_argument("--axes", default="Axis 1,Axis 2,Axis 3", metavar="A,B,C",
                        help="the TwinCAT NC axes of x,y,z (default Axis 1,Axis 2,Axis 3)")
    export.add_argument("--backlash", action="store_true", help="LinuxCNC BACKLASH, TwinCAT "
                        "MC_BacklashCompensation, from the run's measured reversal, where it "
                        "stands out of its noise")
    export.add_argument("--out", metavar="FILE", help="write here instead of stdout (for "
                        "LinuxCNC the whole INI, HOME_OFFSETs calibrated, the rest as it was; "
                        "with --kinematics the folder for the three files)")
    export.add_argument("--kinematics", action="store_true", help="LinuxCNC: the whole "
                        "identified geometry, in the orthoglidekins kinematics component (the "
                        "INI, orthoglide-geometry.hal and orthoglidekins.comp into --out)")
    export.add_argument("--force", action="store_true", help="export a run that did not "
                        "converge, or whose last round was ambiguous, all the same (its "
                        "header says so)")

    comp = sub.add_parser("compensate", help="rewrite a G-code program for a controller "
                          "with the nominal kinematics, so that the identified machine's "
                          "tool follows the programmed path")
    comp.add_argument("program", metavar="PROGRAM", help="the G-code program (RS274/NGC)")
    comp.add_argument("--run", metavar="RUN_DIR", required=True,
                      help="the run whose identified machine (model.json) to compensate for")
    comp.add_argument("--out", metavar="FILE", help="the program to write (default "
                      "PROGRAM's <stem>.compensated<suffix> beside it; never overwrites a "
                      "file compensate did not write)")
    comp.add_argument("--tolerance", type=positive, default=0.001, metavar="MM",
                      help="how far the tool may stray from the programmed path, between "
                           "the points written as well as at them (default 0.001 mm)")
    comp.add_argument("--work-offset", type=triple, default=(0.0, 0.0, 0.0),
                      metavar="X,Y,Z", help="where the program's work origin sits in machine "
                      "coordinates, mm (P = 0 at the mechanical zero Π0; default 0,0,0)")
    comp.add_argument("--debug", action="store_true", help="show tracebacks of failures")
    return parser


def _ignore_file_size_signal() -> None:
    """Under a file-size limit (ulimit -f) a write past it would kill the process with
    SIGXFSZ; ignored, the write fails with EFBIG and the run ends as on a full disk:
    the record cut off, the axes stopped, one line saying how to resume."""
    import signal

    if hasattr(signal, "SIGXFSZ"):
        try:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        except ValueError:
            pass  # not the main thread (an embedding application): leave its handlers


def _on_ctrl_c(signum: int, frame: object) -> None:
    from station.errors import INTERRUPTED

    INTERRUPTED.set()  # the backstop: see station.errors.INTERRUPTED
    raise KeyboardInterrupt


def _catch_ctrl_c() -> None:
    """Ctrl-C raises KeyboardInterrupt and is remembered (station.errors.INTERRUPTED),
    where the default handler would only raise it, and lose it inside a finaliser."""
    import signal

    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, _on_ctrl_c)
    except ValueError:
        pass  # not the main thread (an embedding application): leave its handlers


def main(argv: Sequence[str] | None = None) -> int:
    _ignore_file_size_signal()
    _catch_ctrl_c()
    try:
        args = build_parser().parse_args(argv)
    except ArgumentsRefused as exc:  # one line naming the option and the value
        _fail(argparse.Namespace(), f"error: {exc}")
        return EXIT_BAD_INPUT
    try:
        code = _handle(args)
        sys.stdout.flush()  # a reader gone is found here, not at the interpreter's exit
        return code
    except BrokenPipeError:
        return _reader_gone()


def _handle(args: argparse.Namespace) -> int:
    """The command's exit status, every failure said in one line on stderr."""
    module_name, func_name = _COMMANDS[args.command].split(":")
    from drivers.device_errors import DeviceError
    from station.errors import BadInput, RunFailed, path_message

    try:
        handler = getattr(importlib.import_module(module_name), func_name)
        return int(handler(args) or EXIT_OK)
    except BadInput as exc:
        _fail(args, f"error: {exc}")
        return EXIT_BAD_INPUT
    except (RunFailed, DeviceError) as exc:
        _fail(args, f"failed: {exc}")
        return EXIT_FAILED
    except KeyboardInterrupt:
        _fail(args, "aborted by the operator (Ctrl-C)")
        return EXIT_FAILED
    except BrokenPipeError:
        raise  # stdout's reader is gone (main): nothing to say, nobody to say it to
    except OSError as exc:
        # A file the command did not check first (those the user names are, exit 2):
        # a failure during the command, said with the path.
        _fail(args, f"failed: {path_message(exc)}")
        return EXIT_FAILED
    except Exception as exc:
        _fail(args, f"internal error: {type(exc).__name__}: {exc} (rerun with --debug)")
        return EXIT_FAILED


def _reader_gone() -> int:
    """stdout's reader went away (``orthocal history | head -1``): end quietly. What
    is still buffered for it goes nowhere, so that the interpreter's last flush does
    not fail again and print a traceback of its own (Python's documented recipe:
    docs.python.org/3/library/signal.html, "Note on SIGPIPE")."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass  # a stdout without a descriptor (an embedding application's): nothing to do
    return EXIT_FAILED


def _fail(args: argparse.Namespace, line: str) -> None:
    if getattr(args, "debug", False):
        import traceback

        traceback.print_exc()
    # One line, whatever the message a library gave us holds (a database driver's
    # has several: the error, the statement, a link).
    one = " ".join(part.strip() for part in line.splitlines() if part.strip())
    try:
        print(f"orthocal: {one}", file=sys.stderr, flush=True)
    except OSError:
        pass  # stderr closed too: the exit status says it
