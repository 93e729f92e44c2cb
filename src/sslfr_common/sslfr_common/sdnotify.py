"""The sd_notify protocol, both ends, in plain Python (no libsystemd, no rclpy).

A process proves it is alive by sending datagrams of ``KEY=VALUE`` lines to the
``AF_UNIX`` datagram socket named by ``$NOTIFY_SOCKET`` (sd_notify(3); a name
starting with ``@`` is in the abstract namespace): ``READY=1`` once it is up,
``WATCHDOG=1`` again and again while it works, ``STOPPING=1`` when it begins to stop,
``STATUS=...`` free text. ``$WATCHDOG_USEC`` is the watcher's bound [us] (beat well
within it); ``$WATCHDOG_PID``, when set, names the one process the bound is for.

- :class:`Notifier` is the sending end. Every node process has one
  (:func:`sslfr_common.node.run_nodes` beats from its spin loop); so has ``sslfr up``
  towards systemd (``Type=notify``, ``WatchdogSec=``).
- :class:`NotifyListener` is the receiving end: a socket bound with ``SO_PASSCRED``,
  so every datagram carries the sender's pid from the kernel (as systemd receives
  them). ``sslfr up`` / ``sslfr sim`` and the launch file's watchdog listen on one.

Sending never raises: no listener (not yet bound, gone) costs the beat, not the
process.
"""
from __future__ import annotations

import os
import signal
import socket
import struct
import time
from dataclasses import dataclass

__all__ = ['Notifier', 'NotifyListener', 'Notification', 'beat_period', 'parse']

#: [s] longest interval between two WATCHDOG=1 beats, whatever the bound
MAX_BEAT_PERIOD = 1.0
#: [s] shortest one (a very short bound still does not make every executor turn send)
MIN_BEAT_PERIOD = 0.1
#: asks a node process that stopped beating to write every thread's Python stack to its
#: stderr (faulthandler, registered by sslfr_common.node.run_nodes) before it is killed
STACK_DUMP_SIGNAL = signal.SIGUSR1
_CREDS = struct.Struct('3i')          # struct ucred: pid, uid, gid


def _address(name: str) -> str:
    """sd_notify(3): ``@name`` is ``\\0name`` in the abstract namespace."""
    return '\0' + name[1:] if name.startswith('@') else name


def beat_period(watchdog_s: float | None) -> float | None:
    """Interval [s, steady clock] between two ``WATCHDOG=1`` for a watcher's bound
    ``watchdog_s`` [s]: a quarter of it, within [MIN_BEAT_PERIOD, MAX_BEAT_PERIOD];
    None without a bound (no beats are sent)."""
    if watchdog_s is None:
        return None
    return min(MAX_BEAT_PERIOD, max(MIN_BEAT_PERIOD, watchdog_s / 4.0))


class Notifier:
    """Sends sd_notify messages to ``address`` (None: a notifier that sends nothing).

    :meth:`beat` is meant for every turn of a loop: it costs one ``time.monotonic()``
    and a comparison, and sends ``WATCHDOG=1`` at most every :func:`beat_period` of
    the bound ``watchdog_s`` [s]. ``sent`` and ``failed`` count datagrams.
    """

    __slots__ = ('address', 'watchdog_s', 'period', '_due', '_sock', 'sent', 'failed')

    def __init__(self, address: str | None, watchdog_s: float | None = None) -> None:
        self.address = address or None
        self.watchdog_s = watchdog_s if self.address else None
        self.period = beat_period(self.watchdog_s)
        self._sock = None
        if self.address:
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.setblocking(False)
        # no bound: never due (beat() returns after one comparison)
        self._due = float('inf') if self.period is None else 0.0
        self.sent = 0
        self.failed = 0

    @classmethod
    def from_environ(cls, environ=None, pid: int | None = None) -> 'Notifier':
        """The notifier the environment asks for: ``NOTIFY_SOCKET``, and a beat when
        ``WATCHDOG_USEC`` is a positive integer and ``WATCHDOG_PID`` is unset or this
        process (``pid``, default ``os.getpid()``); otherwise no beat."""
        env = os.environ if environ is None else environ
        watchdog = None
        try:
            usec = int(env.get('WATCHDOG_USEC', '0'))
            wpid = env.get('WATCHDOG_PID', '')
            if usec > 0 and (not wpid or int(wpid) == (os.getpid() if pid is None else pid)):
                watchdog = usec / 1e6
        except ValueError:
            watchdog = None
        return cls(env.get('NOTIFY_SOCKET') or None, watchdog)

    @property
    def enabled(self) -> bool:
        return self._sock is not None

    def notify(self, *fields: str) -> bool:
        """Send ``fields`` (``KEY=VALUE`` each) in one datagram; True when sent."""
        if self._sock is None:
            return False
        try:
            self._sock.sendto('\n'.join(fields).encode(), _address(self.address))
        except OSError:
            self.failed += 1
            return False
        self.sent += 1
        return True

    def beat(self) -> None:
        """``WATCHDOG=1`` when one is due (see the class docstring)."""
        now = time.monotonic()
        if now >= self._due:
            self._due = now + self.period
            self.notify('WATCHDOG=1')

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
            self._due = float('inf')


@dataclass(frozen=True)
class Notification:
    """One datagram: the sender's ``pid`` (from the kernel) and its ``fields``."""

    pid: int
    fields: dict


def parse(data: bytes) -> dict:
    """``KEY=VALUE`` lines -> dict (the last of a repeated key wins; lines without
    ``=`` and undecodable bytes are skipped)."""
    out = {}
    for line in data.decode('utf-8', errors='replace').split('\n'):
        key, eq, value = line.partition('=')
        if eq and key:
            out[key] = value
    return out


class NotifyListener:
    """A bound ``AF_UNIX`` datagram socket at ``path`` (a file path, or ``@name``
    abstract) that receives sd_notify messages with their sender's pid.

    :meth:`receive` never blocks: it returns what has arrived (at most ``limit``
    datagrams). :meth:`fileno` for ``select``. :meth:`close` removes the file.
    """

    def __init__(self, path: str) -> None:
        self.path = str(path)
        self.dropped = 0          # datagrams without credentials (not counted as beats)
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_PASSCRED, 1)
            if not self.path.startswith('@'):
                try:
                    os.unlink(self.path)          # a socket left by a killed predecessor
                except FileNotFoundError:
                    pass
            sock.bind(_address(self.path))
            sock.setblocking(False)
        except OSError:
            sock.close()
            raise
        self._sock = sock

    def fileno(self) -> int:
        return self._sock.fileno()

    def receive(self, limit: int = 1024) -> list[Notification]:
        out = []
        space = socket.CMSG_SPACE(_CREDS.size)
        while len(out) < limit:
            try:
                data, ancillary, _flags, _addr = self._sock.recvmsg(4096, space)
            except (BlockingIOError, InterruptedError):
                break
            pid = None
            for level, kind, payload in ancillary:
                if level == socket.SOL_SOCKET and kind == socket.SCM_CREDENTIALS and len(payload) >= _CREDS.size:
                    pid = _CREDS.unpack_from(payload)[0]
            if not pid:
                self.dropped += 1
                continue
            out.append(Notification(pid, parse(data)))
        return out

    def close(self) -> None:
        if self._sock is None:
            return
        self._sock.close()
        self._sock = None
        if not self.path.startswith('@'):
            try:
                os.unlink(self.path)
            except FileNotFoundError:
                pass

    def __enter__(self) -> 'NotifyListener':
        return self

    def __exit__(self, *exc) -> None:
        self.close()
