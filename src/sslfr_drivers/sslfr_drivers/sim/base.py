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

* answers every request whose type has ``RESPONSE`` with exactly one frame whose
  ``ref`` is the request's sequence number;
* answers a *duplicated* request (same sequence number and type as the previous
  one: the host retried because the answer was lost) from its cache, with a new
  sequence number, without executing it again;
* ignores stale requests (older sequence numbers) unless three arrive in a row or
  the request is PING/GET_INFO (a restarted host), which resynchronise it;
* sends BOOT (sequence 0) after power-up and after every reset;
* runs the watchdog: nothing valid heard for ``WATCHDOG_S`` = 1 s ->
  :meth:`watchdog_expired` (axis boards stop the motor).
"""
from __future__ import annotations

import dataclasses
import random
from dataclasses import dataclass

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.protocol import (PROTOCOL_VERSION, Frame, Framer, PayloadError, SequenceCounter,
                        SequenceTracker, encode_frame)


class Refuse(Exception):
    """Raised by :meth:`SimBoard.handle` to answer NACK with ``code``."""

    def __init__(self, code: m.ErrorCode):
        super().__init__(code.name)
        self.code = code


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
    """

    kind: m.BoardKind = m.BoardKind.UNKNOWN
    name = 'sim-board'
    firmware = (1, 0, 0)
    #: request types this board implements; any other type is NACKed UNKNOWN_TYPE
    #: whatever its payload (the firmware's rule: BAD_PAYLOAD only for own requests)
    REQUESTS = frozenset({m.Ping.TYPE, m.GetInfo.TYPE, m.Reset.TYPE, m.GetConfig.TYPE, m.SetConfig.TYPE})

    def __init__(self, board_id: int = 1, rng: random.Random | None = None,
                 protocol_version: int = PROTOCOL_VERSION):
        self.board_id = board_id
        self.rng = rng or random.Random()
        self.protocol_version = protocol_version
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

    def reset(self) -> None:
        """Reboot: volatile state is lost, BOOT is sent (sequence 0)."""
        self.resets += 1
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
        """Queue ``msg`` (unsolicited if ``ref`` is None)."""
        frame = m.encode(msg, self._seq.next(), ref)
        if self.protocol_version != PROTOCOL_VERSION:
            frame = Frame(frame.type, frame.seq, frame.payload, frame.ref, frame.flags,
                          self.protocol_version)
        self._out += encode_frame(frame)
        self.frames_out += 1

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
        self._seq = SequenceCounter()
        self._host = SequenceTracker()
        self._last_req: tuple[int, int] | None = None
        self._last_answer: m.Message | None = None
        self._stale_run = 0
        self._reset_pending = False
        self.boot_time = now
        self.last_heard: float | None = None
        self.watchdog_tripped = False
        self.boot_state()
        self.send(m.Boot(int(self.kind), self.protocol_version))

    def _on_frame(self, frame: Frame) -> None:
        if frame.version != self.protocol_version:
            self.send(m.Nack(frame.type, m.ErrorCode.VERSION), ref=frame.seq)
            return
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
        try:
            if frame.type not in self.REQUESTS:
                raise Refuse(m.ErrorCode.UNKNOWN_TYPE)
            msg = m.decode(frame)
        except Refuse as r:
            answer: m.Message | None = m.Nack(frame.type, r.code)
        except PayloadError:
            answer = m.Nack(frame.type, m.ErrorCode.BAD_PAYLOAD)
        else:
            try:
                answer = self.handle(msg, frame)
            except Refuse as r:
                answer = m.Nack(frame.type, r.code)
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
    out, i = [], 0
    while i < len(data):
        n = data[i + 3]
        size = 12 + n
        out.append(data[i:i + size])
        i += size
    return out


def _count_frames(data: bytes) -> int:
    return len(_split_frames(data))

