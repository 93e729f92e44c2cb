"""Simulated XBee 802.15.4 coordinator (API mode with escaping, AP=2) in front of
several simulated remote boards.

Written from the XBee 802.15.4 (S1) user guide, independently of digi-xbee, so the
tests exercising digi-xbee against it check two implementations against each
other. The host side really uses digi-xbee's ``Raw802Device.open()``: the sim answers
the AT commands it reads at open (AP, HV, VR, SH, SL, NI, MY, CE, ...).

API frame: ``0x7E | length (u16 BE) | frame data | checksum``; checksum =
``0xFF - (sum(frame data) & 0xFF)``; in escaped mode every 0x7E, 0x7D, 0x11, 0x13
after the start delimiter is sent as ``0x7D, byte ^ 0x20``.

Frame types handled:

====  ===========================  =========================================
0x08  AT command (local; 0x09 queued) -> 0x88 AT command response
0x00  TX request, 64-bit address   -> 0x89 TX status (0 success, 1 no ACK)
0x10  Transmit request (64+16)     -> 0x8B transmit status (0 / 0x01 no ACK)
0x80  RX packet, 64-bit address    <- sent for every frame a remote board emits
====  ===========================  =========================================

A remote board that is "disconnected" (FaultInjector silence) or an unknown
address gets TX status 1 (no ACK) - the host counts those as transmit failures.
"""
from __future__ import annotations

from sslfr_sim.base import FaultInjector, SimBoard, _split_frames

START = 0x7E
ESCAPE = 0x7D
XON = 0x11
XOFF = 0x13
_SPECIAL = {START, ESCAPE, XON, XOFF}

#: AT parameters of the simulated local module: XB24-Axx-xx (HV 0x17) with an
#: 802.15.4 firmware (VR 0x10EF) -> digi-xbee detects RAW_802_15_4.
DEFAULT_AT = {
    'AP': b'\x02', 'HV': b'\x17\x4a', 'VR': b'\x10\xef', 'SH': b'\x00\x13\xa2\x00',
    'SL': b'\x40\x00\x00\x00', 'NI': b'SSLFR-COORD', 'MY': b'\x00\x00', 'CE': b'\x01',
    'ID': b'\x33\x32', 'CH': b'\x0c', 'BD': b'\x03', 'AO': b'\x00', 'SM': b'\x00',
}


def checksum(data: bytes) -> int:
    """XBee API frame checksum: 0xFF minus the low byte of the sum of the frame
    data bytes."""
    return 0xFF - (sum(data) & 0xFF)


def escape(data: bytes) -> bytes:
    """API mode 2 escaping: 0x7E, 0x7D, 0x11, 0x13 become 0x7D, byte ^ 0x20."""
    out = bytearray()
    for b in data:
        if b in _SPECIAL:
            out += bytes((ESCAPE, b ^ 0x20))
        else:
            out.append(b)
    return bytes(out)


def api_frame(data: bytes, escaped: bool = True) -> bytes:
    """Wrap frame data (type byte first) into a complete API frame."""
    body = len(data).to_bytes(2, 'big') + data + bytes((checksum(data),))
    return bytes((START,)) + (escape(body) if escaped else body)


class ApiParser:
    """Stateful parser of escaped API frames; yields frame data with a good checksum.
    ``bad_checksums`` counts rejected frames."""

    def __init__(self, escaped: bool = True):
        self.escaped = escaped
        self._buf = bytearray()
        self._esc = False
        self.bad_checksums = 0

    def feed(self, data: bytes) -> list[bytes]:
        """Complete API frames' data (type byte first) in ``data``; frames with a bad
        checksum are dropped and counted in ``bad_checksums``."""
        out: list[bytes] = []
        for b in data:
            if b == START:
                self._buf = bytearray((START,))
                self._esc = False
                continue
            if not self._buf:
                continue
            if self.escaped and b == ESCAPE:
                self._esc = True
                continue
            if self._esc:
                b ^= 0x20
                self._esc = False
            self._buf.append(b)
            if len(self._buf) >= 3:
                n = (self._buf[1] << 8) | self._buf[2]
                if len(self._buf) == 3 + n + 1:
                    data_ = bytes(self._buf[3:3 + n])
                    if checksum(data_) == self._buf[-1]:
                        out.append(data_)
                    else:
                        self.bad_checksums += 1
                    self._buf = bytearray()
        return out


class XBeeSimCoordinator:
    """Host object for :class:`~sslfr_sim.runner.Runner` (same interface
    as ``PlainHost``): a local XBee on the pty, remote boards by 64-bit address."""

    def __init__(self, at: dict[str, bytes] | None = None, rssi: int = 0x28):
        self.at = dict(DEFAULT_AT if at is None else at)
        self.rssi = rssi
        self.boards: list[tuple[bytes, SimBoard, FaultInjector]] = []
        self._parser = ApiParser(escaped=True)
        self._out = bytearray()
        self.tx_requests = 0
        self.tx_no_ack = 0
        self.at_commands = 0

    def add_board(self, address: bytes, board: SimBoard, faults: FaultInjector) -> None:
        """Put ``board`` behind the radio at 64-bit ``address`` (8 bytes), with its
        own fault injector."""
        if len(address) != 8:
            raise ValueError('XBee 64-bit address must be 8 bytes')
        self.boards.append((bytes(address), board, faults))

    def _board(self, address: bytes):
        for entry in self.boards:
            if entry[0] == address:
                return entry
        return None

    def _send(self, data: bytes) -> None:
        self._out += api_frame(data, escaped=self.at.get('AP') == b'\x02')

    def from_wire(self, data: bytes, now: float) -> None:
        """API frames from the host (``now`` [s, monotonic]): AT commands are
        answered, TX64 data goes to the addressed board."""
        for fd in self._parser.feed(data):
            self._handle(fd, now)

    def _handle(self, fd: bytes, now: float) -> None:
        ftype = fd[0]
        if ftype in (0x08, 0x09) and len(fd) >= 4:            # local AT command (0x09: queued)
            self.at_commands += 1
            frame_id, cmd, param = fd[1], fd[2:4].decode('ascii', 'replace'), fd[4:]
            if param:                                           # set: accept, store
                self.at[cmd] = bytes(param)
                status, value = 0, b''
            elif cmd in self.at:
                status, value = 0, self.at[cmd]
            else:
                status, value = 2, b''                          # invalid command
            if frame_id:
                self._send(bytes((0x88, frame_id)) + fd[2:4] + bytes((status,)) + value)
        elif ftype == 0x00 and len(fd) >= 11:                  # TX request 64-bit
            frame_id, dest, payload = fd[1], fd[2:10], fd[11:]
            ok = self._deliver(dest, payload, now)
            if frame_id:
                self._send(bytes((0x89, frame_id, 0 if ok else 1)))
        elif ftype == 0x10 and len(fd) >= 14:                  # transmit request 64+16
            frame_id, dest, payload = fd[1], fd[2:10], fd[14:]
            ok = self._deliver(dest, payload, now)
            if frame_id:
                self._send(bytes((0x8B, frame_id, 0xFF, 0xFE, 0, 0 if ok else 1, 0)))

    def _deliver(self, dest: bytes, payload: bytes, now: float) -> bool:
        self.tx_requests += 1
        entry = self._board(dest)
        if entry is None or entry[2].silent(now):
            self.tx_no_ack += 1
            return False
        _, board, faults = entry
        board.receive(faults.bytes(payload, now))
        return True

    def to_wire(self, now: float) -> bytes:
        """Boards' output as RX64 frames plus pending AT/TX status answers (``now``
        [s, monotonic])."""
        for addr, board, faults in self.boards:
            out = board.take_output()
            if not out:
                continue
            for frame in _split_frames(out):                # one board frame per RF packet
                data = faults.board_frames(frame, now)      # (<= 100 bytes, 802.15.4 max)
                if data:
                    self._send(bytes((0x80,)) + addr + bytes((self.rssi, 0)) + data)
        out = bytes(self._out)
        self._out.clear()
        return out
