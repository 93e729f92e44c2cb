"""The Modbus TCP server of the gateway (pymodbus, own thread; no rclpy).

One Modbus unit per collector (unit id k+1 for the k-th), each a SunSpec device
(:mod:`sslfr_gateway.sunspec`) in holding registers from 40000. Reads are answered
from the latest image the node gave (:meth:`ModbusGateway.set_image`); writes go
through the write allow-list (client IP addresses; empty: every write is refused
with ILLEGAL_FUNCTION), then :func:`sunspec.decode_write`, then the node's
``command(unit_index, tracker_index_or_None, mode)`` which returns a
``concurrent.futures.Future`` of ``(accepted, message)`` (the planner's answer):
refused -> DEVICE_FAILURE.

Hardening: at most ``max_per_address`` connections from one IP address (more are
closed at once); when all ``max_connections`` are taken, a new connection closes the
least recently active one of the address holding the most (:func:`evict_choice`); a
connection idle for ``idle_timeout`` seconds is closed, and one whose request has not
arrived whole within ``frame_timeout`` seconds of its first byte (slowloris); pymodbus bounds a request's buffer (516 bytes) and answers a
malformed request with an exception or drops it. Every refusal is counted.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import contextvars
import functools
import logging
import threading
import time
from collections.abc import Callable

import pymodbus.logging
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator import DataType, SimData, SimDevice

from sslfr_common.netguard import OneLineLog, OneLineLogger

from . import sunspec

_PEER: contextvars.ContextVar[str] = contextvars.ContextVar('modbus_peer', default='')
_BIT_FUNCTIONS = frozenset({1, 2, 5, 15})


def evict_choice(conns: list[tuple[object, str, float]]):
    """The connection to close when every slot is taken: of ``(conn, address, last
    activity [s])``, the least recently active one of the address holding the most
    connections (a flood from a few addresses cannot keep a new client out)."""
    if not conns:
        return None
    held: dict[str, int] = {}
    for _, ip, _ in conns:
        held[ip] = held.get(ip, 0) + 1
    top = max(held, key=lambda ip: held[ip])
    return min((c for c in conns if c[1] == top), key=lambda c: c[2])[0]


class _LibraryLog(OneLineLogger):
    """pymodbus' own warnings and errors (one per malformed frame) as rate-limited
    one-line reports; its debug dumps stay off (no cost per request)."""

    def isEnabledFor(self, level: int) -> bool:  # noqa: N802 - logging API
        return level >= logging.WARNING


class _Handler(ServerRequestHandler):
    """One client connection: admission by address, its peer for the write check."""

    peer_ip = ''
    last_rx = 0.0
    admitted = False
    partial_since = None         # monotonic time a request began arriving and is not complete

    def connection_made(self, transport) -> None:
        super().connection_made(transport)
        peer = transport.get_extra_info('peername')
        self.peer_ip = str(peer[0]) if peer else ''
        self.last_rx = time.monotonic()
        gw = self.server.gateway
        # the admitted ones only: accepted sockets whose connection_made has not run yet
        # (a burst of connections) have no address yet
        conns = [h for h in self.server.active_connections.values() if h.admitted and h is not self]
        same = sum(1 for h in conns if h.peer_ip == self.peer_ip)
        if same >= gw.max_per_address:
            gw.count('connections_refused')
            self.close()
            return
        if len(conns) >= gw.max_connections:
            victim = evict_choice([(h, h.peer_ip, h.last_rx) for h in conns])
            if victim is not None:
                gw.count('connections_evicted')
                victim.admitted = False
                victim.close()
        self.admitted = True

    def datagram_received(self, data: bytes, addr) -> None:
        self.last_rx = time.monotonic()
        super().datagram_received(data, addr)
        if not self.recv_buffer:
            self.partial_since = None
        elif self.partial_since is None:
            self.partial_since = self.last_rx

    async def handle_request(self):
        token = _PEER.set(self.peer_ip)
        try:
            await super().handle_request()
        finally:
            _PEER.reset(token)


class _Server(ModbusTcpServer):
    def __init__(self, gateway: ModbusGateway, devices: list[SimDevice], address: tuple[str, int]):
        super().__init__(devices, address=address)
        self.gateway = gateway

    def callback_new_connection(self):
        return _Handler(self, self.trace_packet, self.trace_pdu, self.trace_connect)


class ModbusGateway:
    """SunSpec units over Modbus TCP in a background thread."""

    def __init__(self, images: list[list[int]], n_trackers: list[int],
                 command: Callable[[int, int | None, str], concurrent.futures.Future],
                 *, bind_address: str = '127.0.0.1', port: int = 1502,
                 write_allow: tuple[str, ...] = (), max_connections: int = 32,
                 max_per_address: int = 4, idle_timeout: float = 60.0, frame_timeout: float = 5.0,
                 command_timeout: float = 10.0, log: Callable[[str], None] = print):
        self.images = [list(i) for i in images]
        self.n_trackers = list(n_trackers)
        self.command = command
        self.bind_address, self.port = bind_address, port
        self.write_allow = frozenset(write_allow)
        self.max_connections, self.max_per_address = max_connections, max_per_address
        self.idle_timeout, self.command_timeout = idle_timeout, command_timeout
        self.frame_timeout = frame_timeout
        self.oneline = OneLineLog(lambda level, line: log(line))
        self.log = log
        pymodbus.logging.Log._logger = _LibraryLog('pymodbus', self.oneline)  # noqa: SLF001 - its one logger
        self.counters = {'reads': 0, 'writes_accepted': 0, 'writes_refused': 0,
                         'connections_refused': 0, 'connections_evicted': 0, 'idle_closed': 0, 'slow_closed': 0,
                         'unknown_unit': 0}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: _Server | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    def count(self, key: str) -> None:
        self.counters[key] += 1

    def set_image(self, unit_index: int, registers: list[int]) -> None:
        """Replace a unit's image (any thread; same length as the first one)."""
        self.images[unit_index] = list(registers)

    # -- the datastore action -------------------------------------------------------
    async def _action(self, unit_index: int, function_code: int, start_address: int, address: int,
                      count: int, registers: list[int], set_values) -> ExcCodes | None:
        if function_code in _BIT_FUNCTIONS:
            return ExcCodes.ILLEGAL_FUNCTION
        if set_values is None:
            self.counters['reads'] += 1
            image = self.images[unit_index]
            registers[:len(image)] = image
            return None
        peer = _PEER.get()
        if peer not in self.write_allow:
            self.count('writes_refused')
            self.oneline.report('write refused', f'modbus write from {peer or "?"} refused: not in write_allow')
            return ExcCodes.ILLEGAL_FUNCTION
        try:
            commands = sunspec.decode_write(self.n_trackers[unit_index], address, list(set_values))
        except sunspec.WriteRefused as exc:
            self.count('writes_refused')
            self.oneline.report('write refused', f'modbus write from {peer} refused: {exc}')
            return ExcCodes(exc.code)
        for tracker, mode in commands:
            try:
                ok, message = await asyncio.wait_for(
                    asyncio.wrap_future(self.command(unit_index, tracker, mode)), self.command_timeout)
            except (asyncio.TimeoutError, Exception) as exc:  # noqa: BLE001 - any failure refuses
                ok, message = False, f'no answer: {exc!r}'
            self.log(f'modbus write from {peer}: unit {unit_index + 1} mode {mode}: '
                     f'{"accepted" if ok else "refused"} ({message})')
            if not ok:
                self.count('writes_refused')
                return ExcCodes.DEVICE_FAILURE
        self.count('writes_accepted')
        return None

    async def _unknown_unit(self, *args) -> ExcCodes:  # noqa: ARG002 - the action signature
        self.count('unknown_unit')
        return ExcCodes.GATEWAY_NO_RESPONSE

    # -- lifecycle --------------------------------------------------------------------
    def start(self, timeout: float = 10.0) -> int:
        """Start serving; return the bound port. Raises OSError when it cannot bind."""
        self._thread = threading.Thread(target=self._run, name='modbus', daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise OSError('modbus server did not start')
        if self._error is not None:
            raise OSError(f'cannot serve Modbus on {self.bind_address}:{self.port}: {self._error}')
        return self.port

    def _run(self) -> None:
        self._loop = asyncio.new_event_loop()
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._serve())
        except BaseException as exc:  # noqa: BLE001 - reported through start()
            self._error = exc
            self._ready.set()
        finally:
            self._loop.close()

    async def _serve(self) -> None:
        devices = [SimDevice(id=k + 1, simdata=[SimData(sunspec.BASE, values=list(img),
                                                        datatype=DataType.REGISTERS)],
                             action=functools.partial(self._action, k))
                   for k, img in enumerate(self.images)]
        # unit 0 / an unknown unit id: the same address range, answered 0x0B (no such target)
        devices.append(SimDevice(id=0, simdata=[SimData(sunspec.BASE, values=[0] * len(self.images[0]),
                                                        datatype=DataType.REGISTERS)],
                                 action=self._unknown_unit))
        self._server = _Server(self, devices, (self.bind_address, self.port))
        await self._server.serve_forever(background=True)
        sock = self._server.transport.sockets[0]
        self.port = sock.getsockname()[1]
        self._ready.set()
        while not self._server.serving.done():
            now = time.monotonic()
            for h in list(self._server.active_connections.values()):
                partial = getattr(h, 'partial_since', None)
                if partial is not None and now - partial > self.frame_timeout:
                    self.count('slow_closed')
                    h.close()
                elif now - getattr(h, 'last_rx', now) > self.idle_timeout:
                    self.count('idle_closed')
                    h.close()
            await asyncio.wait([self._server.serving], timeout=1.0)

    def stop(self) -> None:
        if self._loop is not None and self._server is not None and self._loop.is_running():
            asyncio.run_coroutine_threadsafe(self._server.shutdown(), self._loop).result(5)
        if self._thread is not None:
            self._thread.join(5)
