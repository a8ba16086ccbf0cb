"""``orthocal probe [PORT ...] [--controller HOST:PORT | --config FILE] [--json]``:
bring-up, what answers where (docs/design.md, "Command line").

For each port named (else the config's indicator ports with ``--config``, else
every port pyserial lists) it tries each built-in indicator protocol at its
usual line settings and reports which answers, with a live reading, or why
none did. With ``--controller`` or ``--config`` it reads the controller's
status, positions, offsets and soft limits and which registers of the profile
answer. It never moves an axis and never writes a register: only reading
requests go out (drivers.bringup).

Exit status: 0 when everything asked for was probed (a silent port is a
finding, not a failure); 1 when a port that exists cannot be opened or used
(permissions, not a serial device, busy) or the controller could not be reached;
2 bad arguments, and a port that does not exist (a typo, an adapter unplugged:
what ``orthocal run`` refuses too). Either is said in one line after the findings.
"""

from __future__ import annotations

import argparse
import errno
import json
import sys
from pathlib import Path
from typing import Any

from station.errors import BadInput, RunFailed

DEFAULT_TIMEOUT_S = 0.5


def controller_from_args(args: argparse.Namespace, config: Any) -> Any:
    """An unconnected ModbusAxisController for --controller or the config's
    [controller]: one retry, so that a silent controller is found out quickly."""
    from drivers.axes import ModbusAxisController

    if config is not None:
        c = config.controller
        try:
            return ModbusAxisController(
                transport=c.transport, host=c.host, port=c.port, device_id=c.device_id,
                profile=c.profile,
                overrides={n: {"address": a} for n, a in c.registers.items()} or None,
                timeout_s=min(c.timeout_s, 2.0), retries=1, baudrate=c.baudrate,
                soft_limits=None)
        except ValueError as exc:
            raise BadInput(f"controller: {exc}") from None
    spec = args.controller
    profile = _profile(args)
    try:
        if spec.startswith(("/", "COM")):
            return ModbusAxisController(transport="rtu", port=spec, device_id=args.device_id,
                                        baudrate=args.baudrate, timeout_s=1.0, retries=1,
                                        profile=profile)
        host, sep, port = spec.rpartition(":")
        if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
            raise BadInput(f"--controller: expected HOST:PORT (or a serial device for RTU), "
                           f"got {spec!r}")
        return ModbusAxisController(transport="tcp", host=host, port=int(port),
                                    device_id=args.device_id, timeout_s=1.0, retries=1,
                                    profile=profile)
    except ValueError as exc:
        raise BadInput(f"--profile: {exc}") from None


def _profile(args: argparse.Namespace) -> str:
    """``--profile``: a built-in map, or a map file (an absolute path here)."""
    from drivers.map_files import is_map_file

    profile = getattr(args, "profile", None) or "orthocal-generic"
    return str(Path(profile).resolve()) if is_map_file(profile) else profile


def default_ports(config: Any) -> list[str]:
    if config is not None:
        return [ind.port for ind in config.indicators]
    from serial.tools import list_ports

    return sorted(p.device for p in list_ports.comports())


def gather(args: argparse.Namespace) -> dict[str, Any]:
    """The probe's findings as docs/design.md's JSON: ``indicators`` and ``controller``."""
    from drivers.bringup import probe_controller, probe_port
    from drivers.device_errors import DeviceError
    from station.config import load_config

    if getattr(args, "config", None) and args.controller:
        raise BadInput("--controller and --config: give one of them")
    if not args.timeout > 0:
        raise BadInput(f"--timeout: must be > 0 s, got {args.timeout}")
    config = load_config(args.config) if getattr(args, "config", None) else None
    ports = list(args.ports) or default_ports(config)
    found: dict[str, Any] = {"indicators": [probe_port(p, args.timeout).to_json()
                                            for p in ports],
                             "controller": None}
    if args.controller or config is not None:
        # Reads only (drivers.bringup): a probe never moves an axis or writes a register.
        ctl = controller_from_args(args, config)
        try:
            ctl.connect()
            found["controller"] = probe_controller(ctl)
        except DeviceError as exc:
            found["controller"] = {"address": ctl.device.removeprefix("controller "),
                                   "error": exc.message}
        finally:
            ctl.close()
    return found


def main(args: argparse.Namespace) -> int:
    found = gather(args)
    if args.json:
        print(json.dumps(found, indent=1))
    else:
        print_human(found)
    # After the findings: the ports that do answer are worth seeing all the same.
    missing = [ind["port"] for ind in found["indicators"] if not ind.get("exists", True)]
    if missing:
        raise BadInput(f"probe: port {missing[0]} does not exist" if len(missing) == 1 else
                       f"probe: ports {', '.join(missing)} do not exist")
    # A port that is there but cannot be used, a controller that does not answer: the
    # probe failed (exit 1), said in one line after the findings.
    failed = [f"port {ind['port']}: {ind['reason']}" for ind in found["indicators"]
              if not ind.get("usable", True)]
    controller = found["controller"]
    if controller is not None and "error" in controller:
        failed.append(f"controller {controller['address']}: {controller['error']}")
    if failed:
        raise RunFailed("probe: " + "; ".join(failed))
    return 0


def _mm(values: dict[str, float] | None) -> str:
    if values is None:
        return "-"
    return ", ".join(f"{a} {v:.3f}" for a, v in values.items())


def print_human(found: dict[str, Any], stream: Any = None) -> None:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    class _Console(Console):
        def on_broken_pipe(self) -> None:
            # rich's own ends the process (SystemExit, a descriptor left open); the
            # command line ends every command whose reader has gone alike
            raise BrokenPipeError(errno.EPIPE, "stdout's reader is gone")

    console = _Console(file=stream or sys.stdout, highlight=False, soft_wrap=False)
    inds = found["indicators"]
    if not inds:
        console.print("indicators: no serial ports found (name them: orthocal probe PORT ...)")
    else:
        table = Table(title="indicators", title_justify="left")
        for col in ("port", "protocol", "line", "reading (mm)", "note"):
            table.add_column(col, overflow="fold")
        for ind in inds:
            reading = "-" if ind["reading_mm"] is None else f"{ind['reading_mm']:+.4f}"
            table.add_row(ind["port"], ind["protocol"] or "none", ind["line"] or "-", reading,
                          ind["reason"] or "")
        console.print(table)
    c = found["controller"]
    if c is None:
        return
    if "error" in c:
        console.print(f"controller {c['address']}: {c['error']}")
        return
    st = c.get("status")
    flags = "-" if st is None else " ".join(
        k for k in ("homed", "moving", "in_position", "alarm", "estop") if st[k]) or "(none)"
    if st is not None and st["alarm_code"]:
        flags += f" (alarm code {st['alarm_code']})"
    limits = c.get("soft_limits_mm") or {}
    if limits.get("lower") is not None:
        lim = "; ".join(f"ρ_{a} ∈ [{limits['lower'][a]:.3f}, {limits['upper'][a]:.3f}]"
                        for a in "xyz") + f" ({limits['source']})"
    else:
        lim = f"unknown: {limits.get('reason') or '-'}"
    table = Table(title=f"controller {c['address']} (profile {c['profile']})",
                  title_justify="left", show_header=False)
    table.add_column("what")
    table.add_column("value", overflow="fold")
    table.add_row("status", flags)
    table.add_row("positions (mm)", _mm(c.get("positions_mm")))
    errors = dict(c.get("errors") or {})
    table.add_row("offsets (mm)", _mm(c.get("offsets_mm"))
                  if c.get("offsets_held_by") != "station" else escape(
                      "none the drive takes over Modbus; the station holds them"
                      + (f" ({c['offsets_note']})" if c.get("offsets_note") else "")))
    # Texts from the map and the drive are not rich markup ("[controller] soft_min").
    table.add_row("soft limits (mm)", escape(lim))
    for key, error in errors.items():
        table.add_row(f"{key}: error", escape(str(error)))
    regs = c["registers"]
    answer = [n for n, r in regs.items() if r["state"] == "ok"]
    absent = [n for n, r in regs.items() if r["state"] == "absent"]
    other = [f"{n} ({r['state']})" for n, r in regs.items() if r["state"] not in ("ok", "absent")]
    table.add_row("registers answering", " ".join(answer) or "none")
    table.add_row("registers absent (exception 2)", " ".join(absent) or "none")
    if other:
        table.add_row("registers failing", " ".join(other))
    console.print(table)
