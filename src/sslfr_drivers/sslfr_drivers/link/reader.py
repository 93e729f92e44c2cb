"""The one reconnecting reader of the project: a thread that owns a byte transport,
reopens it with back-off after a loss and hands every chunk to a protocol object
(pure Python, no rclpy).

Modelled on pyserial's ``serial/threaded``: :class:`ReaderThread` owns the port
(open, read, write, close, reopen); a :class:`Protocol` only parses what it is given.
Both the board link (:class:`~sslfr_drivers.link.board_link.BoardLink`: frames,
requests, answers) and the raw NMEA stream of a bare GPS module
(:class:`~sslfr_drivers.sensors.source.BoardSource`) run on it, so there is one read
loop and one back-off policy (:class:`Backoff`) for every board.

Protocol calls, all from the reader thread, in this order over a connection::

    connection_made(reader)      port (re)opened
    data_received(data)          every non-empty chunk read
    tick()                       after every read or read time-out (timers, retries)
    connection_lost(exc)         the port failed (exc: the TransportError); the
                                 reader closes it and reopens it with back-off

and ``open_failed(exc)`` after each failed open attempt. ``stop()`` closes the port
without calling the protocol.

The reader sleeps until data arrives or the protocol's next deadline
(``next_tick()``), at most ``read_timeout``: an idle board costs a wake-up per
deadline (a heartbeat, a request's time-out), not a poll every few milliseconds
(issue 16: six readers polling at 50 Hz were a third of the ``hardware`` process's
CPU). Another thread that adds an earlier deadline calls :meth:`ReaderThread.poke`,
which interrupts the read on transports that can be interrupted
(``Transport.interrupt``: pyserial ports and ptys, XBee boards); on the others the
reader keeps waking every :data:`UNINTERRUPTIBLE_WAIT`.
"""
from __future__ import annotations

import logging
import threading
import time

from sslfr_drivers.link.transport import Transport, TransportError

_log = logging.getLogger(__name__)

#: Reopen back-off of every board port [s]: the first retry after BACKOFF_MIN, doubling
#: up to BACKOFF_MAX (a board plugged back is seen within 2 s).
BACKOFF_MIN = 0.1
BACKOFF_MAX = 2.0

#: [s] shortest wait of one read when a deadline is due (no busy loop on a deadline
#: that a tick cannot clear), and the longest on a transport a poke cannot interrupt.
MIN_WAIT = 0.002
UNINTERRUPTIBLE_WAIT = 0.02


class Backoff:
    """Exponential back-off: :meth:`next` gives ``lo``, ``2 lo``, ``4 lo``, ... capped
    at ``hi`` [s]; :meth:`reset` after a success starts again at ``lo``.

    Parameters
    ----------
    lo, hi : float
        First and largest delay [s], ``0 < lo <= hi``.
    """

    def __init__(self, lo: float = BACKOFF_MIN, hi: float = BACKOFF_MAX):
        if not 0.0 < lo <= hi:
            raise ValueError(f'back-off needs 0 < lo <= hi, got lo={lo!r} hi={hi!r}')
        self.lo = float(lo)
        self.hi = float(hi)
        self.delay = self.lo

    def next(self) -> float:
        """The delay to wait now [s]; the following one doubles (up to ``hi``)."""
        d = self.delay
        self.delay = min(d * 2.0, self.hi)
        return d

    def reset(self) -> None:
        """Start again at ``lo`` (call after a success)."""
        self.delay = self.lo


class Protocol:
    """What a :class:`ReaderThread` calls (see the module docstring). Every method
    is optional; this base does nothing."""

    def connection_made(self, reader: 'ReaderThread') -> None:
        """The port was (re)opened."""

    def data_received(self, data: bytes) -> None:
        """``data``: a non-empty chunk read from the port."""

    def tick(self) -> None:
        """After every read or read time-out (at least every ``read_timeout`` s)."""

    def next_tick(self) -> float | None:
        """Seconds until :meth:`tick` next has something to do (0 when overdue);
        None when nothing is timed. Called from the reader thread before each read."""
        return None

    def connection_lost(self, exc: BaseException) -> None:
        """The port failed with ``exc``; it is closed and will be reopened."""

    def open_failed(self, exc: BaseException) -> None:
        """An attempt to open the port failed with ``exc``; retried after back-off."""


class ReaderThread:
    """A thread owning ``transport``: opens it (with :class:`Backoff` while it cannot),
    reads it every ``read_timeout`` [s] and feeds ``protocol``; reopens it after a
    :class:`~sslfr_drivers.link.transport.TransportError`.

    Parameters
    ----------
    transport : Transport
        The port (``transport.make_transport(port)``).
    protocol : Protocol
        The parser (see the module docstring).
    name : str, optional
        Thread name and log prefix.
    read_timeout : float
        Longest wait of one read [s]; the protocol's ``next_tick()`` shortens it.
    backoff : Backoff, optional
        Reopen policy (default ``Backoff()``: 0.1 s doubling to 2 s).

    Counters: ``opens`` (successful opens), :attr:`reconnects` (``opens - 1``),
    ``bytes_received``; ``last_error`` is the text of the last open/read failure.
    """

    def __init__(self, transport: Transport, protocol: Protocol, *, name: str | None = None,
                 read_timeout: float = 0.02, backoff: Backoff | None = None):
        self.transport = transport
        self.protocol = protocol
        self.name = name or getattr(transport, 'name', 'port')
        self._extra = getattr(protocol, 'log_extra', {})      # the protocol's node (log_route)
        self.read_timeout = read_timeout
        self.backoff = backoff or Backoff()
        self.opens = 0
        self.bytes_received = 0
        self.last_error = ''
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._wlock = threading.Lock()
        self._wake_at = 0.0           # [s, monotonic] end of the read under way

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> 'ReaderThread':
        """Start the thread (idempotent; restartable after :meth:`stop`)."""
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name=f'reader-{self.name}',
                                            daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread (joined unless called from it) and close the port."""
        self._stop.set()
        self.transport.interrupt()        # end a read under way now, not at its time-out
        t, self._thread = self._thread, None
        if t is not None and t is not threading.current_thread():
            t.join(timeout=2.0)
        self._close()

    @property
    def connected(self) -> bool:
        """True while the port is open."""
        return self.transport.is_open

    @property
    def reconnects(self) -> int:
        """Times the port was opened again after the first open."""
        return max(0, self.opens - 1)

    def write(self, data: bytes) -> None:
        """Write ``data`` (serialised between threads); raises the transport's
        :class:`~sslfr_drivers.link.transport.TransportError` (or ``TransmitError``)."""
        with self._wlock:
            self.transport.write(data)

    def poke(self, within: float = 0.0) -> None:
        """The protocol has a deadline ``within`` [s] from now: end the read under way
        if it would wait past it (safe from any thread; from the reader thread itself
        nothing is needed: it asks ``next_tick()`` before every read)."""
        if threading.current_thread() is self._thread:
            return
        if time.monotonic() + within < self._wake_at:
            self.transport.interrupt()

    # ------------------------------------------------------------------ the loop
    def _close(self) -> None:
        try:
            self.transport.close()
        except TransportError:
            pass

    def _run(self) -> None:
        t, proto = self.transport, self.protocol
        while not self._stop.is_set():
            if not t.is_open:
                try:
                    t.open()
                except (TransportError, ValueError) as exc:
                    self.last_error = str(exc)
                    proto.open_failed(exc)
                    self._stop.wait(self.backoff.next())
                    continue
                self.backoff.reset()
                self.opens += 1
                proto.connection_made(self)
            timeout = self.read_timeout if t.interruptible else min(self.read_timeout, UNINTERRUPTIBLE_WAIT)
            try:
                due = proto.next_tick()
            except Exception:  # noqa: BLE001 - the reader must survive a protocol bug
                _log.exception('%s: protocol next_tick failed', self.name, extra=self._extra)
                due = None
            if due is not None:
                timeout = min(timeout, max(MIN_WAIT, due))
            self._wake_at = time.monotonic() + timeout
            try:
                data = t.read(timeout)
            except TransportError as exc:
                self.last_error = str(exc)
                self._close()
                proto.connection_lost(exc)
                continue
            if data:
                self.bytes_received += len(data)
                try:
                    proto.data_received(data)
                except Exception:  # noqa: BLE001 - the reader must survive any input
                    _log.exception('%s: protocol failed on %d bytes', self.name, len(data), extra=self._extra)
            try:
                proto.tick()
            except Exception:  # noqa: BLE001
                _log.exception('%s: protocol tick failed', self.name, extra=self._extra)
