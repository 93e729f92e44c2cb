"""Rules every network face of the tracker applies to its clients (pure asyncio + stdlib).

The operator page uses this module; every other service that accepts connections
(a field page, a Modbus/TCP gateway, a Foxglove bridge) must use it too, so the same
hostile client meets the same limits everywhere:

- :func:`parse_json`: a request body -> a JSON value with bounded size and nesting
  depth, no ``NaN``/``Infinity``, UTF-8 only; anything else is :class:`BadInput`
  with a message for the client (never a ``RecursionError``).
- :class:`ConnectionGuard`: wraps the server's protocol factory
  (``loop.create_server(guard.wrap(factory), ...)``). A connection is refused when
  its address already holds ``max_connections_per_address``; when all
  ``max_connections`` are taken, the oldest idle connection of the address holding
  the most is closed to make room (a flood from a few addresses cannot keep a new
  client out). A message (an HTTP request head, a Modbus frame) must be complete
  within ``header_timeout`` of its first byte (slowloris), and a connection with no
  message in work is closed after ``idle_timeout`` of silence. The application tells
  the guard when a message is in work (:meth:`ConnectionGuard.busy` /
  :meth:`~ConnectionGuard.idle`); no timer runs meanwhile (its own time-outs apply).
- :class:`StreamSlots`: long-lived streams (Server-Sent Events, websocket
  subscriptions): at most ``per_address`` per address (a new one ends the same
  address's oldest) and ``total`` in all (a new one ends the oldest stream of the
  address holding the most), so a page that reconnects always gets its stream.
- :class:`OneLineLog`: a refusal is logged as one line, at most one line per kind
  per ``interval`` [s] (the rest are counted and summarised), never a traceback.
- :func:`local_networks`: the subnets of this machine's interfaces (for "trusted
  segment" rules such as the operator page's login limit).

Times are ``time.monotonic()`` / loop seconds.
"""
from __future__ import annotations

import asyncio
import ipaddress
import json
import logging
import socket
import struct
import time
from dataclasses import dataclass, field
from typing import Any, Callable


class BadInput(ValueError):
    """A request the service refuses (message for the client, one line)."""


# --------------------------------------------------------------------------------------- JSON
def json_depth_error(raw: str, max_depth: int) -> str | None:
    """None when the JSON text ``raw`` nests arrays/objects at most ``max_depth`` deep
    (brackets inside strings ignored), else the reason. Linear, no recursion."""
    depth, in_str, esc = 0, False, False
    for ch in raw:
        if in_str:
            if esc:
                esc = False
            elif ch == '\\':
                esc = True
            elif ch == '"':
                in_str = False
        elif ch == '"':
            in_str = True
        elif ch in '[{':
            depth += 1
            if depth > max_depth:
                return f'nested deeper than {max_depth} levels'
        elif ch in ']}':
            depth -= 1
    return None


def _no_constant(name: str):
    raise ValueError(f'{name} is not a JSON number')


def parse_json(raw: bytes, *, max_bytes: int, max_depth: int) -> Any:
    """A request body -> its JSON value; :class:`BadInput` when it is larger than
    ``max_bytes``, not UTF-8, not JSON, nested deeper than ``max_depth``, or uses
    ``NaN``/``Infinity`` (not JSON). An empty body is ``None``."""
    if len(raw) > max_bytes:
        raise BadInput(f'request body too large ({len(raw)} bytes > {max_bytes})')
    try:
        text = raw.decode('utf-8')
    except UnicodeDecodeError:
        raise BadInput('the request body is not valid JSON (not UTF-8 text)') from None
    if not text.strip():
        return None
    why = json_depth_error(text, max_depth)
    if why:
        raise BadInput(f'the request body is refused: JSON {why}')
    try:
        return json.loads(text, parse_constant=_no_constant)
    except (ValueError, RecursionError) as exc:
        first = str(exc).splitlines()[0][:120] if str(exc) else exc.__class__.__name__
        raise BadInput(f'the request body is not valid JSON ({first})') from None


# ---------------------------------------------------------------------------------- logging
class OneLineLog:
    """Rate-limited one-line reports: the first of each ``kind`` at once, then at
    most one line per ``interval`` [s] with the number left out since."""

    def __init__(self, sink: Callable[[str, str], None], interval: float = 10.0,
                 clock: Callable[[], float] = time.monotonic):
        self.sink, self.interval, self.clock = sink, float(interval), clock
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}
        self.counts: dict[str, int] = {}

    def report(self, kind: str, text: str, level: str = 'warn') -> bool:
        """Count one event of ``kind``; log ``text`` (first line only, at most 300
        characters) unless one of this kind was logged less than ``interval`` ago.
        True when a line was written."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        now = self.clock()
        last = self._last.get(kind)
        if last is not None and now - last < self.interval:
            self._held[kind] = self._held.get(kind, 0) + 1
            return False
        held = self._held.pop(kind, 0)
        self._last[kind] = now
        line = (text.splitlines()[0] if text else kind)[:300]
        if held:
            line += f' (and {held} more {kind} in the last {self.interval:.0f} s)'
        self.sink(level, line)
        return True


class OneLineLogger(logging.Logger):
    """A :class:`logging.Logger` whose every record becomes one rate-limited line of a
    :class:`OneLineLog` (kind ``name``): hand it to a library (aiohttp's ``logger=``)
    that would otherwise print a traceback per malformed request."""

    def __init__(self, name: str, log: OneLineLog):
        super().__init__(name)
        self.log = log

    def handle(self, record: logging.LogRecord) -> None:  # noqa: D401 - logging API
        try:
            text = record.getMessage()
        except Exception:  # noqa: BLE001 - a bad format string must not raise here
            text = str(record.msg)
        exc = record.exc_info[1] if record.exc_info else None
        if exc is not None:
            msg = getattr(exc, 'message', None)
            lines = [ln.strip() for ln in str(msg if isinstance(msg, str) and msg else exc).splitlines()]
            detail = next((ln for ln in lines if ln), '')[:160]
            text += f': {exc.__class__.__name__}' + (f': {detail}' if detail else '')
        self.log.report(self.name, text, 'warn')

    def isEnabledFor(self, level: int) -> bool:  # noqa: N802 - logging API
        return level >= logging.INFO or level == logging.DEBUG   # debug records are counted too


# ------------------------------------------------------------------------------ connections
@dataclass(frozen=True)
class Limits:
    """Per-service client limits (units in brackets)."""

    max_connections_per_address: int = 16     # [-]
    max_connections: int = 128                # [-]
    header_timeout: float = 10.0              # [s] a message must be complete within this of its first byte
    idle_timeout: float = 60.0                # [s] a connection with nothing in work is closed after this silence


def limit_params(defaults: Limits = Limits()) -> tuple:
    """The :class:`Limits` of a service as its node's parameters (read-only), with one
    description for every network face; :func:`limits_from` reads them back."""
    from .params import ParamSpec
    d = defaults
    return (
        ParamSpec('max_connections_per_address', d.max_connections_per_address,
                  'Open connections one client address may hold; more are refused [-]', '-', 1, 1000,
                  read_only=True),
        ParamSpec('max_connections', d.max_connections,
                  'Open connections in all; when full, the oldest idle connection of the address '
                  'holding the most is closed for a new one [-]', '-', 2, 10000, read_only=True),
        ParamSpec('header_timeout', d.header_timeout,
                  'A request head must be complete within this time of its first byte, else the '
                  'connection is closed (slow clients) [s]', 's', 0.5, 120.0, read_only=True),
        ParamSpec('idle_timeout', d.idle_timeout,
                  'A connection with no request for this long is closed [s]', 's', 1.0, 3600.0,
                  read_only=True),
    )


def limits_from(cfg: dict) -> Limits:
    """The :class:`Limits` of a node's parameters (:func:`limit_params`)."""
    return Limits(int(cfg['max_connections_per_address']), int(cfg['max_connections']),
                  float(cfg['header_timeout']), float(cfg['idle_timeout']))


@dataclass(eq=False)
class _Conn:
    addr: str
    transport: asyncio.BaseTransport
    since: float                  # last time it became idle (or opened)
    first_byte: float | None = None
    busy: int = 0


def peer_address(transport: asyncio.BaseTransport | None) -> str:
    """The client's IP address of a transport ('?' when unknown)."""
    peer = transport.get_extra_info('peername') if transport is not None else None
    if isinstance(peer, (tuple, list)) and peer:
        return str(peer[0])
    return '?'


class _Guarded(asyncio.Protocol):
    """Forwards everything to the inner protocol; tells the guard about traffic."""

    def __init__(self, guard: 'ConnectionGuard', inner: asyncio.BaseProtocol):
        self.guard, self.inner, self.conn = guard, inner, None

    def connection_made(self, transport):
        self.conn = self.guard._admit(transport)
        if self.conn is None:
            transport.abort()
            return
        self.inner.connection_made(transport)

    def data_received(self, data):
        if self.conn is None:
            return
        if not self.conn.busy and self.conn.first_byte is None:
            self.conn.first_byte = self.guard.clock()
        self.inner.data_received(data)

    def eof_received(self):
        return self.inner.eof_received() if self.conn is not None else None

    def connection_lost(self, exc):
        if self.conn is None:
            return
        self.guard._forget(self.conn)
        self.inner.connection_lost(exc)

    def pause_writing(self):
        if self.conn is not None:
            self.inner.pause_writing()

    def resume_writing(self):
        if self.conn is not None:
            self.inner.resume_writing()


class ConnectionGuard:
    """Connection caps and time-outs of one listening service (module docstring)."""

    def __init__(self, limits: Limits, log: OneLineLog, clock: Callable[[], float] = time.monotonic):
        self.limits, self.log, self.clock = limits, log, clock
        self._conns: dict[asyncio.BaseTransport, _Conn] = {}
        self._by_addr: dict[str, int] = {}
        self._sweeper: asyncio.TimerHandle | None = None
        self.counters = {'connections': 0, 'connections_refused': 0, 'connections_evicted': 0,
                         'header_timeouts': 0, 'idle_timeouts': 0}

    def wrap(self, factory: Callable[[], asyncio.BaseProtocol]) -> Callable[[], asyncio.Protocol]:
        """The protocol factory to give ``loop.create_server`` instead of ``factory``."""
        return lambda: _Guarded(self, factory())

    # -- bookkeeping
    def _admit(self, transport) -> _Conn | None:
        addr = peer_address(transport)
        lim = self.limits
        if self._by_addr.get(addr, 0) >= lim.max_connections_per_address:
            self.counters['connections_refused'] += 1
            self.log.report('connection refused',
                            f'connection from {addr} refused: it holds {lim.max_connections_per_address} already')
            return None
        if len(self._conns) >= lim.max_connections and not self._evict_for(addr):
            self.counters['connections_refused'] += 1
            self.log.report('connection refused', f'connection from {addr} refused: '
                                                  f'{lim.max_connections} connections open')
            return None
        conn = _Conn(addr, transport, self.clock())
        self._conns[transport] = conn
        self._by_addr[addr] = self._by_addr.get(addr, 0) + 1
        self.counters['connections'] = len(self._conns)
        self._arm()
        return conn

    def _evict_for(self, addr: str) -> bool:
        """Close the oldest (idle first) connection of the address holding the most;
        False when that is ``addr`` itself (then the newcomer is refused)."""
        heavy = max(self._by_addr, key=lambda a: (self._by_addr[a], a != addr))
        if heavy == addr:
            return False
        idle = [c for c in self._conns.values() if c.addr == heavy and not c.busy]
        victims = idle or [c for c in self._conns.values() if c.addr == heavy]
        victim = min(victims, key=lambda c: c.since)
        self.counters['connections_evicted'] += 1
        self.log.report('connection evicted', f'connection from {victim.addr} closed: all '
                                              f'{self.limits.max_connections} connections taken')
        self._close(victim)
        return True

    def _forget(self, conn: _Conn) -> None:
        if self._conns.pop(conn.transport, None) is None:
            return
        n = self._by_addr.get(conn.addr, 1) - 1
        if n > 0:
            self._by_addr[conn.addr] = n
        else:
            self._by_addr.pop(conn.addr, None)
        self.counters['connections'] = len(self._conns)

    def _close(self, conn: _Conn) -> None:
        self._forget(conn)
        conn.transport.abort()

    # -- what the application tells
    def busy(self, transport) -> None:
        """A complete message arrived on ``transport``: no time-out while it is in work."""
        conn = self._conns.get(transport)
        if conn is not None:
            conn.busy += 1
            conn.first_byte = None

    def idle(self, transport) -> None:
        """The message is answered: the idle time-out runs again."""
        conn = self._conns.get(transport)
        if conn is not None and conn.busy:
            conn.busy -= 1
            if not conn.busy:
                conn.since, conn.first_byte = self.clock(), None

    def connections_of(self, addr: str) -> int:
        return self._by_addr.get(addr, 0)

    def __len__(self) -> int:
        return len(self._conns)

    # -- time-outs
    def _arm(self) -> None:
        if self._sweeper is None:
            period = min(1.0, max(0.05, min(self.limits.header_timeout, self.limits.idle_timeout) / 4))
            self._sweeper = asyncio.get_running_loop().call_later(period, self._sweep)

    def _sweep(self) -> None:
        self._sweeper = None
        now, lim = self.clock(), self.limits
        for conn in list(self._conns.values()):
            if conn.busy:
                continue
            if conn.first_byte is not None and now - conn.first_byte > lim.header_timeout:
                self.counters['header_timeouts'] += 1
                self.log.report('header timeout', f'connection from {conn.addr} closed: request head '
                                                  f'not complete within {lim.header_timeout:g} s')
                self._close(conn)
            elif conn.first_byte is None and now - conn.since > lim.idle_timeout:
                self.counters['idle_timeouts'] += 1
                self._close(conn)
        if self._conns:
            self._arm()

    def close_all(self) -> None:
        for conn in list(self._conns.values()):
            self._close(conn)
        if self._sweeper is not None:
            self._sweeper.cancel()
            self._sweeper = None


# ---------------------------------------------------------------------------------- streams
@dataclass(eq=False)
class StreamSlot:
    addr: str
    opened: float
    on_evict: Callable[[], None]


@dataclass
class StreamSlots:
    """Caps of long-lived streams (module docstring); ``on_evict`` ends a stream."""

    per_address: int = 4
    total: int = 32
    clock: Callable[[], float] = time.monotonic
    evicted: int = 0
    _slots: list = field(default_factory=list)

    def acquire(self, addr: str, on_evict: Callable[[], None]) -> StreamSlot:
        """A slot for a new stream of ``addr``, ending older ones when a cap is reached."""
        mine = [s for s in self._slots if s.addr == addr]
        while len(mine) >= self.per_address:
            self._evict(mine.pop(0))
        if len(self._slots) >= self.total:
            counts: dict[str, int] = {}
            for s in self._slots:
                counts[s.addr] = counts.get(s.addr, 0) + 1
            heavy = max(counts, key=lambda a: counts[a])
            self._evict(next(s for s in self._slots if s.addr == heavy))
        slot = StreamSlot(addr, self.clock(), on_evict)
        self._slots.append(slot)
        return slot

    def _evict(self, slot: StreamSlot) -> None:
        self.release(slot)
        self.evicted += 1
        slot.on_evict()

    def release(self, slot: StreamSlot) -> None:
        try:
            self._slots.remove(slot)
        except ValueError:
            pass

    def count(self, addr: str | None = None) -> int:
        return len(self._slots) if addr is None else sum(1 for s in self._slots if s.addr == addr)


# ---------------------------------------------------------------------------------- networks
SIOCGIFADDR, SIOCGIFNETMASK = 0x8915, 0x891b


def _ipv4_networks() -> list[ipaddress.IPv4Interface]:
    import fcntl
    out = []
    try:
        names = [n for _, n in socket.if_nameindex()]
    except OSError:
        return out
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for name in names:
            req = struct.pack('256s', name.encode()[:15])
            try:
                addr = socket.inet_ntoa(fcntl.ioctl(s.fileno(), SIOCGIFADDR, req)[20:24])
                mask = socket.inet_ntoa(fcntl.ioctl(s.fileno(), SIOCGIFNETMASK, req)[20:24])
            except OSError:
                continue
            out.append(ipaddress.IPv4Interface(f'{addr}/{mask}'))
    return out


def _ipv6_networks() -> list[ipaddress.IPv6Interface]:
    out = []
    try:
        with open('/proc/net/if_inet6', encoding='ascii') as fh:
            for line in fh:
                parts = line.split()
                if len(parts) >= 3:
                    addr = ':'.join(parts[0][i:i + 4] for i in range(0, 32, 4))
                    out.append(ipaddress.IPv6Interface(f'{addr}/{int(parts[2], 16)}'))
    except (OSError, ValueError):
        pass
    return out


def ip_address_error(addr: str) -> str | None:
    """None for a literal IPv4/IPv6 address, else the reason (a host name could
    resolve to every interface)."""
    try:
        ipaddress.ip_address(addr)
    except ValueError:
        return f'{addr!r} is not an IP address (e.g. 127.0.0.1 or 192.168.1.20)'
    return None


def local_networks(bind_address: str) -> list[ipaddress.IPv4Network | ipaddress.IPv6Network]:
    """The subnets of the interface(s) a server bound to ``bind_address`` listens on:
    every interface's for the wildcard (0.0.0.0, ::), else those of the interface
    holding that address; the console's loopback addresses (127.0.0.1, ::1) always.
    Linux (ioctl, /proc); elsewhere only the loopback addresses."""
    nets: list = [ipaddress.ip_network('127.0.0.1/32'), ipaddress.ip_network('::1/128')]
    try:
        bind = ipaddress.ip_address(bind_address)
    except ValueError:
        return nets
    try:
        ifaces = [*_ipv4_networks(), *_ipv6_networks()]
    except Exception:  # noqa: BLE001 - no interface list: loopback only
        ifaces = []
    for iface in ifaces:
        if bind.is_unspecified or iface.ip == bind:
            if iface.network not in nets:
                nets.append(iface.network)
    return nets


def parse_networks(text: str) -> list[ipaddress.IPv4Network | ipaddress.IPv6Network]:
    """``'192.168.1.0/24, 10.0.0.7'`` -> networks; ValueError naming a bad entry."""
    out = []
    for part in (p.strip() for p in text.split(',')):
        if not part:
            continue
        try:
            out.append(ipaddress.ip_network(part, strict=False))
        except ValueError:
            raise ValueError(f'{part!r} is not an IP network (e.g. 192.168.1.0/24 or 10.0.0.7)') from None
    return out


def in_networks(addr: str, nets) -> bool:
    """True when IP address ``addr`` (IPv4-mapped IPv6 included) is in one of ``nets``."""
    try:
        ip = ipaddress.ip_address(addr.split('%', 1)[0])
    except ValueError:
        return False
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    return any(ip.version == n.version and ip in n for n in nets)
