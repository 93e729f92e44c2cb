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
reset it re-reads INFO and STATUS before the link is ``UP`` again; listeners are
told (a reset board has lost its position: STATUS shows HOMED cleared and
FaultBits.RESET).

States (:class:`BoardLinkState`): ``down`` (port closed/unopenable), ``connecting``
(port open, INFO not read yet), ``up``, ``silent`` (port open but the board stopped
answering), ``refused`` (board speaks another protocol version).
"""
from __future__ import annotations

import enum
import logging
import threading
import time
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass
from typing import Callable

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.protocol import (PROTOCOL_VERSION, Frame, Framer, PayloadError, ProtocolError,
                                         ProtocolVersionError, SequenceCounter, SequenceTracker,
                                         encode_frame)
from sslfr_drivers.link.reader import BACKOFF_MAX, BACKOFF_MIN, Backoff, Protocol, ReaderThread
from sslfr_drivers.link.transport import TransmitError, Transport, TransportError

_log = logging.getLogger(__name__)


class LinkError(Exception):
    """Base of the errors a request can end with."""


class LinkTimeout(LinkError, TimeoutError):
    """No answer after all retries."""


class LinkDown(LinkError):
    """The port is closed or was lost while the request was pending."""


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


@dataclass
class _Pending:
    seq: int
    msg: m.Message
    data: bytes
    future: Future
    timeout: float
    retries_left: int
    deadline: float


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
        Reader thread poll period [s]; bounds timer resolution.
    clock : callable
        Monotonic clock [s] (steady; never ROS time).
    """

    def __init__(self, transport: Transport, *, name: str | None = None, timeout: float = 0.25,
                 retries: int = 2, heartbeat: float | None = None, silence: float = 1.0,
                 backoff_min: float = BACKOFF_MIN, backoff_max: float = BACKOFF_MAX,
                 read_timeout: float = 0.02, clock: Callable[[], float] = time.monotonic):
        self.name = name or getattr(transport, 'name', 'board')
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
        self._pending: dict[int, _Pending] = {}
        self._lock = threading.RLock()
        self._listeners: list[Callable[[m.Message, Frame], None]] = []
        self._state_listeners: list[Callable[[BoardLinkState, 'BoardLink'], None]] = []
        self._state = BoardLinkState.DOWN      # the link's own view, changed first
        self._shown = BoardLinkState.DOWN      # what :attr:`state` shows: listeners told
        self._state_cv = threading.Condition()
        self._refreshing = False
        self._next_refresh = 0.0
        self._refresh_backoff = Backoff(backoff_min, backoff_max)
        self._consecutive_stale = 0
        self._last_tx = -1e9
        self._last_rx = -1e9

        self.info: m.Info | None = None
        self.last_status: m.Status | None = None
        self.last_status_time: float | None = None
        self.version_error: ProtocolVersionError | None = None
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
        self.seq_resyncs = 0

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
        """Send ``msg`` and return a Future of the answer message.

        The future ends with the answer (:class:`messages.Ack`, ``Info``, ``Status``)
        or with :class:`NackError`, :class:`LinkTimeout`, :class:`LinkDown` or
        :class:`ProtocolVersionError`. Never blocks beyond one transport write.
        """
        fut: Future = Future()
        if self._state == BoardLinkState.REFUSED and not isinstance(msg, m.GetInfo):
            fut.set_exception(self.version_error or ProtocolVersionError(-1))
            return fut
        if not self._reader.connected:
            fut.set_exception(LinkDown(f'{self.name}: port not open ({self.last_error})'))
            return fut
        timeout = self.timeout if timeout is None else timeout
        retries = self.retries if retries is None else retries
        with self._lock:
            seq = self._seq.next()
            data = encode_frame(m.encode(msg, seq))
            p = _Pending(seq, msg, data, fut, timeout, retries, self.clock() + timeout)
            if msg.RESPONSE:
                self._pending[seq] = p
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
        """Fire and forget (no answer is awaited even if the type has one)."""
        if not self._reader.connected:
            raise LinkDown(f'{self.name}: port not open')
        with self._lock:
            data = encode_frame(m.encode(msg, self._seq.next()))
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
            'seq_resyncs': self.seq_resyncs,
        }

    # ------------------------------------------------------------------ internals
    def _write(self, data: bytes, pending: _Pending | None) -> None:
        try:
            self._reader.write(data)
            self.frames_sent += 1
            self._last_tx = self.clock()
        except TransmitError as exc:
            self.tx_failures += 1
            self.last_error = str(exc)
            if pending is None:
                return
            # stays pending: retried at its deadline like a lost frame
        except TransportError as exc:
            self.last_error = str(exc)
            if pending is not None:
                self._resolve(pending.seq, exc=LinkDown(str(exc)))

    def _resolve(self, seq: int, result=None, exc: BaseException | None = None) -> None:
        with self._lock:
            p = self._pending.pop(seq, None)
        if p is None or p.future.done():
            return
        if exc is not None:
            p.future.set_exception(exc)
        else:
            p.future.set_result(result)

    def _fail_all(self, exc: BaseException) -> None:
        with self._lock:
            seqs = list(self._pending)
        for s in seqs:
            self._resolve(s, exc=exc)

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

    # ------------------------------------------------- reader protocol (reader thread)
    def connection_made(self, reader: ReaderThread) -> None:
        """Port (re)opened: drop partial frames, forget the board's sequence and
        re-read INFO/STATUS before the link is UP."""
        self.framer.reset()
        self.tracker.restart()
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

    def _on_frame(self, frame: Frame, now: float) -> None:
        if frame.version != PROTOCOL_VERSION:
            self.version_errors += 1
            self.version_error = ProtocolVersionError(frame.version)
            self.last_error = str(self.version_error)
            _log.error('%s: %s', self.name, self.version_error)
            self._fail_all(self.version_error)
            self._set_state(BoardLinkState.REFUSED, str(self.version_error))
            return
        msg: m.Message | None
        try:
            msg = m.decode(frame)
        except PayloadError as exc:
            msg = None
            self.decode_errors += 1
            self.last_error = str(exc)
        if isinstance(msg, m.Boot):
            self.tracker.restart()
        with self._lock:
            pending = self._pending.get(frame.ref) if frame.is_response else None
        verdict = self.tracker.accept(frame.seq)
        if verdict == 'stale' and (pending is not None or self._consecutive_stale >= 2):
            # the board restarted its sequence (reset whose BOOT was lost)
            self.tracker.stale -= 1
            self.tracker.restart()
            self.tracker.accept(frame.seq)
            self.seq_resyncs += 1
            self._consecutive_stale = 0
            self._board_reset('sequence restarted')
            verdict = 'new'
        if verdict != 'new':
            if verdict == 'stale':
                self._consecutive_stale += 1
            return
        self._consecutive_stale = 0
        self._last_rx = now
        if msg is None:
            if pending is not None:
                self._resolve(pending.seq, exc=PayloadError(self.last_error))
            return
        if isinstance(msg, m.Boot):
            self._board_reset('BOOT received')
        elif isinstance(msg, m.Status):
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
                self._resolve(pending.seq, exc=NackError(msg.request_type, msg.code))
            else:
                self._resolve(pending.seq, result=msg)
        for fn in list(self._listeners):
            try:
                fn(msg, frame)
            except Exception:  # noqa: BLE001
                _log.exception('%s: listener failed', self.name)
        if self._state in (BoardLinkState.SILENT, BoardLinkState.CONNECTING) and not self._refreshing:
            self._schedule_refresh()

    def _board_reset(self, why: str) -> None:
        _log.warning('%s: board reset detected (%s): position lost until re-homed',
                     self.name, why)
        if self._state == BoardLinkState.UP:
            self._set_state(BoardLinkState.CONNECTING, f'board reset ({why})')
        self.resets += 1    # counted once the link no longer shows UP
        if not self._refreshing:
            self._schedule_refresh()

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
            self.timeouts += 1
            self._resolve(p.seq, exc=LinkTimeout(
                f'{self.name}: no answer to {type(p.msg).__name__} (seq {p.seq})'))
        if expired and self._state == BoardLinkState.UP and now - self._last_rx > self.silence:
            self._set_state(BoardLinkState.SILENT, 'requests unanswered')
        if self.heartbeat and now - self._last_tx >= self.heartbeat \
                and self._state != BoardLinkState.REFUSED:
            self.submit(m.Ping(int(now * 1000) & 0xFFFFFFFF), retries=0)
        if self._state == BoardLinkState.UP and self.heartbeat \
                and now - self._last_rx > max(self.silence, 2 * self.heartbeat):
            self._set_state(BoardLinkState.SILENT, 'no frame heard')
        if self._state in (BoardLinkState.CONNECTING, BoardLinkState.SILENT, BoardLinkState.REFUSED) \
                and not self._refreshing and now >= self._next_refresh:
            self._schedule_refresh()

    def _schedule_refresh(self) -> None:
        self._refreshing = True
        threading.Thread(target=self._refresh, name=f'refresh-{self.name}', daemon=True).start()

    def _refresh(self) -> None:
        """Re-read INFO and STATUS; the link is UP only after this succeeds."""
        try:
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
            self.version_error = None
            self._set_state(BoardLinkState.UP, f'{info.name_str} fw {info.firmware}')
        except ProtocolVersionError as exc:
            self.version_error = exc
            self.version_errors += 1
            self.last_error = str(exc)
            self._set_state(BoardLinkState.REFUSED, str(exc))
        except (LinkError, ProtocolError) as exc:
            self.last_error = str(exc)
            if self._reader.connected and self._state == BoardLinkState.UP:
                self._set_state(BoardLinkState.SILENT, str(exc))
        finally:
            self._next_refresh = self.clock() + self._refresh_backoff.next()
            self._refreshing = False
