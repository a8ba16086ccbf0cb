"""The gauges' serial ports checked before anything moves (``orthocal run --plan``,
``run``, ``resume``).

A port that does not exist when the run starts is bad input: a typo in the config,
or an adapter not plugged in. The driver (drivers.indicators) waits ``reopen_s``
for a port that vanishes mid-run, because a ``/dev/serial/by-id`` link comes back
when its adapter is plugged in again; before the run there is nothing to wait for,
and waiting would only turn a one-line refusal into a failed run ten seconds later.
"""

from __future__ import annotations

from drivers.indicators import port_missing
from station.config import StationConfig
from station.errors import BadInput


def check_ports(config: StationConfig) -> None:
    """BadInput naming the first ``[[indicators]]`` entry whose port does not exist.
    Every entry, not only those a setup uses: the config names the device, and a
    port that is not there is as wrong in an unused entry as in a used one."""
    for ind in config.indicators:
        if port_missing(ind.port):
            raise BadInput(f"indicator {ind.name}: port {ind.port} does not exist "
                           "(plug its adapter in, or correct [[indicators]] port)")
