"""Authentication of the board protocol (version 2): the installation key, sessions,
tags (docs/protocol.md "Authentication"). Pure Python, no rclpy, no I/O.

Every frame carries ``tag = SipHash-2-4(K, prefix || frame[2 .. 9+N])`` (64 bits), with
``K`` the installation's 128-bit key and the 24-byte prefix::

    'sslfr' | direction (1 host->board, 2 board->host) | epoch (u16) | Nh (8) | Nb (8)

``Nh`` / ``Nb`` are the session's nonces, drawn by the host and the board when the
link starts (HELLO / HELLO_REPLY); the *null session* (both nonces zero) carries only
HELLO and the frames a board sends while it has no session (BOOT, NO_SESSION). The
epoch is the upper half of the sender's 32-bit frame count in the session (the wire
carries the lower half, ``seq``): a frame recorded in one session never verifies in
another, and one recorded 65536 frames earlier never verifies again in the same
session. The prefix state is absorbed once per session, direction and epoch.

An unprovisioned board uses :data:`NULL_KEY` (16 zero bytes): everyone knows it, so
its frames authenticate nothing; a host without a key file can only talk to such a
board, and a host with one refuses it ("board not provisioned").
"""
from __future__ import annotations

import hmac
import struct

from sslfr_drivers.link.protocol import TAG_SIZE, Frame
from sslfr_drivers.link.siphash import KEY_SIZE, SipHash, siphash24

NONCE_SIZE = 8
NULL_KEY = bytes(KEY_SIZE)
NULL_NONCE = bytes(NONCE_SIZE)
HOST_TO_BOARD = 1
BOARD_TO_HOST = 2
_LABEL = b'sslfr'
_Q = struct.Struct('<Q')


def key_id(key: bytes) -> str:
    """A public fingerprint of ``key`` (8 hex digits: the first 32 bits of its SipHash
    of the text 'sslfr key id'): shown to match key files and boards, reveals nothing
    usable about the key."""
    return f'{siphash24(key, b"sslfr key id") & 0xFFFFFFFF:08x}'


def board_nonce(key: bytes, boot_count: int, session_count: int) -> bytes:
    """The board's session nonce ``Nb``: SipHash-2-4 under the key of 'sslfr-nb',
    the boot count (u32) and the session count since boot (u32). Unique for the board's
    life (the boot count is kept in EEPROM and never goes back) and unpredictable
    without the key; the firmware computes the same (lib/auth.c)."""
    return _Q.pack(siphash24(key, b'sslfr-nb' + struct.pack('<II', boot_count & 0xFFFFFFFF,
                                                             session_count & 0xFFFFFFFF)))


class Session:
    """The tags of one session (key, host nonce, board nonce), both directions.

    Parameters
    ----------
    key : bytes
        The installation key (16 bytes).
    nh, nb : bytes
        Host and board nonces (8 bytes each); both zero: the null session.
    """

    def __init__(self, key: bytes, nh: bytes = NULL_NONCE, nb: bytes = NULL_NONCE):
        if len(key) != KEY_SIZE or len(nh) != NONCE_SIZE or len(nb) != NONCE_SIZE:
            raise ValueError('a session needs a 16-byte key and two 8-byte nonces')
        self.key, self.nh, self.nb = bytes(key), bytes(nh), bytes(nb)
        self._states: dict[tuple[int, int], SipHash] = {}

    @property
    def is_null(self) -> bool:
        """True for the null session (no nonces: HELLO, BOOT, NO_SESSION)."""
        return self.nh == NULL_NONCE and self.nb == NULL_NONCE

    def _state(self, direction: int, epoch: int) -> SipHash:
        st = self._states.get((direction, epoch))
        if st is None:
            if len(self._states) >= 4:        # old epochs: never needed again
                self._states.clear()
            st = SipHash(self.key).absorb(_LABEL + bytes([direction]) + struct.pack('<H', epoch)
                                          + self.nh + self.nb)
            self._states[(direction, epoch)] = st
        return st

    def tag(self, direction: int, full_seq: int, frame: Frame) -> bytes:
        """The 8-byte tag of ``frame`` sent in ``direction`` as the sender's frame
        number ``full_seq`` (32 bits; ``frame.seq`` is its low half)."""
        st = self._state(direction, (full_seq >> 16) & 0xFFFF)
        return _Q.pack(st.tag(frame.header() + bytes(frame.payload)))

    def seal(self, direction: int, full_seq: int, frame: Frame) -> Frame:
        """``frame`` with sequence number ``full_seq`` (low 16 bits) and its tag."""
        f = Frame(frame.type, full_seq & 0xFFFF, frame.payload, frame.ref, frame.flags, frame.version,
                  bytes(TAG_SIZE))
        return Frame(f.type, f.seq, f.payload, f.ref, f.flags, f.version, self.tag(direction, full_seq, f))

    def verify(self, direction: int, full_seq: int, frame: Frame) -> bool:
        """True when ``frame`` carries the tag of this session for ``full_seq``."""
        if len(frame.tag) != TAG_SIZE:
            return False
        return hmac.compare_digest(self.tag(direction, full_seq, frame), frame.tag)
