"""A TCP front door with a client allow-list (asyncio, own thread; no rclpy).

The foxglove-sdk WebSocket server has no per-address admission, so it listens on a
free loopback port and this relay listens on the public ``bind_address:port``: a
client whose IP address is not in ``allow`` (IPv4-mapped IPv6 addresses compared as
IPv4), or beyond ``max_connections``, is closed at once and counted; an admitted one
is piped byte for byte to the server.
"""
from __future__ import annotations

import asyncio
import ipaddress
import threading
from collections.abc import Callable


def client_ip(peer) -> str:
    """The peer's address as a plain string (``::ffff:a.b.c.d`` -> ``a.b.c.d``)."""
    if not peer:
        return ''
    ip = ipaddress.ip_address(peer[0].split('%')[0])
    mapped = getattr(ip, 'ipv4_mapped', None)
    return str(mapped or ip)


class AllowRelay:
    """Relay ``bind_address:port`` -> ``127.0.0.1:target_port`` for allowed clients."""

    def __init__(self, bind_address: str, port: int, target_port: int, allow: tuple[str, ...],
                 max_connections: int = 16, log: Callable[[str], None] = print):
        self.bind_address, self.port, self.target_port = bind_address, port, target_port
        self.allow = frozenset(allow)
        self.max_connections = max_connections
        self.log = log
        self.active = 0
        self.counters = {'admitted': 0, 'refused_address': 0, 'refused_full': 0}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: asyncio.base_events.Server | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None

    def start(self, timeout: float = 10.0) -> int:
        """Start; return the bound port. Raises OSError when it cannot bind."""
        self._thread = threading.Thread(target=self._run, name='allow-relay', daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout) or self._error is not None:
            raise OSError(f'cannot listen on {self.bind_address}:{self.port}: {self._error}')
        return self.port

    def _run(self) -> None:
        self._loop = asyncio.new_event_loop()
        try:
            self._server = self._loop.run_until_complete(
                asyncio.start_server(self._client, self.bind_address, self.port))
            self.port = self._server.sockets[0].getsockname()[1]
        except BaseException as exc:  # noqa: BLE001 - reported through start()
            self._error = exc
            self._ready.set()
            self._loop.close()
            return
        self._ready.set()
        try:
            self._loop.run_forever()
        finally:
            self._loop.close()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        ip = client_ip(writer.get_extra_info('peername'))
        if ip not in self.allow or self.active >= self.max_connections:
            key = 'refused_address' if ip not in self.allow else 'refused_full'
            self.counters[key] += 1
            if self.counters[key] <= 10 or self.counters[key] % 100 == 0:
                self.log(f'foxglove client {ip} refused ({key}, {self.counters[key]} so far)')
            writer.close()
            return
        self.active += 1
        self.counters['admitted'] += 1
        try:
            up_r, up_w = await asyncio.open_connection('127.0.0.1', self.target_port)
        except OSError:
            self.active -= 1
            writer.close()
            return
        try:
            await asyncio.gather(_pipe(reader, up_w), _pipe(up_r, writer))
        except asyncio.CancelledError:
            pass                                   # stop(): close both ends below
        finally:
            self.active -= 1
            for w in (writer, up_w):
                w.close()

    def stop(self) -> None:
        if self._loop is None or not self._loop.is_running():
            return

        async def _close():
            self._server.close()
            tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self._loop.stop()
        asyncio.run_coroutine_threadsafe(_close(), self._loop)
        if self._thread is not None:
            self._thread.join(5)


async def _pipe(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
    try:
        while data := await src.read(65536):
            dst.write(data)
            await dst.drain()
    except (ConnectionError, OSError):
        pass
    finally:
        dst.close()
