"""SipHash-2-4 (Aumasson and Bernstein, "SipHash: a fast short-input PRF", 2012) with a
64-bit output, in pure Python, able to resume from a saved state.

The board protocol's message authentication code (docs/protocol.md "Authentication")
is SipHash-2-4 under the installation's 128-bit key over a 24-byte prefix (direction,
sequence epoch, the session's two nonces) followed by the frame. The prefix is the same
for every frame of a session and direction, so its three blocks are absorbed once
(:meth:`SipHash.absorb`) and each frame continues from a copy of that state
(:meth:`SipHash.tag`): two or three compression blocks and the finalisation per frame.
The firmware does the same in C (firmware/lib/siphash.c); both are checked against the
reference vectors of the SipHash paper and against each other.

No rclpy, no I/O.
"""
from __future__ import annotations

import struct

KEY_SIZE = 16
TAG_SIZE = 8
_M = 0xFFFFFFFFFFFFFFFF
_Q = struct.Struct('<Q')
_QQ = struct.Struct('<QQ')


def _rounds(v0: int, v1: int, v2: int, v3: int, n: int) -> tuple[int, int, int, int]:
    """``n`` SipRounds on the state (each word 64 bits)."""
    for _ in range(n):
        v0 = (v0 + v1) & _M
        v1 = ((v1 << 13) | (v1 >> 51)) & _M
        v1 ^= v0
        v0 = ((v0 << 32) | (v0 >> 32)) & _M
        v2 = (v2 + v3) & _M
        v3 = ((v3 << 16) | (v3 >> 48)) & _M
        v3 ^= v2
        v0 = (v0 + v3) & _M
        v3 = ((v3 << 21) | (v3 >> 43)) & _M
        v3 ^= v0
        v2 = (v2 + v1) & _M
        v1 = ((v1 << 17) | (v1 >> 47)) & _M
        v1 ^= v2
        v2 = ((v2 << 32) | (v2 >> 32)) & _M
    return v0, v1, v2, v3


class SipHash:
    """A SipHash-2-4 computation that has absorbed a whole number of 8-byte blocks.

    Parameters
    ----------
    key : bytes
        The 128-bit key (16 bytes).
    """

    __slots__ = ('v', 'length')

    def __init__(self, key: bytes):
        if len(key) != KEY_SIZE:
            raise ValueError(f'SipHash key must be {KEY_SIZE} bytes, got {len(key)}')
        k0, k1 = _QQ.unpack(key)
        self.v = (k0 ^ 0x736F6D6570736575, k1 ^ 0x646F72616E646F6D,
                  k0 ^ 0x6C7967656E657261, k1 ^ 0x7465646279746573)
        self.length = 0

    def copy(self) -> 'SipHash':
        """An independent copy of this state."""
        c = SipHash.__new__(SipHash)
        c.v, c.length = self.v, self.length
        return c

    def absorb(self, data: bytes) -> 'SipHash':
        """Absorb ``data``, a multiple of 8 bytes long (ValueError otherwise); returns self."""
        if len(data) % 8:
            raise ValueError('absorb() takes whole 8-byte blocks; give the rest to tag()')
        v0, v1, v2, v3 = self.v
        for (m,) in _Q.iter_unpack(data):
            v3 ^= m
            v0, v1, v2, v3 = _rounds(v0, v1, v2, v3, 2)
            v0 ^= m
        self.v = (v0, v1, v2, v3)
        self.length += len(data)
        return self

    def tag(self, data: bytes = b'') -> int:
        """The 64-bit SipHash-2-4 of everything absorbed followed by ``data`` (any
        length), as an integer (the tag on the wire is its 8 little-endian bytes). The
        state itself is not changed."""
        n = len(data) - len(data) % 8
        v0, v1, v2, v3 = self.v
        for (m,) in _Q.iter_unpack(data[:n]):
            v3 ^= m
            v0, v1, v2, v3 = _rounds(v0, v1, v2, v3, 2)
            v0 ^= m
        total = self.length + len(data)
        last = int.from_bytes(data[n:], 'little') | ((total & 0xFF) << 56)
        v3 ^= last
        v0, v1, v2, v3 = _rounds(v0, v1, v2, v3, 2)
        v0 ^= last
        v2 ^= 0xFF
        v0, v1, v2, v3 = _rounds(v0, v1, v2, v3, 4)
        return v0 ^ v1 ^ v2 ^ v3


def siphash24(key: bytes, data: bytes) -> int:
    """SipHash-2-4 of ``data`` under the 16-byte ``key``, a 64-bit integer."""
    return SipHash(key).tag(bytes(data))


def siphash24_bytes(key: bytes, data: bytes) -> bytes:
    """SipHash-2-4 of ``data`` as its 8 little-endian bytes (the reference output)."""
    return _Q.pack(siphash24(key, data))
