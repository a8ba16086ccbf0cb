"""A simulated axis controller: a real pymodbus server serving a register map
(``register_map``, default "orthocal-generic", docs/design.md) for a
:class:`~drivers.sim.machine.VirtualOrthoglide`, with fault injection. What the
registers do (targets, commands, the exception 2/3 rules) is the drive's,
:class:`~drivers.sim.drive.DriveRegisters`, which :class:`SimController` extends
with the transport and the faults.

Transports: Modbus TCP on 127.0.0.1 (port 0 picks a free port, reported by
:attr:`SimController.port`) or Modbus RTU on a pseudo-terminal null-modem
(:class:`~drivers.sim.ptypair.PtyPair`; the client opens
:attr:`SimController.serial_port`). The server runs in a background thread with
its own asyncio loop; ``start()``/``close()`` (or ``with``) leave no thread,
task, socket or pty behind. It answers as every unit id of its map (``device_id``
for registers without one); requests for another get no reply on RTU and
exception 0x0B (gateway: no response) on TCP.

A power cut (``Faults.power_cut_*`` or :meth:`SimController.power_cut`) makes
the controller unreachable for a while (TCP: open connections closed, new ones
refused, as a drive that is off; RTU: silent), then it serves again with HOMED
clear and its counted position lost (the ACTUAL registers jump); a move before
homing (the map's home command) faults with alarm 83, as IAI drives do.

Fault injection: :class:`Faults`, a dataclass whose fields may be changed while
the server runs (``sim.faults.drop_next = 2``); random faults draw from an RNG
seeded with ``seed`` so a run is reproducible. The datastore is pymodbus 3.16's
``SimDevice``, one per unit id, with an ``action`` hook (called before a write is
applied, it can veto it with an exception code); what it cannot express (lost,
late, garbled replies, silence, busy; exception 2 judged from the whole request)
lives in a thin subclass of pymodbus's request handler.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import socket
import struct
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerType
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler

from drivers.map_files import builtin_maps
from drivers.registers import GENERIC, RegisterMap
from drivers.sim.drive import DriveRegisters
from drivers.sim.faults import Faults, SimStats
from drivers.sim.machine import VirtualOrthoglide

if TYPE_CHECKING:  # pseudo-terminals (tty) are loaded only by an RTU simulator
    from drivers.sim.ptypair import PtyPair

_pymodbus_log = logging.getLogger("pymodbus")
if _pymodbus_log.level == logging.NOTSET:
    # pymodbus logs every dropped frame as an error; the operator console is ours.
    _pymodbus_log.setLevel(logging.CRITICAL)

_WRITE_CODES = {5, 6, 15, 16, 22, 23}  # counted in SimStats.writes


class _Handler(ServerRequestHandler):
    """pymodbus's per-connection handler with the faults a datastore cannot express."""

    sim: SimController

    async def handle_request(self) -> None:
        pdu = self.last_pdu
        if pdu is None:
            return
        verdict = self.sim._admit(pdu)
        if verdict == "ignore":
            return
        if verdict in ("busy", "gateway"):
            code = ExcCodes.DEVICE_BUSY if verdict == "busy" else ExcCodes.GATEWAY_NO_RESPONSE
            self._exception(pdu, code)
            return
        # Outside the map (device, table, address): exception 2 before the datastore.
        if (refused := self.sim.refusal(pdu.dev_id, pdu)) is not None:
            self._exception(pdu, refused)
            return
        await super().handle_request()

    def _exception(self, pdu: ModbusPDU, code: ExcCodes) -> None:
        response = ExceptionResponse(pdu.function_code, code)
        response.transaction_id = pdu.transaction_id
        response.dev_id = pdu.dev_id
        self.server_send(response, self.last_addr)

    def server_send(self, pdu: ModbusPDU | None, addr: tuple | None) -> None:
        if not pdu:
            return
        fate, delay = self.sim._reply_fate()
        if fate == "drop":
            return
        if fate == "disconnect":
            self.close()
            return
        packet = self.framer.buildFrame(pdu)
        if fate == "garble":
            if self.sim.transport == "rtu":
                packet = packet[:-1] + bytes([packet[-1] ^ 0xFF])  # CRC no longer matches
            else:
                packet = packet[:2] + b"\xde\xad" + packet[4:]  # protocol id must be 0
        if delay > 0:
            self.loop.call_later(delay, self._deliver, packet, addr)
        else:
            self._deliver(packet, addr)

    def _deliver(self, packet: bytes, addr: tuple | None) -> None:
        if self.transport:
            self.send(packet, addr)


class _SimConnections:
    """Gives every new connection of a pymodbus server our fault-aware handler."""

    sim: SimController
    # the server's (ModbusBaseServer), beside which this mixin is inherited
    trace_packet: Callable[[bool, bytes], bytes] | None
    trace_pdu: Callable[[bool, ModbusPDU], ModbusPDU] | None
    trace_connect: Callable[[bool], None] | None

    def callback_new_connection(self) -> _Handler:
        handler = _Handler(self, self.trace_packet, self.trace_pdu, self.trace_connect)
        handler.sim = self.sim
        with self.sim._lock:
            self.sim.stats.connections += 1
        return handler


class _SimTcpServer(_SimConnections, ModbusTcpServer):
    pass


class _SimSerialServer(_SimConnections, ModbusSerialServer):
    pass


class SimController(DriveRegisters):
    """A Modbus server for a virtual Orthoglide.

    ``SimController(machine, transport="tcp", register_map=GENERIC)`` then ``start()``;
    connect a client to ``("127.0.0.1", sim.port)`` (TCP) or ``sim.serial_port``
    (RTU), or pass ``**sim.client_kwargs()`` to :class:`drivers.axes.ModbusAxisController`.
    """

    def __init__(
        self,
        machine: VirtualOrthoglide | None = None,
        *,
        transport: str = "tcp",
        host: str = "127.0.0.1",
        port: int = 0,
        device_id: int = 1,
        faults: Faults | None = None,
        seed: int | None = 0,
        soft_limits: tuple[Sequence[float], Sequence[float]] | None = None,
        max_offset_mm: float = 50.0,
        baudrate: int = 115200,
        soft_limit_registers: bool | tuple[Sequence[float], Sequence[float]] = True,
        register_map: RegisterMap = GENERIC,
    ) -> None:
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"transport must be 'tcp' or 'rtu', got {transport!r}")
        super().__init__(machine, register_map, soft_limits=soft_limits,
                         max_offset_mm=max_offset_mm,
                         soft_limit_registers=soft_limit_registers, device_id=device_id)
        self.transport = transport
        self.host = host
        self.faults = faults or Faults()
        self.stats = SimStats()
        self.baudrate = baudrate
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._requested_port = port
        self._port: int | None = None
        self._pty: PtyPair | None = None
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._moves_done = 0
        self._cut_moves_done = 0
        self._powered = True
        self._server: _SimTcpServer | _SimSerialServer | None = None
        self._tasks: set[asyncio.Task] = set()
        self._estop_seen = False

    # --- lifecycle --------------------------------------------------------------------------

    def start(self) -> SimController:
        if self._thread is not None:
            return self
        if self.transport == "rtu":
            from drivers.sim.ptypair import PtyPair

            self._pty = PtyPair(name="orthocal-sim-pty").open()
        self._ready.clear()
        self._thread = threading.Thread(target=self._run, name=f"orthocal-sim-{self.transport}",
                                        daemon=True)
        self._thread.start()
        if not self._ready.wait(10.0):
            self.close()
            raise RuntimeError("simulated controller did not start within 10 s")
        if self._error is not None:
            error = self._error
            self.close()
            raise RuntimeError(f"simulated controller failed to start: {error}") from error
        return self

    def close(self) -> None:
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None:
            with contextlib.suppress(RuntimeError):  # loop already gone
                loop.call_soon_threadsafe(stop.set)
        if self._thread is not None:
            self._thread.join(timeout=10.0)
            self._thread = None
        self._loop = self._stop = None
        if self._pty is not None:
            self._pty.close()
            self._pty = None

    def __enter__(self) -> SimController:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def port(self) -> int:
        """The bound TCP port (after start())."""
        if self.transport != "tcp" or self._port is None:
            raise RuntimeError("no TCP port: not started or not a TCP simulator")
        return self._port

    @property
    def serial_port(self) -> str:
        """The serial device a client opens (RTU, after start())."""
        if self._pty is None:
            raise RuntimeError("no serial port: not started or not an RTU simulator")
        return self._pty.path_b

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}" if self.transport == "tcp" else self.serial_port

    def client_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ModbusAxisController / the [controller] config table
        (``profile``: the map's name if it is a built-in profile, else the map)."""
        port: int | str = self.port if self.transport == "tcp" else self.serial_port
        builtin = builtin_maps().get(self.map.name) == self.map
        kw: dict[str, Any] = {"transport": self.transport, "host": self.host, "port": port,
                              "device_id": self.device_id,
                              "profile": self.map.name if builtin else self.map}
        if self.transport == "rtu":
            kw["baudrate"] = self.baudrate
        return kw

    def _run(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as exc:  # report to start(); the thread must not die silently
            self._error = exc
        finally:
            self._ready.set()

    def _new_server(self, port: int) -> _SimTcpServer | _SimSerialServer:
        devices = self.sim_devices()
        server: _SimTcpServer | _SimSerialServer
        if self.transport == "tcp":
            server = _SimTcpServer(devices, address=(self.host, port))
        else:
            assert self._pty is not None
            server = _SimSerialServer(devices, framer=FramerType.RTU, port=self._pty.path_a,
                                      baudrate=self.baudrate, timeout=1.0, reconnect_delay=0.0)
        server.sim = self
        return server

    async def _serve(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        self._server = self._new_server(self._requested_port)
        try:
            await self._server.serve_forever(background=True)
            if self.transport == "tcp":
                # pymodbus types transport as a BaseTransport; a listener's is the
                # asyncio.Server its loop.create_server returned
                listener = self._server.transport
                self._port = listener.sockets[0].getsockname()[1]  # type: ignore[attr-defined]
            self._ready.set()
            await self._stop.wait()
        finally:
            for task in list(self._tasks):
                task.cancel()
            if self._tasks:
                await asyncio.gather(*self._tasks, return_exceptions=True)
            if self._server is not None:
                await _set_up_accepted()
                await self._server.shutdown()
            # Let the loop run the transports' connection_lost callbacks (socket close).
            for _ in range(3):
                await asyncio.sleep(0)

    # --- power --------------------------------------------------------------------------------

    def power_cut(self, off_s: float = 3.0, count_mm: float | Sequence[float] | None = 0.0,
                  delay_s: float = 0.0, lose_reference: bool = True) -> None:
        """Test hook: cut the power ``delay_s`` from now for ``off_s`` (see
        :class:`Faults`, ``power_cut_*``). Thread-safe; returns at once."""
        loop = self._loop
        if loop is None:
            raise RuntimeError("simulated controller not started")
        loop.call_soon_threadsafe(self._spawn_cut, off_s, count_mm, delay_s, lose_reference)

    @property
    def powered(self) -> bool:
        return self._powered

    def _spawn_cut(self, off_s: float, count_mm: float | Sequence[float] | None,
                   delay_s: float, lose_reference: bool = True) -> None:
        task = asyncio.ensure_future(self._power_cut(off_s, count_mm, delay_s, lose_reference))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _power_cut(self, off_s: float, count_mm: float | Sequence[float] | None,
                         delay_s: float, lose_reference: bool) -> None:
        if delay_s > 0:
            await asyncio.sleep(delay_s)
        count = None if count_mm is None else np.broadcast_to(
            np.asarray(count_mm, dtype=float), (3,))
        with self._lock:
            self._powered = False
            self.stats.power_cuts += 1
        # The carriages stop where they are; the count and HOMED are lost at once
        # (nobody can read them until the power is back).
        if lose_reference:
            self.machine.power_cycle(count, seed=self._rng.randrange(2**31))
        if self.transport == "tcp" and self._server is not None:
            server, self._server = self._server, None
            for conn in list(server.active_connections.values()):
                _reset(conn)
            await server.shutdown()  # new connections refused
        assert self._stop is not None
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._stop.wait(), off_s)
        if self._stop.is_set():
            return
        if self.transport == "tcp":
            self.power_up()
            server = self._new_server(self.port)
            await server.serve_forever(background=True)
            self._server = server
        with self._lock:
            self._powered = True

    # --- what the drive tells ----------------------------------------------------------------

    def refused_write(self) -> None:
        with self._lock:
            self.stats.refused += 1

    def commanded(self, code: int) -> None:
        with self._lock:
            self.stats.commands[code] = self.stats.commands.get(code, 0) + 1

    def moved(self, duration_s: float) -> None:
        """The faults counted in moves: an alarm, a power cut, halfway through one."""
        m = self.machine
        with self._lock:
            n = self.faults.alarm_after_moves
            if n is not None:
                if self._moves_done >= n:
                    self.faults.alarm_after_moves = None
                    m.raise_alarm(self.faults.alarm_code, delay_s=duration_s / 2)
                else:
                    self._moves_done += 1
            n = self.faults.power_cut_after_moves
            if n is not None:
                if self._cut_moves_done >= n:
                    self.faults.power_cut_after_moves = None
                    self._cut_moves_done = 0
                    f = self.faults
                    # halfway in real seconds (the machine's clock may run faster);
                    # power_cut_s is real time: how long the station cannot reach it
                    self._spawn_cut(f.power_cut_s, f.power_cut_count_mm,
                                    duration_s / 2 / m.time_scale,
                                    f.power_cut_loses_reference)
                else:
                    self._cut_moves_done += 1

    # --- faults ---------------------------------------------------------------------------------

    def _admit(self, pdu: ModbusPDU) -> str:
        """What to do with a request: 'ignore', 'busy', 'gateway' or 'serve'."""
        with self._lock:
            self.stats.requests += 1
            if pdu.function_code in _WRITE_CODES:
                self.stats.writes += 1
            f = self.faults
            if f.estop != self._estop_seen:
                self._estop_seen = f.estop
                self.machine.set_estop(f.estop)
            if f.silent or not self._powered:
                self.stats.ignored += 1
                return "ignore"
            if pdu.dev_id not in self.devices:
                self.stats.ignored += 1
                return "ignore" if self.transport == "rtu" else "gateway"
            if f.busy_next > 0 or (f.busy_rate > 0 and self._rng.random() < f.busy_rate):
                f.busy_next = max(0, f.busy_next - 1)
                self.stats.busy += 1
                return "busy"
            return "serve"

    def _reply_fate(self) -> tuple[str, float]:
        """What happens to a reply: ('ok' | 'drop' | 'garble' | 'disconnect', delay)."""
        with self._lock:
            f = self.faults
            self.stats.replies += 1
            if f.drop_next > 0 or (f.drop_rate > 0 and self._rng.random() < f.drop_rate):
                f.drop_next = max(0, f.drop_next - 1)
                self.stats.dropped += 1
                return "drop", 0.0
            if self.transport == "tcp" and f.disconnect_next > 0:
                f.disconnect_next -= 1
                self.stats.disconnects += 1
                return "disconnect", 0.0
            fate = "ok"
            if f.garble_next > 0 or (f.garble_rate > 0 and self._rng.random() < f.garble_rate):
                f.garble_next = max(0, f.garble_next - 1)
                self.stats.garbled += 1
                fate = "garble"
            if f.delay_s > 0:
                self.stats.delayed += 1
            return fate, max(0.0, f.delay_s)


async def _set_up_accepted() -> None:
    """Let every connection the loop has accepted be set up before the server shuts
    down. A client that connected and left while this thread waited for the CPU (a
    loaded machine) is accepted in the same pass of the loop that sets the stop; its
    transport, made by a task of the loop, refuses a listener already closed
    (asyncio's Server._attach) and leaves its socket to the garbage collector: a
    socket behind after close(). Set up, it is one of the connections shutdown()
    closes. No check and shutdown() have a pass of the loop between them, so no
    connection is accepted in between."""
    current = asyncio.current_task()
    for _ in range(10):
        pending = [t for t in asyncio.all_tasks() if t is not current and not t.done()]
        if not pending:
            return
        await asyncio.wait(pending, timeout=1.0)


def _reset(conn: Any) -> None:
    """Drop a TCP connection the way a drive losing power does to its peer: a reset
    (the client's next recv/send raises ConnectionResetError), not a clean close."""
    transport = getattr(conn, "transport", None)
    if transport is None:
        return
    sock = transport.get_extra_info("socket")
    if sock is not None:
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    transport.abort()


__all__ = ["Faults", "SimController", "SimStats"]
