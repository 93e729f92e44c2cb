"""Base of the simulated boards and the byte-level fault injector (no rclpy, no I/O).

A :class:`SimBoard` is a pure state machine driven by its runner:

* ``receive(data)``: bytes from the host (after fault injection);
* ``tick(now)``: advance the model to steady-clock time ``now`` [s] (dynamics,
  watchdog, unsolicited frames);
* ``take_output()``: bytes the board wants to send (the runner passes them through
  the fault injector to the wire).

Subclasses implement :meth:`SimBoard.handle` (one decoded request -> one answer
message or :class:`Refuse`) and optionally :meth:`SimBoard.update` (called from
``tick``), :meth:`SimBoard.boot_state` (state lost at reset) and
:meth:`SimBoard.watchdog_expired`. Like the firmware, a board:

* authenticates every frame (protocol version 2, docs/protocol.md "Authentication"):
  HELLO in the null session opens a *pending* session (answered HELLO_REPLY with the
  board's nonce); the first request that verifies in it makes it the current one
  (the previous session ends then, not before: a replayed HELLO cannot end the
  host's session); any other request must verify in the current session;
* refuses (never executes) an unauthenticated request (NACK AUTH, or NO_SESSION when
  it has no session) and a stale one (NACK REPLAY), counting each; refusals are
  answered at most once per ``REFUSAL_INTERVAL_MS`` (a flood is not echoed);
* takes a new installation key (PROVISION, tagged under the null key) only in the
  provisioning window an external reset opens (:meth:`reset` with ``external=True``,
  :meth:`open_provisioning`), else NACK LOCKED (counted ``provision_refused``);
* answers every request whose type has ``RESPONSE`` with exactly one frame whose
  ``ref`` is the request's sequence number;
* answers a *duplicated* request (same sequence number and type as the previous
  one: the host retried because the answer was lost) from its cache, with a new
  sequence number, without executing it again;
* sends BOOT (null session, sequence 0) after power-up and after every reset, and
  unsolicited frames (samples) only in a session;
* runs the watchdog: no new authenticated request for ``WATCHDOG_S`` = 1 s ->
  :meth:`watchdog_expired` (axis boards stop the motor); forged, replayed and
  duplicated frames do not feed it.

``protocol_version=1`` plays a board of the previous protocol (no tags, no
sessions) for the refusal tests.
"""
from __future__ import annotations

import dataclasses
import random
from dataclasses import dataclass

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.auth import BOARD_TO_HOST, HOST_TO_BOARD, NULL_KEY, Session, board_nonce
from sslfr_drivers.link.protocol import (PROTOCOL_VERSION, Frame, Framer, PayloadError,
                                         SequenceCounter, SequenceTracker, encode_frame)

#: [ms] least time between two refusal NACKs (AUTH, REPLAY, NO_SESSION, VERSION) of
#: a board: a flood of forged frames is counted, not echoed (firmware: lib/session.c)
REFUSAL_INTERVAL_MS = 50
#: [ms] the provisioning window after an external reset (firmware: SESSION_PROVISION_MS)
PROVISION_WINDOW_MS = 10000


class Refuse(Exception):
    """Raised by :meth:`SimBoard.handle` to answer NACK with ``code``."""

    def __init__(self, code: m.ErrorCode):
        super().__init__(code.name)
        self.code = code


class _BoardSession:
    """One session as a board keeps it: tags, the host's sequence numbers, its own."""

    def __init__(self, key: bytes, nh: bytes, nb: bytes):
        self.auth = Session(key, nh, nb)
        self.nh = nh
        self.rx = SequenceTracker()
        self.tx = SequenceCounter()
        self.reply: bytes = b''                      # the HELLO_REPLY (resent to a retried HELLO)
        self.last_req: tuple[int, int] | None = None
        self.last_answer: m.Message | None = None


class SimBoard:
    """Protocol behaviour shared by every simulated board (see module docstring).

    Parameters
    ----------
    board_id : int
        32-bit serial reported in INFO.
    rng : random.Random
        Random source (seed it for reproducible noise).
    protocol_version : int
        Version written in frames and INFO (set != PROTOCOL_VERSION to simulate an
        old board that must be refused).
    key : bytes or None
        The installation key the board was provisioned with; None: unprovisioned
        (the null key). :meth:`provision` changes it (a re-flash).
    """

    kind: m.BoardKind = m.BoardKind.UNKNOWN
    name = 'sim-board'
    firmware = (1, 0, 0)
    #: request types this board implements; any other type is NACKed UNKNOWN_TYPE
    #: whatever its payload (the firmware's rule: BAD_PAYLOAD only for own requests)
    REQUESTS = frozenset({m.Ping.TYPE, m.GetInfo.TYPE, m.Reset.TYPE, m.GetConfig.TYPE, m.SetConfig.TYPE})

    def __init__(self, board_id: int = 1, rng: random.Random | None = None,
                 protocol_version: int = PROTOCOL_VERSION, key: bytes | None = None):
        self.board_id = board_id
        self.rng = rng or random.Random()
        self.protocol_version = protocol_version
        self.key = bytes(key) if key is not None else NULL_KEY
        self.boot_count = 0          # kept across resets, like the firmware's EEPROM counter
        self.auth_failures = 0
        self.no_session = 0
        self.version_errors = 0
        self.sessions = 0
        self.provision_refused = 0
        self._out = bytearray()
        self._ticked = False
        self.now = 0.0
        self.boot_time = 0.0
        self.resets = 0
        self.frames_in = 0
        self.frames_out = 0
        self.requests_stale = 0
        self.requests_duplicate = 0
        self.watchdog_trips = 0
        self.config = dataclasses.replace(m.ConfigRecord.defaults(int(self.kind)), board_id=board_id)
        self._boot(0.0)

    # ------------------------------------------------------------ runner side
    def receive(self, data: bytes) -> None:
        """Feed bytes from the host."""
        for frame in self._framer.feed(data):
            self._on_frame(frame)

    def tick(self, now: float) -> None:
        """Advance to steady time ``now`` [s]: watchdog, then :meth:`update`."""
        if not self._ticked:      # first tick: the board powers up now
            self._ticked = True
            self.now = self.boot_time = now
            if self.last_heard is not None:
                self.last_heard = now
        if now < self.now:
            now = self.now
        dt = now - self.now
        self.now = now
        if (not self.watchdog_tripped and self.last_heard is not None
                and now - self.last_heard > m.WATCHDOG_S):
            self.watchdog_tripped = True
            self.watchdog_trips += 1
            self.watchdog_expired()
        self.update(dt)

    def take_output(self) -> bytes:
        """Bytes queued for the host (and clear the queue)."""
        out = bytes(self._out)
        self._out.clear()
        return out

    def reset(self, external: bool = False) -> None:
        """Reboot: volatile state is lost, BOOT is sent (sequence 0). ``external``: a
        reset through the RESET pin (the USB adapter's DTR, the reset button), which
        opens the provisioning window for PROVISION_WINDOW_S."""
        self.resets += 1
        self._boot(self.now)
        if external:
            self.open_provisioning()

    def open_provisioning(self) -> None:
        """Open the provisioning window now (firmware: after an external reset)."""
        self._provision_from = self.now

    def provision(self, key: bytes | None, protocol_version: int | None = None) -> None:
        """Give the board ``key`` (None: unprovisioned) and/or another protocol version,
        as a re-flash over USB would, and restart it (not counted as a reset)."""
        self.key = bytes(key) if key is not None else NULL_KEY
        if protocol_version is not None:
            self.protocol_version = protocol_version
        self._boot(self.now)

    # ------------------------------------------------------------ subclass API
    def boot_state(self) -> None:
        """(Re)initialise the volatile state lost at reset. Override."""

    def update(self, dt: float) -> None:
        """Advance the model by ``dt`` [s]. Override."""

    def busy(self) -> bool:
        """True while the model needs fine time steps (the runner then ticks every
        5 ms instead of 20 ms; incoming bytes are always handled at once). Default
        True; models override it to save CPU when idle."""
        return True

    def watchdog_expired(self) -> None:
        """Nothing heard for 1 s. Override (axis: stop the motor, latch the fault)."""

    def handle(self, msg: m.Message, frame: Frame) -> m.Message | None:
        """Answer one request. Return the answer, ``None`` for no answer, or raise
        :class:`Refuse`. The base class answers PING, GET_INFO and RESET."""
        if isinstance(msg, m.Ping):
            return m.Ack(msg.TYPE)
        if isinstance(msg, m.GetInfo):
            return self.info()
        if isinstance(msg, m.Reset):
            self._reset_pending = True
            return m.Ack(msg.TYPE)
        if isinstance(msg, m.GetConfig):
            return m.Config(self.config.pack())
        if isinstance(msg, m.SetConfig):
            rec = m.ConfigRecord.unpack(msg.record)
            code = rec.check(int(self.kind))
            if code:
                raise Refuse(m.ErrorCode(code))
            if self.busy_for_config():
                raise Refuse(m.ErrorCode.BUSY)
            self.stored_config = rec          # used from the next boot, as in EEPROM
            return m.Ack(msg.TYPE)
        raise Refuse(m.ErrorCode.UNKNOWN_TYPE)

    def busy_for_config(self) -> bool:
        """True while SET_CONFIG must be refused (axis: the motor moves)."""
        return False

    def info(self) -> m.Info:
        """The INFO answer: board kind, firmware and protocol versions, id, name."""
        return m.Info(int(self.kind), *self.firmware, self.protocol_version, self.config.board_id,
                      self.name.encode('ascii')[:16])

    def send(self, msg: m.Message, ref: int | None = None) -> None:
        """Queue ``msg`` (unsolicited if ``ref`` is None): in the current session
        (dropped when there is none: samples wait for a host)."""
        if self.protocol_version != PROTOCOL_VERSION:
            self._queue(Frame(msg.TYPE, self._seq.next(), msg.pack(), ref or 0, 0 if ref is None else 1,
                              self.protocol_version))
        elif self._cur is not None:
            self._send_in(self._cur, msg, ref)

    def _send_in(self, bs: _BoardSession | None, msg: m.Message, ref: int | None) -> None:
        """``msg`` tagged in session ``bs`` (None: the null session)."""
        if bs is None:
            full, auth = self._null_tx.next_full() & 0xFFFF, self._null
        else:
            full, auth = bs.tx.next_full(), bs.auth
        self._queue(auth.seal(BOARD_TO_HOST, full, m.encode(msg, 0, ref)))

    def _queue(self, frame: Frame) -> None:
        self._out += encode_frame(frame)
        self.frames_out += 1

    def _refuse(self, frame: Frame, code: m.ErrorCode, bs: _BoardSession | None) -> None:
        """NACK(code) to ``frame`` in session ``bs``, at most once per REFUSAL_INTERVAL_MS."""
        now_ms = int(self.now * 1000)
        if self._last_refusal_ms is not None and now_ms - self._last_refusal_ms < REFUSAL_INTERVAL_MS:
            return
        self._last_refusal_ms = now_ms
        if self.protocol_version != PROTOCOL_VERSION:
            self.send(m.Nack(frame.type, code), ref=frame.seq)
        else:
            self._send_in(bs, m.Nack(frame.type, code), frame.seq)

    @property
    def uptime_ms(self) -> int:
        """Milliseconds since the last boot, wrapping at 2**32 like the firmware [ms]."""
        return int((self.now - self.boot_time) * 1000) & 0xFFFFFFFF

    # ------------------------------------------------------------ internals
    def _boot(self, now: float) -> None:
        stored = getattr(self, 'stored_config', None)
        if stored is not None:
            self.config = stored
        self._framer = Framer()
        self._seq = SequenceCounter()            # version 1 only
        self._host = SequenceTracker()           # version 1 only
        self._last_req: tuple[int, int] | None = None
        self._last_answer: m.Message | None = None
        self._stale_run = 0
        self._reset_pending = False
        self.boot_count = (self.boot_count + 1) & 0xFFFFFFFF
        self._null = Session(self.key)
        self._null_tx = SequenceCounter()
        self._cur: _BoardSession | None = None
        self._pend: _BoardSession | None = None
        self._session_count = 0
        self._last_refusal_ms: int | None = None
        self._provision_from: float | None = None
        self.boot_time = now
        self.last_heard: float | None = None
        self.watchdog_tripped = False
        self.boot_state()
        boot = m.Boot(int(self.kind), self.protocol_version)
        if self.protocol_version != PROTOCOL_VERSION:
            self.send(boot)
        else:
            self._send_in(None, boot, None)

    def _on_frame(self, frame: Frame) -> None:
        if frame.version != self.protocol_version:
            self.version_errors += 1
            self._refuse(frame, m.ErrorCode.VERSION, None)
            return
        if self.protocol_version != PROTOCOL_VERSION:
            self._on_frame_v1(frame)
            return
        if frame.type == m.Hello.TYPE:
            self._hello(frame)
            return
        if frame.type == m.Provision.TYPE:
            self._provision(frame)
            return
        bs = None
        if self._cur is not None and self._cur.auth.verify(HOST_TO_BOARD, self._cur.rx.expand(frame.seq), frame):
            bs = self._cur
        elif self._pend is not None and self._pend.auth.verify(HOST_TO_BOARD, frame.seq, frame):
            bs = self._cur = self._pend       # the host uses the new session: the old one ends
            self._pend = None
            self.sessions += 1
        if bs is None:
            if self._cur is None and self._pend is None:
                self.no_session += 1
                self._refuse(frame, m.ErrorCode.NO_SESSION, None)
            else:
                self.auth_failures += 1
                self._refuse(frame, m.ErrorCode.AUTH, self._cur)
            return
        verdict = bs.rx.accept(frame.seq)
        if verdict == 'duplicate' and bs.last_req == (frame.seq, frame.type):
            self.requests_duplicate += 1
            if bs.last_answer is not None:
                self._send_in(bs, bs.last_answer, frame.seq)
            return
        if verdict != 'new':
            self.requests_stale += 1
            self._refuse(frame, m.ErrorCode.REPLAY, bs)
            return
        self.frames_in += 1
        self.last_heard = self.now
        self.watchdog_tripped = False
        answer = self._answer(frame)
        bs.last_req = (frame.seq, frame.type)
        bs.last_answer = answer
        if answer is not None:
            self._send_in(bs, answer, frame.seq)
        if self._reset_pending:
            self.reset()

    def _hello(self, frame: Frame) -> None:
        """HELLO (null session): open a pending session and answer HELLO_REPLY in it;
        a retried HELLO (same nonce as the pending one) gets the same reply again."""
        if not self._null.verify(HOST_TO_BOARD, frame.seq, frame):
            self.auth_failures += 1
            self._refuse(frame, m.ErrorCode.AUTH, self._cur)
            return
        try:
            hello = m.decode(frame)
        except PayloadError:
            self._send_in(None, m.Nack(frame.type, m.ErrorCode.BAD_PAYLOAD), frame.seq)
            return
        if self._pend is not None and self._pend.nh == hello.nonce:
            self._out += self._pend.reply
            self.frames_out += 1
            return
        self._session_count += 1
        nb = board_nonce(self.key, self.boot_count, self._session_count)
        bs = _BoardSession(self.key, hello.nonce, nb)
        reply = bs.auth.seal(BOARD_TO_HOST, bs.tx.next_full(),
                             m.encode(m.HelloReply(nb, self.boot_count), 0, frame.seq))
        bs.reply = encode_frame(reply)
        self._pend = bs
        self._out += bs.reply
        self.frames_out += 1

    def _provision(self, frame: Frame) -> None:
        """PROVISION (tagged under the null key): the new key, only inside the
        provisioning window; ACK in the null session of the new key."""
        if not Session(NULL_KEY).verify(HOST_TO_BOARD, frame.seq, frame):
            self.auth_failures += 1
            self._refuse(frame, m.ErrorCode.AUTH, self._cur)
            return
        if self._provision_from is None or int(self.now * 1000) - int(self._provision_from * 1000) \
                >= PROVISION_WINDOW_MS:
            self.provision_refused += 1
            self._refuse(frame, m.ErrorCode.LOCKED, None)
            return
        try:
            msg = m.decode(frame)
        except PayloadError:
            self._send_in(None, m.Nack(frame.type, m.ErrorCode.BAD_PAYLOAD), frame.seq)
            return
        self.key = bytes(msg.key)
        self._null = Session(self.key)
        self._cur = self._pend = None
        self._send_in(None, m.Ack(frame.type), frame.seq)

    def _answer(self, frame: Frame) -> m.Message | None:
        """The answer to one accepted request (a NACK for a refused one)."""
        try:
            if frame.type not in self.REQUESTS:
                raise Refuse(m.ErrorCode.UNKNOWN_TYPE)
            msg = m.decode(frame)
        except Refuse as r:
            return m.Nack(frame.type, r.code)
        except PayloadError:
            return m.Nack(frame.type, m.ErrorCode.BAD_PAYLOAD)
        try:
            return self.handle(msg, frame)
        except Refuse as r:
            return m.Nack(frame.type, r.code)

    def _on_frame_v1(self, frame: Frame) -> None:
        """A board of protocol version 1 (or any other: no authentication), kept to test
        refusal."""
        self.frames_in += 1
        self.last_heard = self.now
        self.watchdog_tripped = False
        verdict = self._host.accept(frame.seq)
        if verdict == 'duplicate' and self._last_req == (frame.seq, frame.type):
            self.requests_duplicate += 1
            if self._last_answer is not None:
                self.send(self._last_answer, ref=frame.seq)
            return
        if verdict == 'stale':
            self._stale_run += 1
            if self._stale_run < 3 and frame.type not in (m.Ping.TYPE, m.GetInfo.TYPE):
                self.requests_stale += 1
                return
            self._host.restart()
            self._host.accept(frame.seq)
        self._stale_run = 0
        answer = self._answer(frame)
        self._last_req = (frame.seq, frame.type)
        self._last_answer = answer
        if answer is not None:
            self.send(answer, ref=frame.seq)
        if self._reset_pending:
            self.reset()


@dataclass
class FaultInjector:
    """Byte-stream faults between a board and the wire (both directions).

    drop : probability that a byte is dropped
    corrupt : probability that a byte gets one random bit flipped
    corrupt_frames : probability that a board -> host *frame* gets one bit flipped
        (applied by :meth:`board_frames`, counted exactly in ``frames_corrupted``)
    silent_until : steady time [s] until which nothing passes either way (a radio
        cut / unplugged cable that keeps the board powered)
    """

    drop: float = 0.0
    corrupt: float = 0.0
    corrupt_frames: float = 0.0
    silent_until: float = 0.0
    rng: random.Random | None = None

    def __post_init__(self):
        self.rng = self.rng or random.Random()
        self.bytes_dropped = 0
        self.bytes_corrupted = 0
        self.frames_corrupted = 0
        self.frames_silenced = 0

    def silent(self, now: float) -> bool:
        """True while a ``disconnect`` is in force at ``now`` [s, monotonic]."""
        return now < self.silent_until

    def bytes(self, data: bytes, now: float) -> bytes:
        """Apply drop/corrupt/silence to a chunk of bytes."""
        if not data:
            return data
        if self.silent(now):
            self.bytes_dropped += len(data)
            return b''
        if not (self.drop or self.corrupt):
            return data
        out = bytearray()
        rnd = self.rng.random
        for b in data:
            if self.drop and rnd() < self.drop:
                self.bytes_dropped += 1
                continue
            if self.corrupt and rnd() < self.corrupt:
                b ^= 1 << self.rng.randrange(8)
                self.bytes_corrupted += 1
            out.append(b)
        return bytes(out)

    def board_frames(self, data: bytes, now: float) -> bytes:
        """Board -> host: whole-frame faults (frame corruption, silence) then bytes.

        ``data`` is a concatenation of whole frames (what ``SimBoard.take_output``
        returns)."""
        if not data:
            return data
        if self.silent(now):
            self.frames_silenced += _count_frames(data)
            self.bytes_dropped += len(data)
            return b''
        if self.corrupt_frames:
            out = bytearray()
            for frame in _split_frames(data):
                if self.rng.random() < self.corrupt_frames:
                    frame = bytearray(frame)
                    i = self.rng.randrange(len(frame))
                    frame[i] ^= 1 << self.rng.randrange(8)
                    self.frames_corrupted += 1
                out += frame
            data = bytes(out)
        return self.bytes(data, now)


def _split_frames(data: bytes) -> list[bytes]:
    """The board's output cut at frame lengths (header byte 3 = payload length). Bytes
    that are not whole frames (the tests inject garbage) end up in the last piece: a
    tail shorter than a header is one piece, never an IndexError (that once ended the
    simulator's serve thread in a soak)."""
    out, i = [], 0
    while i < len(data):
        if len(data) - i < 4:
            out.append(data[i:])
            break
        n = data[i + 3]
        size = 12 + n
        out.append(data[i:i + size])
        i += size
    return out


def _count_frames(data: bytes) -> int:
    return len(_split_frames(data))

