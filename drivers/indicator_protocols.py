"""Dial-indicator protocols as data: how one kind of gauge talks
(:class:`IndicatorProtocol`), the built-ins docs/design.md fixes
(:data:`BUILTIN_PROTOCOLS`), a built-in with a config table's overrides
(:func:`make_protocol`), and what a reply line means (:class:`ReplyParser`).

A gauge's protocol is data, not a class per vendor, so a gauge nobody has met
yet is a ``[[indicators]]`` entry with ``protocol = "generic"`` and a few
overrides rather than new code. The serial driver (:mod:`drivers.indicators`),
the simulated gauges (:mod:`drivers.sim.pty_gauges`) and the bring-up probe
(:mod:`drivers.bringup`) all speak through these, so none of them needs a port
to know a protocol.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any, Literal, Self

from pydantic import BaseModel, ConfigDict, field_validator, model_validator

from drivers.device_errors import IndicatorReplyError

UNIT_MM: dict[str, float] = {"mm": 1.0, "um": 0.001, "in": 25.4}


class IndicatorProtocol(BaseModel):
    """How one kind of gauge talks: line settings, request, reply grammar, units.

    ``reply_pattern`` / ``error_pattern`` are matched (``re.fullmatch``) against
    the ASCII reply line with its terminator removed; the reply pattern has
    exactly one group, the value, and the error pattern at most one, the gauge's
    error code. The value is converted to mm as ``float(group) * scale *
    UNIT_MM[unit]``. ``reply_format`` / ``error_format`` (``str.format`` with
    ``value`` / ``code``, without terminator) say how the gauge writes a line;
    the simulator speaks through them, and the model checks they agree with the
    patterns so a protocol cannot be self-contradictory.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    baudrate: int = 9600
    bytesize: Literal[5, 6, 7, 8] = 8
    parity: Literal["N", "E", "O", "M", "S"] = "N"
    # A float has no Literal type (PEP 586); pydantic validates 1.5 all the same.
    stopbits: Literal[1, 1.5, 2] = 1  # type: ignore[valid-type]
    request: bytes
    terminator: bytes = b"\r"
    reply_pattern: str
    error_pattern: str | None = None
    unit: Literal["mm", "um", "in"] = "mm"
    scale: float = 1.0
    reply_format: str | None = None
    error_format: str | None = None

    @field_validator("baudrate")
    @classmethod
    def _positive_baud(cls, v: int) -> int:
        if v <= 0:
            raise ValueError("baudrate must be positive")
        return v

    @field_validator("request", "terminator")
    @classmethod
    def _non_empty(cls, v: bytes) -> bytes:
        if not v:
            raise ValueError("must not be empty")
        return v

    @field_validator("scale")
    @classmethod
    def _non_zero_scale(cls, v: float) -> float:
        if v == 0:
            raise ValueError("scale must not be zero")
        return v

    @field_validator("reply_pattern")
    @classmethod
    def _one_group(cls, v: str) -> str:
        groups = _compile(v).groups
        if groups != 1:
            raise ValueError(f"needs exactly one group (the value), has {groups}")
        return v

    @field_validator("error_pattern")
    @classmethod
    def _at_most_one_group(cls, v: str | None) -> str | None:
        if v is not None and _compile(v).groups > 1:
            raise ValueError("may have at most one group (the gauge's error code)")
        return v

    @model_validator(mode="after")
    def _formats_match_patterns(self) -> Self:
        if self.reply_format is not None:
            for sample in (-1.2345, 0.0, 12.5):
                line = _format(self.reply_format, "reply_format", value=sample)
                if not re.fullmatch(self.reply_pattern, line):
                    raise ValueError(
                        f"reply_format writes {line!r}, which reply_pattern does not match"
                    )
        if self.error_format is not None:
            if self.error_pattern is None:
                raise ValueError("error_format needs an error_pattern")
            line = _format(self.error_format, "error_format", code=1)
            if not re.fullmatch(self.error_pattern, line):
                raise ValueError(
                    f"error_format writes {line!r}, which error_pattern does not match"
                )
        return self

    @property
    def bits_per_char(self) -> float:
        """Bit-times one character occupies on the line (start + data + parity + stop)."""
        return 1 + self.bytesize + (0 if self.parity == "N" else 1) + self.stopbits

    @property
    def mm_per_unit(self) -> float:
        return self.scale * UNIT_MM[self.unit]

    def serial_settings(self) -> dict[str, Any]:
        """Keyword arguments for ``serial.serial_for_url`` / ``serial.Serial``."""
        return {
            "baudrate": self.baudrate,
            "bytesize": self.bytesize,
            "parity": self.parity,
            "stopbits": self.stopbits,
        }


def _compile(pattern: str) -> re.Pattern[str]:
    try:
        return re.compile(pattern)
    except re.error as e:
        raise ValueError(f"invalid regular expression {pattern!r}: {e}") from None


def _format(fmt: str, field: str, **kw: Any) -> str:
    try:
        return fmt.format(**kw)
    except (KeyError, IndexError, ValueError) as e:
        raise ValueError(f"{field} {fmt!r} cannot be formatted: {e}") from None


# Built-ins as docs/design.md fixes them. Mitutoyo's reply pattern accepts any channel
# number in front because multiplexers answer with their own; the value itself
# must carry sign and point, as the gauge always sends both.
BUILTIN_PROTOCOLS: dict[str, IndicatorProtocol] = {
    p.name: p
    for p in (
        IndicatorProtocol(
            name="mitutoyo",
            baudrate=9600,
            bytesize=8,
            parity="N",
            stopbits=1,
            request=b"1\r",
            terminator=b"\r",
            reply_pattern=r"\d\dA([+-]\d+\.\d+)",
            error_pattern=r"9(\d*).*",
            reply_format="01A{value:+09.3f}",
            error_format="9{code}",
        ),
        IndicatorProtocol(
            name="sylvac",
            baudrate=4800,
            bytesize=7,
            parity="E",
            stopbits=2,
            request=b"?\r",
            terminator=b"\r",
            reply_pattern=r"([+-]\d+\.\d+)",
            error_pattern=r"ERR(\d+)",
            reply_format="{value:+.4f}",
            error_format="ERR{code}",
        ),
        IndicatorProtocol(
            name="mahr",
            baudrate=9600,
            bytesize=7,
            parity="E",
            stopbits=2,
            request=b"?\r",
            terminator=b"\r\n",
            reply_pattern=r"([+-]?\d+\.\d+) mm",
            reply_format="{value:.4f} mm",
        ),
        # generic: a neutral starting point meant to be overridden from the config.
        IndicatorProtocol(
            name="generic",
            baudrate=9600,
            bytesize=8,
            parity="N",
            stopbits=1,
            request=b"?\r",
            terminator=b"\r",
            reply_pattern=r"\s*([+-]?\d+(?:\.\d*)?)\s*(?:mm)?\s*",
            reply_format="{value:+.4f}",
        ),
    )
}


def make_protocol(name: str, overrides: Mapping[str, Any] | None = None) -> IndicatorProtocol:
    """A built-in protocol, with fields replaced from a config table.

    The result is validated as a whole (unknown fields, a reply pattern without
    its group, formats contradicting patterns are errors: pydantic's
    ``ValidationError``, a ``ValueError``). Strings given for byte fields are
    encoded as UTF-8, so TOML's ``request = "?\\r"`` works. Overriding a pattern
    without its format drops the built-in's format (the simulator then needs
    one restated to impersonate that gauge).
    """
    try:
        base = BUILTIN_PROTOCOLS[name]
    except KeyError:
        known = ", ".join(sorted(BUILTIN_PROTOCOLS))
        raise ValueError(f"unknown indicator protocol {name!r} (known: {known})") from None
    if not overrides:
        return base
    fields = {**base.model_dump(), **dict(overrides)}
    # A built-in's formats describe the built-in's grammar; once the config
    # replaces a pattern they would contradict it, so they go unless restated.
    for pattern, fmt in (("reply_pattern", "reply_format"), ("error_pattern", "error_format")):
        if pattern in overrides and fmt not in overrides:
            fields[fmt] = None
    return IndicatorProtocol.model_validate(fields)


class ReplyParser:
    """One protocol's reply grammar, compiled once: a run parses a reply at every
    reading of every gauge. :meth:`parse` turns a line (its terminator removed)
    into mm, or raises :class:`~drivers.device_errors.IndicatorReplyError` naming
    ``device`` for a gauge's error reply or anything the grammar does not match.
    """

    def __init__(self, protocol: IndicatorProtocol) -> None:
        self._reply_re = re.compile(protocol.reply_pattern)
        self._error_re = (
            re.compile(protocol.error_pattern) if protocol.error_pattern else None
        )
        self._mm_per_unit = protocol.mm_per_unit

    def parse(self, raw: bytes, device: str) -> float:
        try:
            line = raw.decode("ascii")
        except UnicodeDecodeError:
            raise IndicatorReplyError(device, f"garbled reply {raw!r}") from None
        m = self._reply_re.fullmatch(line)
        if m is not None:
            try:
                return float(m.group(1)) * self._mm_per_unit
            except ValueError:
                raise IndicatorReplyError(device, f"garbled reply {raw!r}") from None
        if self._error_re is not None:
            e = self._error_re.fullmatch(line)
            if e is not None:
                code = e.group(1) if e.re.groups else ""
                raise IndicatorReplyError(device, f"gauge error {code or '?'} (reply {raw!r})")
        raise IndicatorReplyError(device, f"garbled reply {raw!r}")
