"""The firmware's protocol code (``firmware/lib``) compiled for the host, through ctypes:
the CRC, encoder, deframer, sequence tracker, payload codecs and board session that the
ATmega328P runs, with the interface of :mod:`sslfr_drivers.link.protocol` where one exists,
so tests can drive both implementations with the same inputs. Pure Python + ctypes.
"""
from __future__ import annotations

import ctypes as C

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.protocol import MAX_FRAME, Frame, FrameError, decode_frame, tag_size
from sslfr_drivers.firmware import build, hostlib_path

_lib = None


def lib():
    """The loaded ``libsslfr_proto.so`` (built with ``make -C firmware host`` if needed)."""
    global _lib
    if _lib is None:
        build('host')
        L = C.CDLL(str(hostlib_path()))
        u8p, u32p = C.POINTER(C.c_uint8), C.POINTER(C.c_uint32)
        sig = {
            'hl_crc16': (C.c_uint16, [C.c_char_p, C.c_uint16, C.c_uint16]),
            'hl_encode': (C.c_uint8, [C.c_uint8, C.c_uint8, C.c_uint16, C.c_uint16, C.c_uint8, C.c_char_p,
                                      C.c_uint8, C.c_char_p, u8p]),
            'hl_decode': (C.c_uint8, [C.c_char_p, C.c_uint16, u32p, u8p, u8p]),
            'hl_siphash': (None, [C.c_char_p, C.c_char_p, C.c_uint8, u8p]),
            'hl_auth_tag': (None, [C.c_char_p, C.c_char_p, C.c_char_p, C.c_uint8, C.c_uint32, C.c_uint8,
                                   C.c_uint8, C.c_uint16, C.c_uint16, C.c_uint8, C.c_char_p, C.c_uint8, u8p]),
            'hl_board_nonce': (None, [C.c_char_p, C.c_uint32, C.c_uint32, u8p]),
            'hl_key_image': (None, [C.c_char_p, u8p]),
            'hl_key_load': (C.c_uint8, [C.c_char_p, u8p]),
            'hl_boot_count_next': (C.c_uint32, [C.c_uint32]),
            'hl_framer_size': (C.c_size_t, []), 'hl_framer_init': (None, [C.c_void_p]),
            'hl_framer_feed': (C.c_size_t, [C.c_void_p, C.c_char_p, C.c_size_t, u8p, C.c_size_t]),
            'hl_framer_counters': (None, [C.c_void_p, u32p]),
            'hl_tracker_size': (C.c_size_t, []), 'hl_tracker_init': (None, [C.c_void_p]),
            'hl_tracker_restart': (None, [C.c_void_p]), 'hl_tracker_accept': (C.c_uint8, [C.c_void_p, C.c_uint16]),
            'hl_tracker_counters': (None, [C.c_void_p, u32p]),
            'hl_request_size': (C.c_int8, [C.c_uint8]),
            'hl_parse_move_to': (C.c_uint8, [C.c_char_p, C.c_uint8, C.POINTER(C.c_int32), C.POINTER(C.c_float)]),
            'hl_parse_home': (C.c_uint8, [C.c_char_p, C.c_uint8, u8p, C.POINTER(C.c_float), C.POINTER(C.c_int32)]),
            'hl_parse_host_loss': (C.c_uint8, [C.c_char_p, C.c_uint8, u8p, u8p, C.POINTER(C.c_int32),
                                               C.POINTER(C.c_float), u32p]),
            'hl_msg_status': (C.c_uint8, [u8p, C.c_int32, C.c_int32, C.c_float, C.c_uint8, C.c_uint8, C.c_uint16,
                                          C.c_float, C.c_uint32]),
            'hl_msg_info': (C.c_uint8, [u8p, C.c_uint8, C.c_uint8, C.c_uint8, C.c_uint8, C.c_uint32, C.c_char_p]),
            'hl_msg_samples': (C.c_uint8, [u8p, C.c_uint8, C.c_uint32, C.c_uint16, C.c_uint16, C.c_uint8, C.c_uint8]),
            'hl_config_check': (C.c_uint8, [C.c_char_p, C.c_uint8]),
            'hl_config_defaults': (None, [C.c_uint8, u8p]),
            'hl_config_load': (C.c_uint8, [C.c_char_p, C.c_uint8, u8p]),
            'hl_config_image': (None, [C.c_char_p, u8p]),
            'hl_board_new': (C.c_void_p, [C.c_uint8, C.c_uint32, C.c_char_p, C.c_char_p, C.c_uint32, u8p,
                                          C.c_size_t]),
            'hl_board_open_provisioning': (None, [C.c_void_p, C.c_uint32]),
            'hl_board_rx': (C.c_size_t, [C.c_void_p, C.c_char_p, C.c_size_t, C.c_uint32, u8p, C.c_size_t]),
            'hl_board_watchdog': (C.c_uint8, [C.c_void_p, C.c_uint32]),
            'hl_board_counters': (None, [C.c_void_p, u32p]),
            'hl_board_free': (None, [C.c_void_p]),
        }
        for name, (res, args) in sig.items():
            fn = getattr(L, name)
            fn.restype, fn.argtypes = res, args
        _lib = L
    return _lib


def _buf(n: int):
    return (C.c_uint8 * n)()


def crc16(data: bytes, crc: int = 0xFFFF) -> int:
    """The firmware's CRC-16/CCITT-FALSE."""
    return lib().hl_crc16(bytes(data), len(data), crc)


def encode_frame(frame: Frame) -> bytes:
    """The firmware's encoder (FrameError for a payload above 88 bytes)."""
    out = _buf(MAX_FRAME)
    tag = bytes(frame.tag).ljust(8, b'\0')
    n = lib().hl_encode(frame.version, frame.flags, frame.seq, frame.ref, frame.type, bytes(frame.payload),
                        len(frame.payload), tag, out) if len(frame.payload) <= 255 else 0
    if n == 0:
        raise FrameError(f'payload of {len(frame.payload)} bytes')
    return bytes(out[:n])


DECODE_REASONS = {1: 'short', 2: 'sync', 3: 'length', 4: 'crc'}


def decode_frame_reason(data: bytes) -> Frame | str:
    """The firmware's single-frame decoder: the Frame, or why not ('short', 'sync',
    'length', 'crc')."""
    hdr = (C.c_uint32 * 6)()
    payload, tag = _buf(256), _buf(8)
    data = bytes(data)
    if len(data) > 0xFFFF:
        return 'length'
    r = lib().hl_decode(data, len(data), hdr, payload, tag)
    if r:
        return DECODE_REASONS[r]
    version, n, flags, seq, ref, mtype = hdr
    return Frame(mtype, seq, bytes(payload[:n]), ref, flags, version, bytes(tag[:tag_size(version)]))


def siphash24(key: bytes, data: bytes) -> bytes:
    """The firmware's SipHash-2-4 of ``data`` (at most 255 bytes) as 8 bytes."""
    out = _buf(8)
    lib().hl_siphash(bytes(key), bytes(data), len(data), out)
    return bytes(out)


def auth_tag(key: bytes, nh: bytes, nb: bytes, direction: int, full: int, frame: Frame) -> bytes:
    """The firmware's tag of ``frame`` in the session (``nh``, ``nb``) for frame number ``full``."""
    out = _buf(8)
    lib().hl_auth_tag(bytes(key), bytes(nh), bytes(nb), direction, full & 0xFFFFFFFF, frame.version,
                      frame.flags, frame.seq, frame.ref, frame.type, bytes(frame.payload), len(frame.payload), out)
    return bytes(out)


def board_nonce(key: bytes, boot_count: int, session_count: int) -> bytes:
    """The firmware's session nonce Nb."""
    out = _buf(8)
    lib().hl_board_nonce(bytes(key), boot_count & 0xFFFFFFFF, session_count & 0xFFFFFFFF, out)
    return bytes(out)


def key_image(key: bytes) -> bytes:
    """The EEPROM image of an installation key (key + CRC-16)."""
    out = _buf(18)
    lib().hl_key_image(bytes(key), out)
    return bytes(out)


def key_load(image: bytes) -> tuple[bool, bytes]:
    """What the firmware makes of a key image: (valid, key in use; the null key if not)."""
    out = _buf(16)
    ok = lib().hl_key_load(bytes(image), out)
    return bool(ok), bytes(out)


def boot_count_next(stored: int) -> int:
    """This start's boot count from the EEPROM's stored u32."""
    return lib().hl_boot_count_next(stored & 0xFFFFFFFF)


class Framer:
    """The firmware's deframer with the interface of :class:`protocol.Framer`."""

    def __init__(self) -> None:
        self._mem = C.create_string_buffer(lib().hl_framer_size())
        lib().hl_framer_init(self._mem)

    def feed(self, chunk: bytes) -> list[Frame]:
        chunk = bytes(chunk)
        cap = (len(chunk) + 1) * MAX_FRAME
        out = _buf(cap)
        n = lib().hl_framer_feed(self._mem, chunk, len(chunk), out, cap)
        raw = bytes(out[:n])
        frames, i = [], 0
        while i < len(raw):
            size = 12 + raw[i + 3]
            frames.append(decode_frame(raw[i:i + size]))
            i += size
        return frames

    def counters(self) -> dict:
        c = (C.c_uint32 * 6)()
        lib().hl_framer_counters(self._mem, c)
        return dict(zip(('frames_ok', 'crc_errors', 'length_errors', 'bytes_discarded', 'foreign_version',
                         'pending'), c))


class SequenceTracker:
    """The firmware's sequence tracker with the interface of :class:`protocol.SequenceTracker`."""

    VERDICTS = ('new', 'duplicate', 'stale')

    def __init__(self) -> None:
        self._mem = C.create_string_buffer(lib().hl_tracker_size())
        lib().hl_tracker_init(self._mem)

    def restart(self) -> None:
        lib().hl_tracker_restart(self._mem)

    def accept(self, seq: int) -> str:
        return self.VERDICTS[lib().hl_tracker_accept(self._mem, seq)]

    def counters(self) -> dict:
        c = (C.c_uint32 * 4)()
        lib().hl_tracker_counters(self._mem, c)
        return dict(zip(('received', 'lost', 'duplicates', 'stale'), c))


def request_size(mtype: int) -> int:
    """Payload size of a v1 request type, -1 when the type is not a request."""
    return lib().hl_request_size(mtype)


def parse_move_to(payload: bytes) -> tuple[int, int, float]:
    """(error code or 0, steps, speed) as the axis firmware parses MOVE_TO."""
    steps, speed = C.c_int32(), C.c_float()
    r = lib().hl_parse_move_to(bytes(payload), len(payload), C.byref(steps), C.byref(speed))
    return r, steps.value, speed.value


def parse_home(payload: bytes) -> tuple[int, int, float, int]:
    """(error code or 0, switch, speed, position) as the axis firmware parses HOME."""
    sw, speed, pos = C.c_uint8(), C.c_float(), C.c_int32()
    r = lib().hl_parse_home(bytes(payload), len(payload), C.byref(sw), C.byref(speed), C.byref(pos))
    return r, sw.value, speed.value, pos.value


def parse_host_loss(payload: bytes) -> tuple[int, int, int, int, float, int]:
    """(error code or 0, mode, switch, steps, speed, delay_ms) as the axis firmware parses
    SET_HOST_LOSS_STOW."""
    mode, sw, steps, speed, delay = C.c_uint8(), C.c_uint8(), C.c_int32(), C.c_float(), C.c_uint32()
    r = lib().hl_parse_host_loss(bytes(payload), len(payload), C.byref(mode), C.byref(sw), C.byref(steps),
                                 C.byref(speed), C.byref(delay))
    return r, mode.value, sw.value, steps.value, speed.value, delay.value


def pack_status(s: m.Status) -> bytes:
    out = _buf(64)
    n = lib().hl_msg_status(out, s.position, s.target, s.speed, s.flags, s.limit_bits, s.fault_bits,
                            s.sensor_angle, s.uptime_ms)
    return bytes(out[:n])


def pack_info(i: m.Info) -> bytes:
    out = _buf(64)
    n = lib().hl_msg_info(out, i.board_kind, i.fw_major, i.fw_minor, i.fw_patch, i.board_id,
                          i.name.rstrip(b'\0')[:16])
    return bytes(out[:n])


def pack_sample(msg) -> bytes:
    """ThermocoupleSample / SwitchSample / AlsSample / PulseSample payloads as the firmware
    builds them."""
    out = _buf(16)
    name = type(msg).__name__
    if name == 'ThermocoupleSample':
        n = lib().hl_msg_samples(out, 0, msg.board_ms, msg.inlet, msg.outlet, 0, 0)
    elif name == 'SwitchSample':
        n = lib().hl_msg_samples(out, 1, msg.board_ms, 0, 0, msg.bits, 0)
    elif name == 'PulseSample':
        n = lib().hl_msg_samples(out, 3, msg.board_ms, msg.count & 0xFFFF, msg.count >> 16, msg.pin, 0)
    else:
        n = lib().hl_msg_samples(out, 2, msg.board_ms, msg.count, 0, msg.gain_code, msg.it_code)
    return bytes(out[:n])


def config_check(record: bytes, kind: int) -> int:
    """0 when the firmware accepts the 30-byte record for a board of ``kind``, else the
    NACK code (OUT_OF_RANGE)."""
    return lib().hl_config_check(bytes(record), kind)


def config_defaults(kind: int) -> bytes:
    out = _buf(30)
    lib().hl_config_defaults(kind, out)
    return bytes(out)


def config_load(image: bytes, kind: int) -> tuple[bool, bytes]:
    """What the firmware makes of an EEPROM image: (valid, record in use)."""
    out = _buf(30)
    ok = lib().hl_config_load(bytes(image), kind, out)
    return bool(ok), bytes(out)


def config_image(record: bytes) -> bytes:
    out = _buf(32)
    lib().hl_config_image(bytes(record), out)
    return bytes(out)


#: the board session's counters (firmware/lib/session.h), as the harness reports them too
BOARD_COUNTERS = ('frames_in', 'frames_out', 'requests_stale', 'requests_duplicate', 'watchdog_trips',
                  'version_errors', 'auth_failures', 'no_session', 'sessions', 'boot_count', 'provision_refused')


class Board:
    """The firmware's board session with the common requests only (PING, GET_INFO,
    RESET, GET_CONFIG, SET_CONFIG; every other type UNKNOWN_TYPE), as a sensor board
    without samples: bytes in, bytes out, at a given board time."""

    def __init__(self, kind: int = 0, board_id: int = 1, name: str = 'sim-board', key: bytes | None = None,
                 boot_count: int = 0):
        self._out = _buf(1 << 16)
        self._b = lib().hl_board_new(kind, board_id, name.encode(), None if key is None else bytes(key),
                                     boot_count, self._out, len(self._out))
        self.boot_bytes = bytes(self._out[:12 + 8 + 2])

    def open_provisioning(self, now_ms: int) -> None:
        """Open the provisioning window at board time ``now_ms`` (an external reset)."""
        lib().hl_board_open_provisioning(self._b, now_ms & 0xFFFFFFFF)

    def receive(self, data: bytes, now_ms: int = 0) -> bytes:
        n = lib().hl_board_rx(self._b, bytes(data), len(data), now_ms & 0xFFFFFFFF, self._out, len(self._out))
        return bytes(self._out[:n])

    def watchdog(self, now_ms: int) -> bool:
        return bool(lib().hl_board_watchdog(self._b, now_ms & 0xFFFFFFFF))

    def counters(self) -> dict:
        c = (C.c_uint32 * 11)()
        lib().hl_board_counters(self._b, c)
        return dict(zip(BOARD_COUNTERS, c))

    def __del__(self):
        if getattr(self, '_b', None):
            lib().hl_board_free(self._b)
            self._b = None
