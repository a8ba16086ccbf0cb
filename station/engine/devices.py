"""Opening the station's devices from its config: the axis controller and the dial
indicators a run uses, with the station's retry policy."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from drivers.base import AxisController, Gauges
from station.config import StationConfig
from station.errors import BadInput

if TYPE_CHECKING:
    from drivers.indicators import IndicatorGroup, SerialIndicator
    from drivers.sim.station import VirtualStation

# Attempts after the first, per request, for the controller and each gauge. A run
# makes ~1000 controller requests and ~600 readings: on a bus where one request in
# seven fails (bench/soak.py: 5 % lost, 5 % garbled, 5 % busy) four attempts run
# out about once every two or three runs (0.14^4 x 1000), six once in a hundred
# (0.14^6 x 1000). The price: a dead device is declared after six timeouts, not four.
DEVICE_RETRIES = 5


@dataclass
class Devices:
    """What a run moves and reads; ``stack`` closes them. ``station``: the virtual
    station whose servers they talk to, when simulated."""

    controller: AxisController
    indicators: Gauges
    station: VirtualStation | None = None
    stack: ExitStack = field(default_factory=ExitStack)

    def close(self) -> None:
        self.stack.close()


def build_controller(config: StationConfig, on_event: Callable[[dict[str, object]], None] | None
                     ) -> AxisController:
    from drivers.axes import ModbusAxisController

    c = config.controller
    try:
        controller = ModbusAxisController(
            transport=c.transport, host=c.host, port=c.port, device_id=c.device_id,
            profile=c.profile,
            overrides={name: {"address": addr} for name, addr in c.registers.items()} or None,
            timeout_s=c.timeout_s, retries=DEVICE_RETRIES, baudrate=c.baudrate,
            on_event=on_event, acceleration_mm_s2=c.accel_mm_s2, reconnect_s=c.reconnect_s)
    except ValueError as exc:  # an unknown profile or a bad register override
        raise BadInput(f"controller: {exc}") from None
    if controller.map.has_role("OFFSET"):
        if c.offsets is not None:
            controller.close()
            raise BadInput(f"controller.offsets: the drive holds its own zero offsets (map "
                           f"{controller.map.name!r} has OFFSET registers): remove the line")
        return controller.connect()
    # No Modbus-writable zero offset: the station holds them (drivers.held_offsets).
    from drivers.held_offsets import HeldOffsets

    return HeldOffsets(controller.connect(), c.offsets)


def build_indicators(config: StationConfig, names: list[str] | None,
                     on_event: Callable[[dict[str, object]], None] | None) -> IndicatorGroup:
    from drivers.indicator_protocols import make_protocol
    from drivers.indicators import IndicatorGroup, SerialIndicator

    opened: list[SerialIndicator] = []
    try:
        for ind in config.indicators:
            if names is not None and ind.name not in names:
                continue
            overrides: dict[str, object] = {}
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
                                          on_event=on_event, reopen_s=ind.reopen_s))
        return IndicatorGroup(opened)
    except BaseException:
        for each in opened:
            each.close()
        raise


def open_devices(config: StationConfig, on_event: Callable[[dict[str, object]], None] | None,
                 station: VirtualStation | None = None) -> Devices:
    stack = ExitStack()
    try:
        controller = build_controller(config, on_event)
        stack.callback(controller.close)
        # the setups' gauges and the station's own joint test's
        first = config.indicators[0].name
        used = sorted({n for s in config.setups for n in s.indicators}
                      | {config.joints.gauge_of(a, first) for a in config.joints.station_test})
        indicators = build_indicators(config, used, on_event)
        stack.callback(indicators.close)
    except BaseException:
        stack.close()
        raise
    return Devices(controller, indicators, station, stack)
