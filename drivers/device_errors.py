"""Typed device faults.

Every fault names the device it came from, so the station can print one line
such as ``controller 127.0.0.1:5020: alarm 17`` and exit 1 without a traceback.
"""

from __future__ import annotations


class DeviceError(Exception):
    """A device fault. ``device`` names it (``"controller 127.0.0.1:502"``,
    ``"indicator A (/dev/ttyUSB0)"``); ``transient`` says whether a bounded
    retry may help."""

    transient = False

    def __init__(self, device: str, message: str) -> None:
        self.device = device
        self.message = message
        super().__init__(f"{device}: {message}")


# --- axis controller -----------------------------------------------------------------


class ControllerError(DeviceError):
    """Any fault of the axis controller."""


class ControllerConnectionError(ControllerError):
    """The controller cannot be reached (refused, no route, port missing)."""


class ControllerNotHomed(ControllerError):
    """The controller lost its reference (power cut: HOMED clear, or counted positions
    that jumped); nothing it reports can be used until it is homed again."""


class ControllerTimeout(ControllerError):
    """A request got no reply in time (after the bounded retries)."""

    transient = True


class ControllerBusy(ControllerError):
    """The controller answered 'busy' (Modbus exception 6) after the bounded retries."""

    transient = True


class ExceptionResponse(ControllerError):
    """The controller answered a request with a Modbus exception code."""

    def __init__(self, device: str, message: str, code: int) -> None:
        self.code = code
        super().__init__(device, message)


class TargetRefused(ExceptionResponse):
    """A target was refused (exception 3: outside the soft limits)."""


class AlarmError(ControllerError):
    """The drive is in alarm; ``code`` is its ALARM_CODE."""

    def __init__(self, device: str, message: str, code: int) -> None:
        self.code = code
        super().__init__(device, message)


class EStopError(ControllerError):
    """The emergency stop is engaged."""


class MoveTimeout(ControllerError):
    """A move did not arrive in position within its deadline."""


class ReadbackMismatch(ControllerError):
    """A written value did not read back as written."""


# --- dial indicators -----------------------------------------------------------------


class IndicatorError(DeviceError):
    """Any fault of a dial indicator."""


class IndicatorTimeout(IndicatorError):
    """No (complete) reply within the timeout, after the bounded retries."""

    transient = True


class IndicatorReplyError(IndicatorError):
    """Replies were garbled or the gauge reported an error, after the bounded retries."""

    transient = True


class IndicatorPortError(IndicatorError):
    """The serial port cannot be opened or vanished (unplugged)."""
