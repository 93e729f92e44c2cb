"""BoardLink: request/response with one board, on the project's reconnecting reader.

Pure Python (no rclpy). A node creates one :class:`BoardLink` per board, calls
:meth:`BoardLink.start` and then uses :meth:`submit` (returns a
``concurrent.futures.Future``, never blocks) or :meth:`request` (blocks up to
``timeout * (retries + 1)``). The port belongs to a
:class:`~sslfr_drivers.link.reader.ReaderThread` (it opens, reads and reopens a lost
port with :class:`~sslfr_drivers.link.reader.Backoff`); the link is its protocol
object: it feeds the :class:`~sslfr_drivers.link.protocol.Framer`, matches answers to
requests, retries unanswered requests with the SAME sequence number (the board
answers a duplicated request from its cache and does not execute it twice) and sends
heartbeats. After every (re)connection, after a silence and after a detected board
reset it starts a session (HELLO / HELLO_REPLY, link/auth.py) and re-reads INFO and
STATUS before the link is ``UP`` again; listeners are told (a reset board has lost
its position: STATUS shows HOMED cleared and FaultBits.RESET).

Every frame is authenticated (protocol version 2, docs/protocol.md
"Authentication"): requests are tagged in the session, and a board frame is used only
when its tag verifies in the session and its sequence number is new. Everything else
is dropped and counted (``auth_failures``: forged, damaged, another key, another
session; ``stale``: replayed or late; ``out_of_session``: the board's own frames of no
session, BOOT / NO_SESSION, which only make the link check for a board reboot).

States (:class:`BoardLinkState`): ``down`` (port closed/unopenable), ``connecting``
(port open, no session or INFO not read yet), ``up``, ``silent`` (port open but the
board stopped answering), ``refused`` (the board speaks another protocol version, or
does not accept this host's key: :attr:`BoardLink.last_error` says which).
"""
from __future__ import annotations

import enum
import logging
import math
import os
import threading
import time
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass
from typing import Callable

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.auth import BOARD_TO_HOST, HOST_TO_BOARD, NONCE_SIZE, NULL_KEY, NULL_NONCE, Session, key_id
from sslfr_drivers.link.protocol import (PROTOCOL_V1, PROTOCOL_VERSION, Frame, Framer, PayloadError,
                                         ProtocolError, ProtocolVersionError, SequenceCounter,
                                         SequenceTracker, encode_frame)
from sslfr_drivers.link.reader import BACKOFF_MAX, BACKOFF_MIN, Backoff, Protocol, ReaderThread
from sslfr_drivers.link.transport import TransmitError, Transport, TransportError

_log = logging.getLogger(__name__)


class LinkError(Exception):
    """Base of the errors a request can end with."""


class LinkTimeout(LinkError, TimeoutError):
    """No answer after all retries."""


class LinkDown(LinkError):
    """The port is closed or was lost while the request was pending."""


class AuthError(LinkError):
    """The board does not accept this host's key, or has none (message says which and
    what to do)."""


class NoSession(LinkError):
    """No authenticated session with the board yet (the link is starting one)."""


class NackError(LinkError):
    """The board refused the request. ``code`` is a :class:`messages.ErrorCode`."""

    def __init__(self, request_type: int, code: int):
        try:
            name = m.ErrorCode(code).name
        except ValueError:
            name = f'code {code}'
        req = m.registry().get(request_type)
        super().__init__(f'board refused {req.__name__ if req else hex(request_type)}: {name}')
        self.request_type = request_type
        self.code = code


class BoardLinkState(str, enum.Enum):
    """State of one :class:`BoardLink` (its value is the text shown in diagnostics).
    Not the ``AxisStatus.LINK_*`` codes (``sslfr_common.contract.LinkState``)."""

    DOWN = 'down'
    CONNECTING = 'connecting'
    UP = 'up'
    SILENT = 'silent'
    REFUSED = 'refused'


#: The former name, kept for existing call sites (axis/board_session.py).
LinkState = BoardLinkState


#: [s] least time between two checks for a board reboot triggered by the board's
#: frames of no session (a flood of replayed BOOT frames costs one HELLO per period)
PROBE_INTERVAL = 1.0


@dataclass
class _Pending:
    key: object          # seq (session requests) or ('n', seq) (HELLO, version-1 GET_INFO)
    msg: m.Message
    data: bytes
    future: Future
    timeout: float
    retries_left: int
    deadline: float
    nonce: bytes = b''   # HELLO: the host nonce Nh
    adopt: bool = True   # HELLO: start using the new session when it is answered
    refused: str = ''    # HELLO: why the board refused it (the error if no reply comes)


class BoardLink(Protocol):
    """One board: requests, answers, counters, heartbeat, reconnect.

    Parameters
    ----------
    transport : Transport
        Byte transport (``transport.make_transport(port)``).
    name : str
        For logs.
    timeout : float
        Default answer timeout per try [s].
    retries : int
        Default extra tries after a timeout (same sequence number).
    heartbeat : float or None
        If set, send PING when nothing was sent for this long [s] (keeps the board's
        1 s watchdog quiet; use <= 0.3 s). ``None``: the owner sends traffic itself.
    silence : float
        No frame received for this long while requests are outstanding or
        heartbeats are sent -> state ``silent`` [s].
    backoff_min, backoff_max : float
        Reopen / re-read back-off bounds [s] (doubling between them; default the
        reader's policy, 0.1 s to 2 s).
    read_timeout : float
        Longest wait of the reader thread [s]. It wakes for a frame or for the
        link's next deadline (:meth:`next_tick`: a request's time-out, the heartbeat,
        the silence check, a re-read); this only bounds how long an idle link sleeps.
        Keep it at most the request ``timeout``: a request submitted during a read
        then never waits past its deadline without a poke.
    clock : callable
        Monotonic clock [s] (steady; never ROS time).
    key : bytes or None
        The installation key (16 bytes, :func:`sslfr_drivers.link.keys.load_key`);
        None: the null key of unprovisioned boards (no authentication: a provisioned
        board refuses this host, which the link reports).
    """

    def __init__(self, transport: Transport, *, name: str | None = None, timeout: float = 0.25,
                 retries: int = 2, heartbeat: float | None = None, silence: float = 1.0,
                 backoff_min: float = BACKOFF_MIN, backoff_max: float = BACKOFF_MAX,
                 read_timeout: float = 0.25, clock: Callable[[], float] = time.monotonic,
                 key: bytes | None = None):
        self.name = name or getattr(transport, 'name', 'board')
        self.key = bytes(key) if key is not None else NULL_KEY
        if len(self.key) != 16:
            raise ValueError(f'{self.name}: the key must be 16 bytes')
        self._null = Session(self.key)                 # HELLO, the board's BOOT / NO_SESSION
        self._unprovisioned = Session(NULL_KEY) if self.key != NULL_KEY else None
        self._session: Session | None = None
        self._null_seq = SequenceCounter()
        self._next_probe = 0.0
        self.timeout = timeout
        self.retries = retries
        self.heartbeat = heartbeat
        self.silence = silence
        self.clock = clock
        self._reader = ReaderThread(transport, self, name=self.name, read_timeout=read_timeout,
                                    backoff=Backoff(backoff_min, backoff_max))

        self.framer = Framer()
        self.tracker = SequenceTracker()
        self._seq = SequenceCounter()
        self._pending: dict[object, _Pending] = {}
        self._lock = threading.RLock()
        self._tx_lock = threading.Lock()     # frames leave in the order of their numbers
        self._listeners: list[Callable[[m.Message, Frame], None]] = []
        self._state_listeners: list[Callable[[BoardLinkState, 'BoardLink'], None]] = []
        self._state = BoardLinkState.DOWN      # the link's own view, changed first
        self._shown = BoardLinkState.DOWN      # what :attr:`state` shows: listeners told
        self._state_cv = threading.Condition()
        self._refreshing = False
        self._next_refresh = 0.0
        self._refresh_backoff = Backoff(backoff_min, backoff_max)
        self._last_tx = -1e9
        self._last_rx = -1e9

        self.info: m.Info | None = None
        self.last_status: m.Status | None = None
        self.last_status_time: float | None = None
        self.version_error: ProtocolVersionError | None = None
        self.auth_error = ''                  # why the board does not accept this host's key
        self.boot_count: int | None = None    # the board's, from its last HELLO_REPLY
        self.last_error = ''
        # counters (see counters())
        self.frames_sent = 0
        self.decode_errors = 0
        self.nacks = 0
        self.timeouts = 0
        self.retries_sent = 0
        self.tx_failures = 0
        self.resets = 0
        self.version_errors = 0
        self.auth_failures = 0
        self.out_of_session = 0
        self.auth_refusals = 0
        self.sessions = 0

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> 'BoardLink':
        """Start the reader thread (it opens the transport, with back-off)."""
        self._reader.start()
        return self

    def stop(self) -> None:
        """Stop the reader thread and close the port, fail pending requests."""
        self._reader.stop()
        self._fail_all(LinkDown('link stopped'))
        self._set_state(BoardLinkState.DOWN)

    close = stop

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    @property
    def transport(self) -> Transport:
        """The board's port (owned by the reader thread)."""
        return self._reader.transport

    @property
    def reconnects(self) -> int:
        """Times the port was reopened after the first open."""
        return self._reader.reconnects

    @property
    def bytes_received(self) -> int:
        """Bytes read from the port, frames or not."""
        return self._reader.bytes_received

    @property
    def state(self) -> BoardLinkState:
        """Current link state (:class:`BoardLinkState`); the state listeners have
        been told it before it shows here."""
        return self._shown

    @property
    def is_up(self) -> bool:
        """True when the link state is UP."""
        return self._shown == BoardLinkState.UP

    def wait_up(self, timeout: float) -> bool:
        """Block until the link is ``up`` (INFO read) or ``timeout`` [s] passes."""
        with self._state_cv:
            return self._state_cv.wait_for(lambda: self._shown == BoardLinkState.UP, timeout)

    def add_listener(self, fn: Callable[[m.Message, Frame], None]) -> None:
        """``fn(msg, frame)`` for every decoded new frame from the board (answers and
        unsolicited frames: BOOT, sensor samples). Runs in the reader thread: keep it
        short and never call :meth:`request` from it (use :meth:`submit`)."""
        self._listeners.append(fn)

    def add_state_listener(self, fn: Callable[[BoardLinkState, 'BoardLink'], None]) -> None:
        """``fn(state, link)`` on every state change (reader or refresh thread)."""
        self._state_listeners.append(fn)

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
        if self._state == BoardLinkState.REFUSED and self._session is None:
            fut.set_exception(self.version_error or AuthError(self.auth_error or self.last_error))
            return fut
        if not self._reader.connected:
            fut.set_exception(LinkDown(f'{self.name}: port not open ({self.last_error})'))
            return fut
        timeout = self.timeout if timeout is None else timeout
        retries = self.retries if retries is None else retries
        with self._tx_lock:
            with self._lock:
                session = self._session
                if session is None:
                    fut.set_exception(NoSession(f'{self.name}: no session with the board yet'
                                                + (f' ({self.last_error})' if self.last_error else '')))
                    return fut
                full = self._seq.next_full()
                data = encode_frame(session.seal(HOST_TO_BOARD, full, m.encode(msg, 0)))
                p = _Pending(full & 0xFFFF, msg, data, fut, timeout, retries, self.clock() + timeout)
                if msg.RESPONSE:
                    self._pending[p.key] = p
            self._write(data, p if msg.RESPONSE else None)
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
        with self._tx_lock:
            with self._lock:
                if self._session is None:
                    raise NoSession(f'{self.name}: no session with the board yet')
                data = encode_frame(self._session.seal(HOST_TO_BOARD, self._seq.next_full(), m.encode(msg, 0)))
            self._write(data, None)

    # convenience wrappers (blocking)
    def ping(self, **kw) -> m.Ack:
        """PING carrying the host clock [ms, modulo 2**32]; the board's ACK."""
        return self.request(m.Ping(int(self.clock() * 1000) & 0xFFFFFFFF), **kw)

    def get_info(self, **kw) -> m.Info:
        """The board's INFO answer."""
        return self.request(m.GetInfo(), **kw)

    def get_status(self, **kw) -> m.Status:
        """The board's STATUS answer."""
        return self.request(m.GetStatus(), **kw)

    def move_to(self, steps: int, speed: float, **kw) -> m.Ack:
        """MOVE_TO absolute ``steps`` [steps] at ``speed`` [steps/s]."""
        return self.request(m.MoveTo(int(steps), float(speed)), **kw)

    def stop_motor(self, **kw) -> m.Ack:
        """STOP: decelerate to rest; the ACK."""
        return self.request(m.Stop(), **kw)

    def home(self, switch: int, speed: float, position: int = 0, **kw) -> m.Ack:
        """Start homing toward ``switch`` (:class:`messages.Switch`), signed ``speed``
        [steps/s]; the counter becomes ``position`` [steps] at the switch."""
        return self.request(m.Home(int(switch), float(speed), int(position)), **kw)

    def set_zero(self, position: int = 0, **kw) -> m.Ack:
        """SET_ZERO: the counter becomes ``position`` [steps] and the axis
        counts as homed; the ACK."""
        return self.request(m.SetZero(int(position)), **kw)

    def reset_board(self, **kw) -> m.Ack:
        """RESET: reboot the board (position lost); the ACK."""
        return self.request(m.Reset(), **kw)

    # ------------------------------------------------------------------- counters
    @property
    def frames_lost(self) -> int:
        """Board frames never received (sequence gaps; exact across wrap-around)."""
        return self.tracker.lost

    def counters(self) -> dict[str, int]:
        """Snapshot of every counter (for diagnostics)."""
        return {
            'frames_sent': self.frames_sent,
            'frames_received': self.tracker.received,
            'frames_lost': self.tracker.lost,
            'duplicates': self.tracker.duplicates,
            'stale': self.tracker.stale,
            'crc_errors': self.framer.crc_errors,
            'length_errors': self.framer.length_errors,
            'bytes_discarded': self.framer.bytes_discarded,
            'bytes_received': self.bytes_received,
            'decode_errors': self.decode_errors,
            'nacks': self.nacks,
            'timeouts': self.timeouts,
            'retries': self.retries_sent,
            'tx_failures': self.tx_failures,
            'reconnects': self.reconnects,
            'resets': self.resets,
            'version_errors': self.version_errors,
            'auth_failures': self.auth_failures,
            'out_of_session': self.out_of_session,
            'auth_refusals': self.auth_refusals,
            'sessions': self.sessions,
        }

    # ------------------------------------------------------------------ internals
    def _write(self, data: bytes, pending: _Pending | None) -> None:
        try:
            self._reader.write(data)
            self.frames_sent += 1
            self._last_tx = self.clock()
            if pending is not None:           # a deadline the reader may sleep past
                self._reader.poke(pending.timeout)
        except TransmitError as exc:
            self.tx_failures += 1
            self.last_error = str(exc)
            if pending is None:
                return
            # stays pending: retried at its deadline like a lost frame
        except TransportError as exc:
            self.last_error = str(exc)
            if pending is not None:
                self._resolve(pending.key, exc=LinkDown(str(exc)))

    def _resolve(self, key, result=None, exc: BaseException | None = None) -> None:
        with self._lock:
            p = self._pending.pop(key, None)
        if p is None or p.future.done():
            return
        if exc is not None:
            p.future.set_exception(exc)
        else:
            p.future.set_result(result)

    def _fail_all(self, exc: BaseException, session_only: bool = False) -> None:
        with self._lock:
            keys = [k for k in self._pending if not (session_only and isinstance(k, tuple))]
        for k in keys:
            self._resolve(k, exc=exc)

    def _set_state(self, state: BoardLinkState, why: str = '') -> None:
        """Change state: the link's own view at once, then the listeners, then what
        :attr:`state` and :meth:`wait_up` show (unless a newer change came meanwhile,
        from a listener or the other thread)."""
        with self._state_cv:
            if state == self._state:
                return
            old, self._state = self._state, state
        _log.info('%s: link %s -> %s %s', self.name, old.value, state.value, why)
        for fn in list(self._state_listeners):
            try:
                fn(state, self)
            except Exception:  # noqa: BLE001 - a listener bug must not kill the link
                _log.exception('%s: state listener failed', self.name)
        with self._state_cv:
            if self._state == state:
                self._shown = state
                self._state_cv.notify_all()
        self._reader.poke()                   # the deadlines depend on the state

    # ------------------------------------------------- reader protocol (reader thread)
    def connection_made(self, reader: ReaderThread) -> None:
        """Port (re)opened: drop partial frames and the session, then start a new
        session and re-read INFO/STATUS before the link is UP."""
        self.framer.reset()
        self.tracker.restart()
        self._session = None
        self._set_state(BoardLinkState.CONNECTING, f'opened {self.name}')
        self._refresh_backoff.reset()
        self._schedule_refresh()

    def open_failed(self, exc: BaseException) -> None:
        """The port could not be opened (the reader retries with back-off)."""
        self.last_error = str(exc)
        self._set_state(BoardLinkState.DOWN, str(exc))

    def connection_lost(self, exc: BaseException) -> None:
        """The port failed: every pending request ends with :class:`LinkDown`."""
        self.last_error = str(exc)
        self._fail_all(LinkDown(str(exc)))
        self._set_state(BoardLinkState.DOWN, str(exc))

    def data_received(self, data: bytes) -> None:
        """Deframe ``data``; handle every valid frame."""
        now = self.clock()
        for frame in self.framer.feed(data):
            try:
                self._on_frame(frame, now)
            except Exception:  # noqa: BLE001 - never let one frame kill the reader
                _log.exception('%s: error handling frame %r', self.name, frame)

    def tick(self) -> None:
        """Retries, time-outs, heartbeat, silence and re-read timers."""
        self._service(self.clock())

    def next_tick(self) -> float | None:
        """Seconds until :meth:`_service` has something to do (the reader sleeps until
        then unless a frame comes): the first of the pending requests' deadlines, the
        next heartbeat, the silence check and the next re-read; None when none."""
        now = self.clock()
        due = math.inf
        with self._lock:
            for p in self._pending.values():
                due = min(due, p.deadline)
        state, hb = self._state, self.heartbeat
        if hb and self._session is not None and state != BoardLinkState.REFUSED:
            due = min(due, self._last_tx + hb)
        if state == BoardLinkState.UP and hb:
            due = min(due, self._last_rx + max(self.silence, 2 * hb) + 1e-3)
        if state in (BoardLinkState.CONNECTING, BoardLinkState.SILENT, BoardLinkState.REFUSED) \
                and not self._refreshing:
            due = min(due, self._next_refresh)
        return None if due == math.inf else max(0.0, due - now)

    # ------------------------------------------------------- frames (reader thread)
    def _on_frame(self, frame: Frame, now: float) -> None:
        if frame.version != PROTOCOL_VERSION:
            self._foreign_frame(frame)
            return
        session = self._session
        if session is not None:
            full = self.tracker.expand(frame.seq)
            if session.verify(BOARD_TO_HOST, full, frame):
                self._session_frame(frame, full, now)
                return
        with self._lock:
            hello = self._pending.get(('n', frame.ref)) if frame.is_response else None
        if hello is not None and isinstance(hello.msg, m.Hello) and frame.type == m.HelloReply.TYPE:
            if self._hello_reply(hello, frame):
                return
        if self._null.verify(BOARD_TO_HOST, frame.seq, frame):
            self._out_of_session(frame, hello, now)
            return
        self.auth_failures += 1
        if hello is not None and isinstance(hello.msg, m.Hello) and frame.type == m.Nack.TYPE:
            # the board answers our HELLO with a frame we cannot verify: it has another key
            if self._unprovisioned is not None and self._unprovisioned.verify(BOARD_TO_HOST, frame.seq, frame):
                hello.refused = (f'{self.name}: the board is not provisioned (it has no installation key): '
                                 'provision it over its USB port: sslfr keys provision BOARD --port PORT')
            elif self.key == NULL_KEY:
                hello.refused = (f'{self.name}: the board is provisioned with an installation key and this '
                                 'host has none: set the key_file parameter to the installation key file')
            else:
                hello.refused = (f'{self.name}: the board does not accept this host\'s key (key id '
                                 f'{key_id(self.key)}): it was provisioned with another key; use the '
                                 'installation\'s key file or provision the board again over USB')

    def _foreign_frame(self, frame: Frame) -> None:
        """A frame of another protocol version: a version-1 INFO answering our version-1
        GET_INFO is read (it names the board); anything else refuses the board."""
        with self._lock:
            p = self._pending.get(('n', frame.ref)) if frame.is_response else None
        if p is not None and frame.version == PROTOCOL_V1 and frame.type == m.Info.TYPE:
            try:
                info = m.decode(frame)
            except PayloadError as exc:
                self._resolve(p.key, exc=exc)
                return
            self.info = info
            self._resolve(p.key, result=info)
            return
        self.version_errors += 1
        self.version_error = ProtocolVersionError(frame.version)
        self.last_error = str(self.version_error)
        self._session = None
        if self._state != BoardLinkState.REFUSED:
            _log.error('%s: %s', self.name, self.version_error)
        self._fail_all(self.version_error)
        self._set_state(BoardLinkState.REFUSED, str(self.version_error))

    def _hello_reply(self, hello: _Pending, frame: Frame) -> bool:
        """A HELLO_REPLY to our HELLO: True when it verifies in the session it opens
        (then adopted if the HELLO says so, and the HELLO answered)."""
        try:
            reply = m.decode(frame)
        except PayloadError:
            return False
        candidate = Session(self.key, hello.nonce, reply.nonce)
        if not candidate.verify(BOARD_TO_HOST, frame.seq, frame):
            return False
        if hello.adopt:
            self._adopt(candidate, reply, frame)
        self._resolve(hello.key, result=reply)
        return True

    def _adopt(self, session: Session, reply: m.HelloReply, frame: Frame) -> None:
        """Use ``session`` from now on (reader thread). Requests still waiting for an
        answer in the previous session are sent again in the new one (new sequence
        numbers: the board cannot answer them otherwise), except RESET (never twice) and
        except after a board reset (a changed boot count: the board lost its position,
        its owner must re-reference it before moving: they end with NoSession)."""
        rebooted = self.boot_count is not None and reply.boot_count != self.boot_count
        with self._tx_lock:
            with self._lock:
                self._session = session
                self._seq = SequenceCounter()
                self.tracker.restart()
                self.tracker.accept(frame.seq)
                old = [p for k, p in self._pending.items() if not isinstance(k, tuple)]
                for p in old:
                    del self._pending[p.key]
                moved = []
                for p in old:
                    if isinstance(p.msg, m.Reset) or rebooted:
                        continue
                    full = self._seq.next_full()
                    p.key = full & 0xFFFF
                    p.data = encode_frame(session.seal(HOST_TO_BOARD, full, m.encode(p.msg, 0)))
                    p.deadline = self.clock() + p.timeout
                    self._pending[p.key] = p
                    moved.append(p)
            for p in moved:
                self._write(p.data, p)
        kept = {id(p) for p in moved}
        for p in old:
            if id(p) not in kept and not p.future.done():
                p.future.set_exception(NoSession(f'{self.name}: new session with the board'
                                                 + (' (it was reset)' if rebooted else '')))
        self.sessions += 1
        self.auth_error = ''
        self.version_error = None
        self._last_rx = self.clock()
        self._new_boot_count(reply.boot_count, in_session=True)

    def _new_boot_count(self, count: int, in_session: bool = False) -> None:
        """The board's boot count from an authenticated HELLO_REPLY: a change is a reset
        (``in_session``: the reply opened the session now in use, which stays)."""
        old, self.boot_count = self.boot_count, count
        if old is not None and count != old:
            self.last_status = None           # its uptime restarted: not a second reset
            self._board_reset(f'boot count {old} -> {count}', end_session=not in_session)

    def _out_of_session(self, frame: Frame, hello: _Pending | None, now: float) -> None:
        """A frame of the board's own key but of no session (BOOT after a reboot, NACK
        NO_SESSION): it may be a recording, so it is never used; while UP it makes the
        link check (one HELLO per PROBE_INTERVAL) whether the board rebooted."""
        self.out_of_session += 1
        if self._state == BoardLinkState.UP:
            if not self._refreshing and now >= self._next_probe:
                self._next_probe = now + PROBE_INTERVAL
                self._refreshing = True
                threading.Thread(target=self._probe, name=f'probe-{self.name}', daemon=True).start()
        elif self._state in (BoardLinkState.SILENT, BoardLinkState.CONNECTING) and not self._refreshing:
            self._schedule_refresh()

    def _session_frame(self, frame: Frame, full: int, now: float) -> None:
        """An authenticated board frame of the session."""
        msg: m.Message | None
        try:
            msg = m.decode(frame)
        except PayloadError as exc:
            msg = None
            self.decode_errors += 1
            self.last_error = str(exc)
        with self._lock:
            pending = self._pending.get(frame.ref) if frame.is_response else None
        if self.tracker.accept(frame.seq) != 'new':
            return                      # duplicate or stale: counted by the tracker
        self._last_rx = now
        if msg is None:
            if pending is not None:
                self._resolve(pending.key, exc=PayloadError(self.last_error))
            return
        if isinstance(msg, m.Status):
            old = self.last_status
            if old is not None and msg.uptime_ms < old.uptime_ms \
                    and old.uptime_ms - msg.uptime_ms < 1 << 31:
                self._board_reset('uptime went back')
            self.last_status = msg
            self.last_status_time = now
        elif isinstance(msg, m.Info):
            self.info = msg
        if pending is not None:
            if isinstance(msg, m.Nack):
                self.nacks += 1
                if msg.code in (m.ErrorCode.AUTH, m.ErrorCode.REPLAY, m.ErrorCode.NO_SESSION):
                    # a frame with our sequence number was refused: possibly a forged copy
                    # of our request; ours may still be answered (else it times out)
                    self.auth_refusals += 1
                else:
                    self._resolve(pending.key, exc=NackError(msg.request_type, msg.code))
            else:
                self._resolve(pending.key, result=msg)
        elif isinstance(msg, m.Nack) and msg.code in (m.ErrorCode.AUTH, m.ErrorCode.REPLAY):
            self.auth_refusals += 1
        for fn in list(self._listeners):
            try:
                fn(msg, frame)
            except Exception:  # noqa: BLE001
                _log.exception('%s: listener failed', self.name)
        if self._state in (BoardLinkState.SILENT, BoardLinkState.CONNECTING) and not self._refreshing:
            self._schedule_refresh()

    def _board_reset(self, why: str, end_session: bool = True) -> None:
        """The board rebooted: its session is gone (``end_session``: nothing more is sent
        in it, requests waiting in it end with NoSession, never re-sent to a board that
        lost its position); a new session and the re-read follow."""
        _log.warning('%s: board reset detected (%s): position lost until re-homed',
                     self.name, why)
        if end_session:
            with self._tx_lock:
                with self._lock:
                    self._session = None
            self._fail_all(NoSession(f'{self.name}: the board was reset ({why})'), session_only=True)
        if self._state == BoardLinkState.UP:
            self._set_state(BoardLinkState.CONNECTING, f'board reset ({why})')
        self.resets += 1    # counted once the link no longer shows UP
        if not self._refreshing:
            self._schedule_refresh()

    # --------------------------------------------------------------- timers (reader)
    def _service(self, now: float) -> None:
        expired: list[_Pending] = []
        resend: list[_Pending] = []
        with self._lock:
            for p in self._pending.values():
                if now >= p.deadline:
                    if p.retries_left > 0:
                        p.retries_left -= 1
                        p.deadline = now + p.timeout
                        resend.append(p)
                    else:
                        expired.append(p)
        for p in resend:
            self.retries_sent += 1
            self._write(p.data, p)
        for p in expired:
            if p.refused:
                self._resolve(p.key, exc=AuthError(p.refused))
                continue
            self.timeouts += 1
            self._resolve(p.key, exc=LinkTimeout(
                f'{self.name}: no answer to {type(p.msg).__name__} (seq {p.data[5] | p.data[6] << 8})'))
        if expired and self._state == BoardLinkState.UP and now - self._last_rx > self.silence:
            self._set_state(BoardLinkState.SILENT, 'requests unanswered')
        if self.heartbeat and now - self._last_tx >= self.heartbeat and self._session is not None \
                and self._state != BoardLinkState.REFUSED:
            self.submit(m.Ping(int(now * 1000) & 0xFFFFFFFF), retries=0)
        if self._state == BoardLinkState.UP and self.heartbeat \
                and now - self._last_rx > max(self.silence, 2 * self.heartbeat):
            self._set_state(BoardLinkState.SILENT, 'no frame heard')
        if self._state in (BoardLinkState.CONNECTING, BoardLinkState.SILENT, BoardLinkState.REFUSED) \
                and not self._refreshing and now >= self._next_refresh:
            self._schedule_refresh()

    # ------------------------------------------------ session and re-read (own thread)
    def _null_request(self, msg: m.Message, version: int = PROTOCOL_VERSION, adopt: bool = True):
        """Send ``msg`` outside any session (HELLO in the null session, or a version-1
        GET_INFO) and wait for its answer (the usual time-out and retries)."""
        fut: Future = Future()
        if not self._reader.connected:
            raise LinkDown(f'{self.name}: port not open ({self.last_error})')
        seq = self._null_seq.next()
        if version == PROTOCOL_VERSION:
            frame = self._null.seal(HOST_TO_BOARD, seq, m.encode(msg, seq))
        else:
            frame = Frame(msg.TYPE, seq, msg.pack(), version=version)
        data = encode_frame(frame)
        p = _Pending(('n', seq), msg, data, fut, self.timeout, self.retries, self.clock() + self.timeout,
                     nonce=getattr(msg, 'nonce', b''), adopt=adopt)
        with self._lock:
            self._pending[p.key] = p
        self._write(data, p)
        try:
            return fut.result(timeout=self.timeout * (self.retries + 1) + 1.0)
        except FutureTimeout:
            raise LinkTimeout(f'{self.name}: no answer to {type(msg).__name__}') from None

    def _handshake(self, adopt: bool = True) -> m.HelloReply:
        """HELLO with a fresh host nonce; the board's HELLO_REPLY (adopted if ``adopt``)."""
        nonce = NULL_NONCE
        while nonce == NULL_NONCE:
            nonce = os.urandom(NONCE_SIZE)
        return self._null_request(m.Hello(nonce), adopt=adopt)

    def _probe(self) -> None:
        """While UP, after a frame of no session: has the board rebooted? A new session
        is opened but not used; only a changed boot count counts (a reset, then the
        usual re-read adopts a new session)."""
        count = None
        try:
            count = self._handshake(adopt=False).boot_count
        except (LinkError, ProtocolError):
            pass                       # the link's own time-outs handle a silent board
        finally:
            self._refreshing = False
        if count is not None:
            self._new_boot_count(count)   # a reset: the re-read adopts a new session

    def _schedule_refresh(self) -> None:
        self._refreshing = True
        threading.Thread(target=self._refresh, name=f'refresh-{self.name}', daemon=True).start()

    def _refresh(self) -> None:
        """Start a session and re-read INFO and STATUS; the link is UP only after this
        succeeds. A version-1 board is only read for INFO (it stays refused)."""
        try:
            self._handshake()
            info = self.request(m.GetInfo())
            if not isinstance(info, m.Info):
                raise ProtocolError(f'GET_INFO answered with {type(info).__name__}')
            if info.protocol != PROTOCOL_VERSION:
                raise ProtocolVersionError(info.protocol)
            try:
                self.request(m.GetStatus())
            except NackError:
                pass   # boards without STATUS (some sensor boards) are fine
            self._refresh_backoff.reset()
            self._set_state(BoardLinkState.UP, f'{info.name_str} fw {info.firmware}'
                            + ('' if self.key != NULL_KEY else ' (NOT authenticated: no key)'))
        except ProtocolVersionError as exc:
            self.version_error = exc
            self.last_error = str(exc)
            self._session = None
            self._set_state(BoardLinkState.REFUSED, str(exc))
            try:
                self._null_request(m.GetInfo(), version=PROTOCOL_V1)
            except (LinkError, ProtocolError):
                pass
        except AuthError as exc:
            if str(exc) != self.auth_error:
                _log.error('%s', exc)
            self.auth_error = self.last_error = str(exc)
            self._session = None
            self._set_state(BoardLinkState.REFUSED, str(exc))
        except (LinkError, ProtocolError) as exc:
            self.last_error = str(exc)
            if self._reader.connected and self._state == BoardLinkState.UP:
                self._set_state(BoardLinkState.SILENT, str(exc))
        finally:
            delay = self._refresh_backoff.next()
            self._next_refresh = self.clock() + delay
            self._refreshing = False
            self._reader.poke(delay)
