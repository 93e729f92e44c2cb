"""BoardLink: request/response with one board, on the project's reconnecting reader.

Pure Python (no rclpy). A node creates one :class:`BoardLink` per board, calls
:meth:`BoardLink.start` and then uses :meth:`submit` (returns a
``concurrent.futures.Future``, never blocks) or :meth:`request` (blocks up to
``timeout * (retries + 1)``). The port belongs to a
:class:`~sslfr_drivers.link.reader.ReaderThread` (it opens, reads and reopens a lost
port); the link is its protocol object, made of one part per job:

- :class:`~.requests.RequestTable`: answers matched to requests, retries with the SAME
  sequence number (the board answers a duplicate from its cache, never executes twice);
- :class:`~.link_auth.LinkAuth`: the authenticated session (every frame is tagged);
- :class:`~.link_state.LinkStateMachine`: down / connecting / up / silent / refused,
  the re-read of INFO and STATUS after every (re)connection, silence and board reset;
- :class:`~.heartbeat.Heartbeat`: PING when idle, silence detection.

Listeners are told of every frame and state change (a reset board has lost its
position: STATUS shows HOMED cleared and FaultBits.RESET).
"""
from __future__ import annotations

import logging
import math
import threading
import time
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Callable

from sslfr_common.log_route import log_extra
from sslfr_drivers.link import messages as m
from sslfr_drivers.link.board_calls import BoardCalls
from sslfr_drivers.link.heartbeat import Heartbeat
from sslfr_drivers.link.link_auth import LinkAuth
from sslfr_drivers.link.link_errors import AuthError, LinkDown, LinkError, LinkTimeout, NackError, NoSession
from sslfr_drivers.link.link_state import PROBE_INTERVAL, BoardLinkState, LinkState, LinkStateMachine
from sslfr_drivers.link.protocol import Frame, Framer, PayloadError
from sslfr_drivers.link.reader import BACKOFF_MAX, BACKOFF_MIN, Backoff, Protocol, ReaderThread
from sslfr_drivers.link.requests import Pending, RequestTable
from sslfr_drivers.link.transport import TransmitError, Transport, TransportError

__all__ = ['AuthError', 'BoardLink', 'BoardLinkState', 'LinkDown', 'LinkError', 'LinkState', 'LinkTimeout',
           'NackError', 'NoSession', 'PROBE_INTERVAL']

_log = logging.getLogger(__name__)

#: The order of :meth:`BoardLink.counters`.
COUNTERS = ('frames_sent', 'frames_received', 'frames_lost', 'duplicates', 'stale', 'crc_errors',
            'length_errors', 'bytes_discarded', 'bytes_received', 'decode_errors', 'nacks', 'timeouts',
            'retries', 'tx_failures', 'reconnects', 'resets', 'version_errors', 'auth_failures',
            'out_of_session', 'auth_refusals', 'sessions')


class BoardLink(BoardCalls, Protocol):
    """One board: requests, answers, counters, heartbeat, reconnect.

    ``transport``: the byte transport (``transport.make_transport(port)``); ``name``: for
    logs; ``timeout`` [s] per try and ``retries`` (same sequence number): a request's
    defaults; ``heartbeat`` [s]: PING when nothing was sent for this long (keeps the
    board's 1 s watchdog quiet; <= 0.3 s), None: the owner sends traffic itself;
    ``silence`` [s]: no frame for this long while requests or heartbeats go out ->
    ``silent``; ``backoff_min``, ``backoff_max`` [s]: reopen / re-read back-off;
    ``read_timeout`` [s]: the reader's longest wait (it wakes for a frame or the next
    deadline, :meth:`next_tick`; at most ``timeout``); ``clock``: the steady clock [s];
    ``key``: the installation key (16 bytes, link/keys.py), None: the null key of
    unprovisioned boards (a provisioned board refuses this host, which the link reports);
    ``owner``: the ROS node the link works for, whose logger gets its log lines.
    """

    def __init__(self, transport: Transport, *, name: str | None = None, timeout: float = 0.25,
                 retries: int = 2, heartbeat: float | None = None, silence: float = 1.0,
                 backoff_min: float = BACKOFF_MIN, backoff_max: float = BACKOFF_MAX,
                 read_timeout: float = 0.25, clock: Callable[[], float] = time.monotonic,
                 key: bytes | None = None, owner: str = ''):
        self.name = name or getattr(transport, 'name', 'board')
        self.log_extra = log_extra(owner)     # its log lines go to its node's logger (log_route)
        self.timeout = timeout
        self.retries = retries
        self.clock = clock
        self.requests = RequestTable(self.name)
        self.auth = LinkAuth(self, key)
        self.key = self.auth.key
        self.states = LinkStateMachine(self, backoff_min, backoff_max)
        self.beat = Heartbeat(heartbeat, silence)
        self._reader = ReaderThread(transport, self, name=self.name, read_timeout=read_timeout,
                                    backoff=Backoff(backoff_min, backoff_max))
        self.framer = Framer()
        self.tx_lock = threading.Lock()      # frames leave in the order of their numbers
        self._listeners: list[Callable[[m.Message, Frame], None]] = []

        self.info: m.Info | None = None
        self.last_status: m.Status | None = None
        self.last_status_time: float | None = None
        self.version_error = None             # ProtocolVersionError: the board speaks another version
        self.auth_error = ''                  # why the board does not accept this host's key
        self.boot_count: int | None = None    # the board's, from its last HELLO_REPLY
        self.last_error = ''
        # counters (see counters())
        self.frames_sent = self.decode_errors = self.tx_failures = self.resets = 0
        self.version_errors = self.auth_failures = self.out_of_session = self.sessions = 0

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> 'BoardLink':
        """Start the reader thread (it opens the transport, with back-off)."""
        self._reader.start()
        return self

    def stop(self) -> None:
        """Stop the reader thread and close the port, fail pending requests."""
        self._reader.stop()
        self.requests.fail_all(LinkDown('link stopped'))
        self.states.set(BoardLinkState.DOWN)

    close = stop

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    transport = property(lambda self: self._reader.transport, doc='The board\'s port (owned by the reader).')
    connected = property(lambda self: self._reader.connected, doc='The port is open.')
    reconnects = property(lambda self: self._reader.reconnects, doc='Times the port was reopened.')
    bytes_received = property(lambda self: self._reader.bytes_received, doc='Bytes read, frames or not.')
    tracker = property(lambda self: self.auth.tracker, doc='Sequence numbers of the board\'s frames.')
    timeouts = property(lambda self: self.requests.timeouts, doc='Requests never answered.')
    retries_sent = property(lambda self: self.requests.retries_sent, doc='Requests sent again.')
    frames_lost = property(lambda self: self.auth.tracker.lost, doc='Board frames never received (exact).')

    @property
    def heartbeat(self) -> float | None:
        """PING period when idle [s]; None: no heartbeat (settable)."""
        return self.beat.period

    @heartbeat.setter
    def heartbeat(self, period: float | None) -> None:
        self.beat.period = period

    @property
    def state(self) -> BoardLinkState:
        """Current link state; the state listeners have been told it before it shows here."""
        return self.states.shown

    @property
    def is_up(self) -> bool:
        """True when the link state is UP."""
        return self.states.shown == BoardLinkState.UP

    def wait_up(self, timeout: float) -> bool:
        """Block until the link is ``up`` (INFO read) or ``timeout`` [s] passes."""
        return self.states.wait_up(timeout)

    def add_listener(self, fn: Callable[[m.Message, Frame], None]) -> None:
        """``fn(msg, frame)`` for every decoded new frame from the board (answers and
        unsolicited frames: BOOT, sensor samples). Runs in the reader thread: keep it
        short and never call :meth:`request` from it (use :meth:`submit`)."""
        self._listeners.append(fn)

    def add_state_listener(self, fn: Callable[[BoardLinkState, 'BoardLink'], None]) -> None:
        """``fn(state, link)`` on every state change (reader or refresh thread)."""
        self.states.listeners.append(fn)

    # ------------------------------------------------------------------- requests
    def submit(self, msg: m.Message, timeout: float | None = None,
               retries: int | None = None) -> Future:
        """Send ``msg`` in the session and return a Future of the answer message.

        The future ends with the answer (:class:`messages.Ack`, ``Info``, ``Status``)
        or with :class:`NackError`, :class:`LinkTimeout`, :class:`LinkDown`,
        :class:`NoSession`, :class:`AuthError` or :class:`ProtocolVersionError`. Never
        blocks beyond one transport write.
        """
        fut: Future = Future()
        if self.states.state == BoardLinkState.REFUSED and self.auth.session is None:
            fut.set_exception(self.version_error or AuthError(self.auth_error or self.last_error))
            return fut
        if not self._reader.connected:
            fut.set_exception(LinkDown(f'{self.name}: port not open ({self.last_error})'))
            return fut
        timeout = self.timeout if timeout is None else timeout
        retries = self.retries if retries is None else retries
        with self.tx_lock:
            with self.requests.lock:
                if self.auth.session is None:
                    fut.set_exception(NoSession(f'{self.name}: no session with the board yet'
                                                + (f' ({self.last_error})' if self.last_error else '')))
                    return fut
                full, data = self.auth.seal(msg)
                p = Pending(full & 0xFFFF, msg, data, fut, timeout, retries, self.clock() + timeout)
                if msg.RESPONSE:
                    self.requests.add(p)
            self.write(data, p if msg.RESPONSE else None)
        if not msg.RESPONSE and not fut.done():
            fut.set_result(None)
        return fut

    def request(self, msg: m.Message, timeout: float | None = None,
                retries: int | None = None) -> m.Message:
        """Blocking :meth:`submit`: return the answer or raise its error."""
        fut = self.submit(msg, timeout, retries)
        t = self.timeout if timeout is None else timeout
        r = self.retries if retries is None else retries
        try:
            return fut.result(timeout=t * (r + 1) + 1.0)
        except FutureTimeout:  # reader thread stalled: should not happen
            raise LinkTimeout(f'{self.name}: no answer to {type(msg).__name__}') from None

    def send(self, msg: m.Message) -> None:
        """Fire and forget in the session (no answer is awaited even if the type has
        one); raises what :meth:`submit` would end with before sending."""
        if not self._reader.connected:
            raise LinkDown(f'{self.name}: port not open')
        with self.tx_lock:
            with self.requests.lock:
                if self.auth.session is None:
                    raise NoSession(f'{self.name}: no session with the board yet')
                data = self.auth.seal(msg)[1]
            self.write(data, None)

    def counters(self) -> dict[str, int]:
        """Snapshot of every counter (for diagnostics), in the order of :data:`COUNTERS`."""
        tr, fr = self.auth.tracker, self.framer
        c = {'frames_received': tr.received, 'frames_lost': tr.lost, 'duplicates': tr.duplicates,
             'stale': tr.stale, 'crc_errors': fr.crc_errors, 'length_errors': fr.length_errors,
             'bytes_discarded': fr.bytes_discarded, 'bytes_received': self.bytes_received,
             'retries': self.retries_sent, 'reconnects': self.reconnects, 'timeouts': self.timeouts,
             'nacks': self.requests.nacks, 'auth_refusals': self.requests.auth_refusals}
        return {k: c[k] if k in c else getattr(self, k) for k in COUNTERS}

    # ------------------------------------------------------------------ the wire
    def write(self, data: bytes, pending: Pending | None) -> None:
        """Put a frame on the port (any thread); a lost port ends ``pending``, a failed
        transmission leaves it to be retried at its deadline like a lost frame."""
        try:
            self._reader.write(data)
            self.frames_sent += 1
            self.beat.last_tx = self.clock()
            if pending is not None:           # a deadline the reader may sleep past
                self._reader.poke(pending.timeout)
        except TransmitError as exc:
            self.tx_failures += 1
            self.last_error = str(exc)
        except TransportError as exc:
            self.last_error = str(exc)
            if pending is not None:
                self.requests.resolve(pending.key, exc=LinkDown(str(exc)))

    def poke(self, within: float = 0.0) -> None:
        """Wake the reader within ``within`` [s] (a new deadline)."""
        self._reader.poke(within)

    def end_session(self) -> None:
        """Send nothing more in the current session."""
        with self.tx_lock:
            with self.requests.lock:
                self.auth.session = None

    # ------------------------------------------------- reader protocol (reader thread)
    def connection_made(self, reader: ReaderThread) -> None:
        """Port (re)opened: drop partial frames and the session, then start a new
        session and re-read INFO/STATUS before the link is UP."""
        self.framer.reset()
        self.auth.tracker.restart()
        self.auth.session = None
        self.states.set(BoardLinkState.CONNECTING, f'opened {self.name}')
        self.states.backoff.reset()
        self.states.schedule_refresh()

    def open_failed(self, exc: BaseException) -> None:
        """The port could not be opened (the reader retries with back-off)."""
        self.last_error = str(exc)
        self.states.set(BoardLinkState.DOWN, str(exc))

    def connection_lost(self, exc: BaseException) -> None:
        """The port failed: every pending request ends with :class:`LinkDown`."""
        self.last_error = str(exc)
        self.requests.fail_all(LinkDown(str(exc)))
        self.states.set(BoardLinkState.DOWN, str(exc))

    def data_received(self, data: bytes) -> None:
        """Deframe ``data``; handle every valid frame."""
        now = self.clock()
        for frame in self.framer.feed(data):
            try:
                self.auth.on_frame(frame, now)
            except Exception:  # noqa: BLE001 - never let one frame kill the reader
                _log.exception('%s: error handling frame %r', self.name, frame, extra=self.log_extra)

    def tick(self) -> None:
        """Retries, time-outs, heartbeat, silence and re-read timers."""
        now = self.clock()
        resend, expired = self.requests.due(now)
        for p in resend:
            self.write(p.data, p)
        for p in expired:
            self.requests.expire(p)
        up = self.states.state == BoardLinkState.UP
        if expired and up and self.beat.quiet(now):
            self.states.set(BoardLinkState.SILENT, 'requests unanswered')
        if self.beat.ping_due(now) and self.auth.session is not None \
                and self.states.state != BoardLinkState.REFUSED:
            self.submit(m.Ping(int(now * 1000) & 0xFFFFFFFF), retries=0)
        if self.states.state == BoardLinkState.UP and self.beat.unheard(now):
            self.states.set(BoardLinkState.SILENT, 'no frame heard')
        if self.states.refresh_due(now):
            self.states.schedule_refresh()

    def next_tick(self) -> float | None:
        """Seconds until :meth:`tick` has something to do (the reader sleeps until
        then unless a frame comes): the first of the requests' deadlines, the next
        heartbeat, the silence check and the next re-read; None when none."""
        now = self.clock()
        due = self.requests.next_deadline()
        state, hb = self.states.state, self.beat.period
        if hb and self.auth.session is not None and state != BoardLinkState.REFUSED:
            due = min(due, self.beat.next_ping())
        if state == BoardLinkState.UP and hb:
            due = min(due, self.beat.next_unheard())
        refresh = self.states.next_refresh_at()
        if refresh is not None:
            due = min(due, refresh)
        return None if due == math.inf else max(0.0, due - now)

    # ------------------------------------------------------- frames (reader thread)
    def session_frame(self, frame: Frame, full: int, now: float) -> None:
        """An authenticated board frame of the session: answers, STATUS / INFO kept
        (an uptime going back is a board reset), listeners told."""
        msg: m.Message | None
        try:
            msg = m.decode(frame)
        except PayloadError as exc:
            msg = None
            self.decode_errors += 1
            self.last_error = str(exc)
        pending = self.requests.get(frame.ref) if frame.is_response else None
        if self.auth.tracker.accept(frame.seq) != 'new':
            return                      # duplicate or stale: counted by the tracker
        self.beat.last_rx = now
        if msg is None:
            if pending is not None:
                self.requests.resolve(pending.key, exc=PayloadError(self.last_error))
            return
        self.states.note(msg, now)
        self.requests.answer(pending, msg)
        for fn in list(self._listeners):
            try:
                fn(msg, frame)
            except Exception:  # noqa: BLE001
                _log.exception('%s: listener failed', self.name, extra=self.log_extra)
        self.states.heard_board()
