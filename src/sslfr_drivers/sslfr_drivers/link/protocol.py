"""SSLFR board protocol: frame layout, CRC-16, stateful framer, sequence tracking.

Pure Python (no rclpy). The wire format is documented in docs/protocol.md; this
module is its reference implementation and the simulated boards use it too.

Frame layout of protocol version 2 (all multi-byte integers little-endian)::

    offset size field
    0      2    SYNC = 0xA5 0x5A
    2      1    version      protocol version (PROTOCOL_VERSION = 2)
    3      1    length       L = N + TAG_SIZE: payload and tag, 8..MAX_BODY
    4      1    flags        bit0 FLAG_RESPONSE: this frame answers request `ref`
    5      2    seq          sender's sequence number, u16, +1 per frame sent (wraps)
    7      2    ref          seq of the request answered (valid if FLAG_RESPONSE)
    9      1    type         message type (see messages.py registry)
    10     N    payload      0..MAX_PAYLOAD bytes
    10+N   8    tag          message authentication code (link/auth.py)
    18+N   2    crc          CRC-16/CCITT-FALSE over bytes 2 .. 17+N

Version 1 had no tag (``length`` = N, 0..88). Bytes 0..3 and the CRC trailer are
frozen for every protocol version (the tag counts in ``length``), so a frame of
another version is still delimited and CRC-checked and can be refused with a clear
message (:class:`ProtocolVersionError`) instead of being misparsed; a version-1
board's INFO stays readable.

A whole frame is at most ``HEADER_SIZE + MAX_BODY + 2 = 100`` bytes: it fits in one
XBee 802.15.4 RF packet (100 bytes maximum payload, no encryption).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

SYNC = b'\xa5\x5a'
PROTOCOL_VERSION = 2
#: the version without authentication (its boards are read for INFO, refused otherwise)
PROTOCOL_V1 = 1
HEADER_SIZE = 10
CRC_SIZE = 2
TAG_SIZE = 8
#: largest ``length`` field (payload + tag): one frame = one XBee RF packet
MAX_BODY = 88
#: largest payload of a version-2 frame
MAX_PAYLOAD = MAX_BODY - TAG_SIZE
MAX_FRAME = HEADER_SIZE + MAX_BODY + CRC_SIZE
SEQ_MOD = 1 << 16
#: full sequence numbers (the epoch in the upper 16 bits) wrap here
FULL_MOD = 1 << 32
#: a sequence number ahead of the last one by less than this is new; otherwise stale.
SEQ_WINDOW = SEQ_MOD // 2

FLAG_RESPONSE = 0x01

_HDR = struct.Struct('<2sBBBHHB')
assert _HDR.size == HEADER_SIZE


class ProtocolError(ValueError):
    """Base of every error this protocol declares (bad frame, bad payload, version)."""


class FrameError(ProtocolError):
    """A byte string is not one valid frame (:func:`decode_frame`)."""


class PayloadError(ProtocolError):
    """A frame's payload does not match its message type's layout."""


class ProtocolVersionError(ProtocolError):
    """The peer speaks another protocol version; it is refused, never guessed at."""

    def __init__(self, peer_version: int, ours: int = PROTOCOL_VERSION):
        super().__init__(
            f'board speaks protocol version {peer_version}, this host speaks version '
            f'{ours}: refusing the board (update its firmware or the host software)')
        self.peer_version = peer_version
        self.ours = ours


def _make_crc_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return table


_CRC_TABLE = _make_crc_table()


def crc16(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xorout).

    Check value: ``crc16(b'123456789') == 0x29B1``.
    """
    table = _CRC_TABLE
    for b in data:
        crc = ((crc << 8) & 0xFFFF) ^ table[((crc >> 8) ^ b) & 0xFF]
    return crc


def tag_size(version: int) -> int:
    """Bytes of authentication tag a frame of ``version`` carries in its body."""
    return TAG_SIZE if version == PROTOCOL_VERSION else 0


@dataclass(frozen=True)
class Frame:
    """One decoded frame.

    Attributes
    ----------
    type : int
        Message type code (0..255), see :mod:`sslfr_drivers.link.messages`.
    seq : int
        Sender's sequence number (0..65535).
    payload : bytes
        Raw payload (decode with ``messages.decode``).
    ref : int
        Sequence number of the request this frame answers (meaningful when
        ``is_response``).
    flags : int
        Flag bits (``FLAG_RESPONSE``).
    version : int
        Protocol version the sender speaks.
    tag : bytes
        Authentication tag (version 2: 8 bytes, ``None`` gives 8 zero bytes, which
        no receiver accepts: seal frames with :mod:`sslfr_drivers.link.auth`; other
        versions: empty).
    """

    type: int
    seq: int
    payload: bytes = b''
    ref: int = 0
    flags: int = 0
    version: int = PROTOCOL_VERSION
    tag: bytes | None = None

    def __post_init__(self):
        if self.tag is None:
            object.__setattr__(self, 'tag', bytes(tag_size(self.version)))

    @property
    def is_response(self) -> bool:
        """True when the RESPONSE flag is set (an answer to a host request)."""
        return bool(self.flags & FLAG_RESPONSE)

    def header(self) -> bytes:
        """Bytes 2..9 of the wire frame: version, length, flags, seq, ref, type (the
        first 8 bytes the tag covers; the payload follows)."""
        return _HDR.pack(SYNC, self.version, len(self.payload) + len(self.tag), self.flags,
                         self.seq, self.ref, self.type)[2:]


def encode_frame(frame: Frame) -> bytes:
    """Serialise ``frame`` to wire bytes (SYNC .. CRC).

    Raises
    ------
    FrameError
        Payload longer than the version allows, a tag of the wrong size, or a
        field out of range.
    """
    n = len(frame.payload)
    tag = frame.tag
    if len(tag) != tag_size(frame.version):
        raise FrameError(f'a version-{frame.version} frame carries a {tag_size(frame.version)}-byte '
                         f'tag, not {len(tag)}')
    if n + len(tag) > MAX_BODY:
        raise FrameError(f'payload of {n} bytes exceeds {MAX_BODY - len(tag)} (version {frame.version})')
    if not (0 <= frame.type <= 255 and 0 <= frame.seq < SEQ_MOD and 0 <= frame.ref < SEQ_MOD
            and 0 <= frame.flags <= 255 and 0 <= frame.version <= 255):
        raise FrameError(f'frame field out of range: {frame!r}')
    body = _HDR.pack(SYNC, frame.version, n + len(tag), frame.flags, frame.seq, frame.ref,
                     frame.type) + bytes(frame.payload) + bytes(tag)
    return body + struct.pack('<H', crc16(memoryview(body)[2:]))


def _split_body(version: int, body: bytes) -> tuple[bytes, bytes] | None:
    """(payload, tag) of a frame body, None when a version-2 body is shorter than its tag."""
    t = tag_size(version)
    if len(body) < t:
        return None
    return (body[:len(body) - t], body[len(body) - t:]) if t else (body, b'')


def decode_frame(data: bytes) -> Frame:
    """Decode exactly one frame from ``data``.

    Raises
    ------
    FrameError
        Wrong sync, length, size or CRC (a version-2 frame shorter than its tag is a
        wrong length).
    """
    data = bytes(data)
    if len(data) < HEADER_SIZE + CRC_SIZE:
        raise FrameError(f'{len(data)} bytes is shorter than a frame')
    sync, version, n, flags, seq, ref, mtype = _HDR.unpack_from(data)
    if sync != SYNC:
        raise FrameError('bad sync bytes')
    if n > MAX_BODY or len(data) != HEADER_SIZE + n + CRC_SIZE:
        raise FrameError(f'length field {n} does not match {len(data)} bytes')
    (crc,) = struct.unpack_from('<H', data, HEADER_SIZE + n)
    if crc != crc16(memoryview(data)[2:HEADER_SIZE + n]):
        raise FrameError('CRC mismatch')
    split = _split_body(version, data[HEADER_SIZE:HEADER_SIZE + n])
    if split is None:
        raise FrameError(f'length field {n} is shorter than the tag of a version-{version} frame')
    return Frame(mtype, seq, split[0], ref, flags, version, split[1])


class Framer:
    """Stateful deframer fed with byte chunks of any size.

    Frames may be split across chunks and several frames may arrive in one chunk.
    Garbage between frames is skipped; after a bad CRC or impossible length (above
    MAX_BODY, or a version-2 length shorter than the tag, checked after the CRC) the
    framer resynchronises on the next SYNC after the bad frame's first byte, so a
    good frame hidden inside a corrupted one is still found. :meth:`feed` never
    raises on any input and only ever returns frames whose CRC is correct.

    Counters (monotonic): ``frames_ok``, ``crc_errors``, ``length_errors``,
    ``bytes_discarded``, ``foreign_version`` (valid frames of another protocol
    version; they are returned too, so the link can refuse the board).
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.frames_ok = 0
        self.crc_errors = 0
        self.length_errors = 0
        self.bytes_discarded = 0
        self.foreign_version = 0

    def reset(self) -> None:
        """Drop any partial frame (e.g. after a reconnect). Counters are kept."""
        self.bytes_discarded += len(self._buf)
        self._buf.clear()

    @property
    def pending(self) -> int:
        """Bytes buffered waiting for the rest of a frame."""
        return len(self._buf)

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[Frame]:
        """Add ``chunk`` and return every complete valid frame, in order."""
        buf = self._buf
        buf += chunk
        out: list[Frame] = []
        while True:
            i = buf.find(SYNC)
            if i < 0:
                # keep a trailing 0xA5: it may be the first half of a split SYNC
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                self.bytes_discarded += len(buf) - keep
                del buf[:len(buf) - keep]
                break
            if i:
                self.bytes_discarded += i
                del buf[:i]
            if len(buf) < 4:
                break
            n = buf[3]
            if n > MAX_BODY:
                self.length_errors += 1
                self.bytes_discarded += 1
                del buf[:1]
                continue
            size = HEADER_SIZE + n + CRC_SIZE
            if len(buf) < size:
                break
            crc = buf[size - 2] | (buf[size - 1] << 8)
            if crc != crc16(memoryview(buf)[2:size - 2]):
                self.crc_errors += 1
                self.bytes_discarded += 1
                del buf[:1]
                continue
            _, version, _, flags, seq, ref, mtype = _HDR.unpack_from(buf)
            split = _split_body(version, bytes(buf[HEADER_SIZE:size - 2]))
            if split is None:
                self.length_errors += 1
                self.bytes_discarded += 1
                del buf[:1]
                continue
            frame = Frame(mtype, seq, split[0], ref, flags, version, split[1])
            del buf[:size]
            self.frames_ok += 1
            if version != PROTOCOL_VERSION:
                self.foreign_version += 1
            out.append(frame)
        return out


class SequenceCounter:
    """Outgoing sequence numbers: 0, 1, ..., 65535, 0, ... (``next()``), and the full
    32-bit count behind them (``next_full()``: the tag covers its upper half, the
    epoch, so a frame recorded 65536 frames earlier never verifies again)."""

    def __init__(self, start: int = 0):
        self._next = start % FULL_MOD

    def next_full(self) -> int:
        """The next outgoing full sequence number (0..2**32-1; seq = its low 16 bits)."""
        s = self._next
        self._next = (s + 1) % FULL_MOD
        return s

    def next(self) -> int:
        """The next outgoing sequence number (0..65535, wrapping)."""
        return self.next_full() % SEQ_MOD

    def peek(self) -> int:
        """The 16-bit number :meth:`next` will return, without consuming it."""
        return self._next % SEQ_MOD


class SequenceTracker:
    """Classify incoming sequence numbers of one sender and count lost frames.

    ``accept(seq)`` returns ``'new'``, ``'duplicate'`` (same as the last new one) or
    ``'stale'`` (behind the last new one, a late or replayed frame). For a new frame
    ``delta = (seq - last) mod 2**16`` with ``1 <= delta < SEQ_WINDOW`` and
    ``delta - 1`` frames were lost in between; this is exact across the 65535 -> 0
    wrap-around. A jump of ``SEQ_WINDOW`` or more backwards-looking is stale. The
    first frame after :meth:`restart` (a board reset or reconnect) is always new and
    counts no loss.

    The tracker also keeps the sender's full 32-bit count (``last``): :meth:`expand`
    gives the full number a 16-bit ``seq`` stands for (the nearest to ``last``; the
    first frame after a restart is in epoch 0), the one the sender's tag covers.

    Counters: ``received`` (new frames), ``lost``, ``duplicates``, ``stale``.
    """

    def __init__(self) -> None:
        self.last: int | None = None
        self.received = 0
        self.lost = 0
        self.duplicates = 0
        self.stale = 0

    def restart(self) -> None:
        """Forget the last sequence number (the peer restarted its counter)."""
        self.last = None

    def expand(self, seq: int) -> int:
        """The full 32-bit sequence number that 16-bit ``seq`` stands for."""
        if self.last is None:
            return seq
        delta = (seq - self.last) % SEQ_MOD
        if delta < SEQ_WINDOW:
            return (self.last + delta) % FULL_MOD
        return (self.last - (SEQ_MOD - delta)) % FULL_MOD

    def accept(self, seq: int) -> str:
        """Classify ``seq`` (0..65535): 'new', 'duplicate' or 'stale'; updates the
        counters (see the class docstring)."""
        if self.last is None:
            self.last = seq
            self.received += 1
            return 'new'
        delta = (seq - self.last) % SEQ_MOD
        if delta == 0:
            self.duplicates += 1
            return 'duplicate'
        if delta >= SEQ_WINDOW:
            self.stale += 1
            return 'stale'
        self.lost += delta - 1
        self.last = (self.last + delta) % FULL_MOD
        self.received += 1
        return 'new'
