"""Bring-up probes: which built-in protocol a serial port answers, and what a
controller reports. Read-only by construction: a gauge is only sent its
protocol's reading request, and the controller only read requests.

Sylvac and Mahr gauges take the same request (``?\\r``) and a pseudo-terminal
ignores the baud rate, so the protocol is decided by the reply's grammar, never
by which settings happened to be tried first: ``+0.0123\\r`` is Sylvac,
``0.0123 mm\\r\\n`` is Mahr, ``01A+0000.123\\r`` Mitutoyo.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import serial

from drivers.device_errors import DeviceError, ExceptionResponse
from drivers.indicator_protocols import BUILTIN_PROTOCOLS, IndicatorProtocol
from drivers.indicators import PORT_ERRORS, port_missing

#: why a port that names no device was not tried
MISSING = "the port does not exist"

#: the built-in protocols a probe tries, in this order
PROBED = ("mitutoyo", "sylvac", "mahr")
_QUIET_S = 0.05  # after a terminator, how long to wait for more bytes of the reply


def line_settings(p: IndicatorProtocol) -> str:
    return f"{p.baudrate} {p.bytesize}{p.parity}{p.stopbits:g}"


def classify(raw: bytes) -> tuple[str, float | None, str] | None:
    """(protocol, reading in mm or None for the gauge's error reply, line) of a
    raw reply, terminator included, matched against every built-in grammar; None
    when no grammar matches the reply exactly."""
    for name in PROBED:
        p = BUILTIN_PROTOCOLS[name]
        if not raw.endswith(p.terminator):
            continue
        body = raw[: -len(p.terminator)]
        # A longer terminator must not pass as a shorter one: "…mm\r\n" is not "\r".
        if any(len(q.terminator) > len(p.terminator) and raw.endswith(q.terminator)
               for q in BUILTIN_PROTOCOLS.values()):
            continue
        try:
            line = body.decode("ascii")
        except UnicodeDecodeError:
            return None
        m = re.fullmatch(p.reply_pattern, line)
        if m is not None:
            return name, float(m.group(1)) * p.mm_per_unit, line
        if p.error_pattern is not None and re.fullmatch(p.error_pattern, line):
            return name, None, line
    return None


@dataclass
class PortProbe:
    port: str
    protocol: str | None = None
    baudrate: int | None = None
    line: str | None = None
    reading_mm: float | None = None
    reply: str | None = None
    reason: str | None = None
    tried: list[str] = field(default_factory=list)
    # False: the port names no device at all (a typo, an adapter unplugged), which
    # the command refuses as bad input; a silent port that exists is a finding.
    exists: bool = True
    # False: the port is there but cannot be opened or used (permissions, not a
    # serial device, busy): the probe fails (exit 1), after the findings.
    usable: bool = True

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def _exchange(port: str, p: IndicatorProtocol, timeout_s: float,
              factory: Callable[..., Any]) -> bytes:
    """Send ``p``'s request at ``p``'s line settings; every byte that comes back
    until the line is quiet after a terminator, or ``timeout_s``."""
    with factory(port, timeout=min(timeout_s, _QUIET_S), write_timeout=timeout_s,
                 **p.serial_settings()) as ser:
        ser.reset_input_buffer()
        ser.write(p.request)
        deadline = time.monotonic() + timeout_s
        buf = b""
        while time.monotonic() < deadline:
            chunk = ser.read(ser.in_waiting or 1)
            if chunk:
                buf += chunk
                continue
            if buf.endswith((b"\r", b"\n")):
                break  # a whole line, and nothing more for a quiet period
        return buf


def probe_port(port: str, timeout_s: float = 0.5,
               factory: Callable[..., Any] = serial.serial_for_url) -> PortProbe:
    """Try each built-in protocol on ``port`` at its usual line settings; a
    port that does not exist (drivers.indicators.port_missing) is not tried. A
    ``factory`` other than pyserial's opens names of its own: all exist."""
    if factory is serial.serial_for_url and port_missing(port):
        return PortProbe(port, reason=MISSING, exists=False)
    result = PortProbe(port)
    replies: list[str] = []
    for name in PROBED:
        p = BUILTIN_PROTOCOLS[name]
        shown = p.request.decode("ascii").encode("unicode_escape").decode("ascii")
        result.tried.append(f"{name} ({shown} at {line_settings(p)})")
        try:
            raw = _exchange(port, p, timeout_s, factory)
        except PORT_ERRORS as exc:
            result.reason = f"cannot open or use the port: {exc}"
            result.usable = False
            return result
        if not raw:
            continue
        found = classify(raw)
        if found is None:
            replies.append(f"{name}: {raw!r}")
            continue
        protocol, value, line = found
        if protocol != name:
            # Same request, another grammar (a Mahr reply to the Sylvac attempt): the
            # attempt at that protocol's own settings decides.
            continue
        result.protocol, result.baudrate, result.line = name, p.baudrate, line_settings(p)
        result.reply = line
        if value is None:
            result.reason = f"the gauge answers with its error reply {line!r}"
        else:
            result.reading_mm = value
        return result
    if replies:
        result.reason = "replies match no built-in protocol: " + "; ".join(replies)
    else:
        result.reason = f"no reply within {timeout_s:g} s to any of: " + ", ".join(result.tried)
    return result


def probe_controller(ctl: Any) -> dict[str, Any]:
    """What a connected :class:`drivers.axes.ModbusAxisController` reports, each
    quantity on its own so that one that fails does not hide the others. Reads
    only."""
    out: dict[str, Any] = {"address": ctl.device.removeprefix("controller "),
                           "profile": ctl.map.name}

    def attempt(key: str, fn: Callable[[], Any]) -> None:
        try:
            out[key] = fn()
        except DeviceError as exc:
            out[key] = None
            out.setdefault("errors", {})[key] = exc.message

    def status() -> dict[str, Any]:
        st = ctl.read_status()
        return {k: getattr(st, k) for k in ("homed", "moving", "in_position", "alarm",
                                             "estop", "alarm_code")}

    def axes(values: Sequence[float]) -> dict[str, float]:
        return {a: round(float(v), 6) for a, v in zip("xyz", values, strict=True)}

    def limits() -> dict[str, Any]:
        sl = ctl.soft_limits()
        lo, hi = sl
        known = bool(np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)))
        return {"lower": axes(lo) if known else None, "upper": axes(hi) if known else None,
                "source": getattr(sl, "source", "registers"),
                "reason": getattr(sl, "reason", "") or None}

    attempt("status", status)
    attempt("positions_mm", lambda: axes(ctl.read_positions()))
    if ctl.map.has_role("OFFSET"):
        attempt("offsets_mm", lambda: axes(ctl.read_offsets()))
    else:
        # No fault: the drive has none over Modbus, the station holds them (its map
        # says why and where they live in the drive).
        out["offsets_mm"] = None
        out["offsets_held_by"] = "station"
        out["offsets_note"] = ctl.map.unsupported.get("offsets", "")
    attempt("soft_limits_mm", limits)
    registers: dict[str, Any] = {}
    for reg in ctl.map.registers:
        entry: dict[str, Any] = {"address": reg.address, "table": reg.table}
        try:
            entry["value"] = ctl.read_raw(reg.name)
            entry["state"] = "ok"
        except ExceptionResponse as exc:
            entry["state"] = "absent" if exc.code == 2 else f"exception {exc.code}"
        except DeviceError as exc:
            entry["state"] = "error"
            entry["error"] = exc.message
        registers[reg.name] = entry
    out["registers"] = registers
    return out
