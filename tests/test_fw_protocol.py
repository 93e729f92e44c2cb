"""The firmware's protocol code (firmware/lib, compiled for the host) against the Python
codec (sslfr_drivers.link.protocol, messages*), frame for frame: the vectors and Hypothesis
strategies of src/sslfr_drivers/test/test_protocol.py plus corrupted and split input,
and whole board sessions (duplicates, stale requests, versions, RESET) against the
simulators' SimBoard."""
from __future__ import annotations

import math
import random
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fw_support import require

from sslfr_drivers.link import messages as m
from sslfr_drivers.link import sensor_messages as ms
from sslfr_drivers.link.auth import BOARD_TO_HOST, HOST_TO_BOARD, NULL_KEY, Session, board_nonce
from sslfr_drivers.link.protocol import (FLAG_RESPONSE, MAX_PAYLOAD, PROTOCOL_V1, PROTOCOL_VERSION, SEQ_MOD,
                                         Frame, FrameError, Framer, SequenceTracker, crc16, decode_frame,
                                         encode_frame)
from sslfr_drivers.link.siphash import siphash24_bytes


@pytest.fixture(scope='module', autouse=True)
def _hostlib():
    require('host')


def native():
    from sslfr_sim import fw_native as n
    return n


def _frame(type, seq, payload, ref, flags, version, tag):
    return Frame(type, seq, payload, ref, flags, version, tag if version == PROTOCOL_VERSION else b'')


frames = st.builds(_frame, type=st.integers(0, 255), seq=st.integers(0, SEQ_MOD - 1),
                   payload=st.binary(max_size=MAX_PAYLOAD), ref=st.integers(0, SEQ_MOD - 1),
                   flags=st.sampled_from([0, FLAG_RESPONSE]), version=st.sampled_from([2, 2, 2, 1, 3]),
                   tag=st.binary(min_size=8, max_size=8))


def test_crc16_check_value_and_doc_example():
    n = native()
    assert n.crc16(b'123456789') == 0x29B1 == crc16(b'123456789')
    assert n.crc16(b'') == 0xFFFF
    key, nh, nb = bytes(range(16)), bytes(range(1, 9)), bytes(range(0x11, 0x19))
    sealed = Session(key, nh, nb).seal(HOST_TO_BOARD, 1, m.encode(m.Ping(100), 0))
    raw = n.encode_frame(sealed)
    assert raw == encode_frame(sealed)
    assert raw.hex(' ').startswith('a5 5a 02 0c 00 01 00 00 00 01 64 00 00 00 ' + sealed.tag.hex(' '))
    assert n.auth_tag(key, nh, nb, HOST_TO_BOARD, 1, sealed) == sealed.tag


@settings(deadline=None, max_examples=300)
@given(st.binary(max_size=300), st.integers(0, 0xFFFF))
def test_crc_equal(data, init):
    assert native().crc16(data, init) == crc16(data, init)


@settings(deadline=None)
@given(frames)
def test_encode_equal_and_roundtrip(frame):
    raw = native().encode_frame(frame)
    assert raw == encode_frame(frame)
    assert native().decode_frame_reason(raw) == frame == decode_frame(raw)


def test_payload_too_long_refused_by_both():
    with pytest.raises(FrameError):
        native().encode_frame(Frame(1, 0, bytes(MAX_PAYLOAD + 1)))
    assert len(native().encode_frame(Frame(1, 0, bytes(MAX_PAYLOAD)))) == 100
    assert len(native().encode_frame(Frame(1, 0, bytes(88), version=PROTOCOL_V1))) == 100


@settings(deadline=None, max_examples=300)
@given(st.binary(max_size=120))
def test_single_frame_decoder_agrees(blob):
    got = native().decode_frame_reason(blob)
    try:
        want = decode_frame(blob)
    except FrameError:
        assert isinstance(got, str)
    else:
        assert got == want


def _feed_both(chunks):
    py, fw = Framer(), native().Framer()
    out_py, out_fw = [], []
    for c in chunks:
        out_py += py.feed(c)
        out_fw += fw.feed(c)
    c = fw.counters()
    assert out_fw == out_py
    assert (c['frames_ok'], c['crc_errors'], c['length_errors'], c['bytes_discarded'], c['foreign_version'],
            c['pending']) == (py.frames_ok, py.crc_errors, py.length_errors, py.bytes_discarded,
                              py.foreign_version, py.pending)
    return out_fw


@settings(deadline=None)
@given(st.lists(frames, min_size=1, max_size=8), st.data())
def test_framer_any_chunking(frame_list, data):
    wire = b''.join(encode_frame(f) for f in frame_list)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(wire)), max_size=12)))
    chunks, prev = [], 0
    for c in cuts + [len(wire)]:
        chunks.append(wire[prev:c])
        prev = c
    assert _feed_both(chunks) == frame_list


@settings(deadline=None)
@given(st.binary(max_size=300), frames, st.binary(max_size=300))
def test_resync_after_garbage(before, frame, after):
    assert frame in _feed_both([before, encode_frame(frame), after])


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=2000), st.integers(1, 64))
def test_fuzz_random_bytes(blob, chunk):
    _feed_both([blob[i:i + chunk] for i in range(0, len(blob), chunk)])


@settings(max_examples=100, deadline=None)
@given(st.lists(frames, min_size=1, max_size=20), st.randoms(use_true_random=False))
def test_corrupted_and_split_streams(frame_list, rnd):
    """Frames with bytes flipped, dropped and inserted, split at random: same frames,
    same counters."""
    wire = bytearray()
    for f in frame_list:
        raw = bytearray(encode_frame(f))
        r = rnd.random()
        if r < 0.2:
            raw[rnd.randrange(len(raw))] ^= 1 << rnd.randrange(8)
        elif r < 0.3:
            del raw[rnd.randrange(len(raw))]
        elif r < 0.4:
            raw.insert(rnd.randrange(len(raw)), 0xA5)
        wire += raw
    chunks, i = [], 0
    while i < len(wire):
        n = rnd.randint(1, 40)
        chunks.append(bytes(wire[i:i + n]))
        i += n
    _feed_both(chunks)


def test_one_percent_corrupted_frames():
    rng = random.Random(1234)
    wire = bytearray()
    for i in range(10_000):
        raw = bytearray(encode_frame(Frame(rng.choice([0x01, 0x10, 0x83, 0xC1]), i % SEQ_MOD,
                                           bytes(rng.randrange(256) for _ in range(rng.randrange(0, 40))),
                                           tag=rng.randbytes(8))))
        if rng.random() < 0.01:
            for _ in range(rng.randint(1, 3)):
                raw[rng.randrange(len(raw))] ^= rng.randrange(1, 256)
        wire += raw
    chunks, pos = [], 0
    while pos < len(wire):
        n = rng.randint(1, 200)
        chunks.append(bytes(wire[pos:pos + n]))
        pos += n
    got = _feed_both(chunks)
    assert 9_850 < len(got) < 9_950


# ---------------------------------------------------------------- sequence tracking
def _track_both(seqs):
    py, fw = SequenceTracker(), native().SequenceTracker()
    for s in seqs:
        assert fw.accept(s) == py.accept(s), s
    c = fw.counters()
    assert (c['received'], c['lost'], c['duplicates'], c['stale']) == (py.received, py.lost, py.duplicates,
                                                                       py.stale)


def test_duplicate_stale_and_wrap_vectors():
    _track_both([10, 11, 11, 9, 12, 5, 14])
    _track_both([65533, 65534, 1, 2, 2, 65535])


@settings(deadline=None)
@given(st.lists(st.integers(0, SEQ_MOD - 1), max_size=200), st.integers(0, SEQ_MOD - 1))
def test_tracker_random(seqs, start):
    _track_both([start] + [(start + s) % SEQ_MOD if i % 2 else s for i, s in enumerate(seqs)])


# ---------------------------------------------------------------- payload codecs
REQUESTS = {m.Ping.TYPE: m.Ping, m.GetInfo.TYPE: m.GetInfo, m.GetStatus.TYPE: m.GetStatus,
            m.Reset.TYPE: m.Reset, m.GetConfig.TYPE: m.GetConfig, m.SetConfig.TYPE: m.SetConfig,
            m.MoveTo.TYPE: m.MoveTo, m.Stop.TYPE: m.Stop, m.Home.TYPE: m.Home, m.SetZero.TYPE: m.SetZero,
            m.Hello.TYPE: m.Hello, m.Provision.TYPE: m.Provision, m.SetHostLossStow.TYPE: m.SetHostLossStow,
            ms.SetPulseInput.TYPE: ms.SetPulseInput}


def test_request_registry_equal():
    n = native()
    for code in range(256):
        cls = m.registry().get(code)
        is_request = cls is not None and cls.RESPONSE
        assert (n.request_size(code) >= 0) == is_request, hex(code)
        if is_request:
            assert code in REQUESTS


@settings(deadline=None, max_examples=400)
@given(st.sampled_from([m.MoveTo.TYPE, m.Home.TYPE]), st.one_of(
    st.binary(max_size=12),
    st.builds(lambda a, b: struct.pack('<if', a, b), st.integers(-2**31, 2**31 - 1), st.floats(width=32)),
    st.builds(lambda s, b, p: struct.pack('<Bfi', s, b, p), st.integers(0, 255), st.floats(width=32),
              st.integers(-2**31, 2**31 - 1))))
def test_request_payload_verdicts_equal(mtype, payload):
    """BAD_PAYLOAD exactly where messages.decode raises PayloadError; same values."""
    n = native()
    try:
        msg = m.decode(Frame(mtype, 0, payload))
    except m.PayloadError if hasattr(m, 'PayloadError') else Exception:
        msg = None
    if mtype == m.MoveTo.TYPE:
        code, steps, speed = n.parse_move_to(payload)
        assert (code == 0) == (msg is not None)
        if msg is not None:
            assert (steps, speed) == (msg.steps, msg.speed)
    else:
        code, sw, speed, pos = n.parse_home(payload)
        assert (code == 0) == (msg is not None)
        if msg is not None:
            assert (sw, speed, pos) == (msg.switch, msg.speed, msg.position)


@settings(deadline=None, max_examples=300)
@given(st.one_of(st.binary(max_size=16),
                 st.builds(lambda *a: struct.pack('<BBifI', *a), st.integers(0, 255), st.integers(0, 255),
                           st.integers(-2**31, 2**31 - 1), st.floats(width=32), st.integers(0, 2**32 - 1))))
def test_host_loss_stow_payload_verdicts_equal(payload):
    """SET_HOST_LOSS_STOW: BAD_PAYLOAD exactly where messages.decode raises; same values."""
    try:
        msg = m.decode(Frame(m.SetHostLossStow.TYPE, 0, payload))
    except Exception:  # noqa: BLE001 - PayloadError
        msg = None
    code, mode, sw, steps, speed, delay = native().parse_host_loss(payload)
    assert (code == 0) == (msg is not None)
    if msg is not None:
        assert (mode, sw, steps, speed, delay) == (msg.mode, msg.switch, msg.steps, msg.speed, msg.delay_ms)


i32, u8, u16, u32 = (st.integers(-2**31, 2**31 - 1), st.integers(0, 255), st.integers(0, 65535),
                     st.integers(0, 2**32 - 1))
f32 = st.floats(width=32, allow_nan=False)


@settings(deadline=None)
@given(st.builds(m.Status, i32, i32, f32, u8, u8, u16, st.one_of(f32, st.just(math.nan)), u32))
def test_status_payload_equal(status):
    raw = native().pack_status(status)
    assert raw == status.pack()


@settings(deadline=None)
@given(st.builds(m.Info, u8, u8, u8, u8, st.just(PROTOCOL_VERSION), u32,
                 st.text('abcdefghijklmnopqrstuvwxyz-0123456789', max_size=16).map(
                     lambda t: t.encode().ljust(16, b'\0'))))
def test_info_payload_equal(info):
    assert native().pack_info(info) == info.pack()


@settings(deadline=None)
@given(st.one_of(st.builds(ms.ThermocoupleSample, u32, u16, u16),
                 st.builds(ms.SwitchSample, u32, st.integers(0, 31)),
                 st.builds(ms.AlsSample, u32, u16, u8, u8),
                 st.builds(ms.PulseSample, u32, u32, u8)))
def test_sample_payloads_equal(sample):
    assert native().pack_sample(sample) == sample.pack()


@settings(deadline=None, max_examples=300)
@given(st.builds(m.ConfigRecord, st.just(1), st.sampled_from([1, 0x10, 0x11, 0x12]), u32,
                 st.sampled_from([9600, 57600, 115200, 1234]), st.sampled_from([0, 1, 2, 3, 0xFF]),
                 st.integers(0, 31), st.floats(width=32), st.floats(width=32), i32, i32, u16))
def test_config_record_layout_and_defaults(rec):
    n = native()
    raw = rec.pack()
    assert len(raw) == 30
    ok, used = n.config_load(n.config_image(raw), rec.kind)
    assert ok == (n.config_check(raw, rec.kind) == 0) == (rec.check(rec.kind) == 0)
    assert used == (raw if ok else n.config_defaults(rec.kind))
    assert n.config_image(raw) == rec.eeprom_image()
    for kind in (1, 0x10, 0x11, 0x12):
        assert n.config_defaults(kind) == m.ConfigRecord.defaults(kind).pack()
    assert n.config_load(b'\xff' * 32, 1) == (False, m.ConfigRecord.defaults(1).pack())


# ---------------------------------------------------------------- authentication
def test_siphash_reference_vectors():
    """The SipHash paper's vectors (key 00..0f, messages 00, 00 01, ...: the first, the
    8-byte one and the 15-byte one of its appendix)."""
    n, key = native(), bytes(range(16))
    assert n.siphash24(key, b'') == bytes.fromhex('310e0edd47db6f72')
    assert n.siphash24(key, bytes(range(8))) == bytes.fromhex('6224939a79f5f593')
    assert n.siphash24(key, bytes(range(15))) == bytes.fromhex('e545be4961ca29a1')
    for k in range(64):
        assert n.siphash24(key, bytes(range(k))) == siphash24_bytes(key, bytes(range(k)))


@settings(deadline=None, max_examples=300)
@given(st.binary(min_size=16, max_size=16), st.binary(max_size=255))
def test_siphash_equal(key, data):
    assert native().siphash24(key, data) == siphash24_bytes(key, data)


nonces = st.binary(min_size=8, max_size=8)


@settings(deadline=None, max_examples=300)
@given(st.binary(min_size=16, max_size=16), nonces, nonces, st.sampled_from([HOST_TO_BOARD, BOARD_TO_HOST]),
       st.integers(0, 2**32 - 1), frames)
def test_tags_equal(key, nh, nb, direction, full, frame):
    """The firmware's tag of any frame, session, direction and frame number (the epoch
    included) is the Python one; both verify each other's frames."""
    frame = Frame(frame.type, full & 0xFFFF, frame.payload, frame.ref, frame.flags)
    sealed = Session(key, nh, nb).seal(direction, full, frame)
    assert native().auth_tag(key, nh, nb, direction, full, frame) == sealed.tag
    assert native().encode_frame(sealed) == encode_frame(sealed)


@settings(deadline=None)
@given(st.binary(min_size=16, max_size=16), st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1))
def test_board_nonce_and_eeprom_images_equal(key, boot, count):
    from sslfr_drivers.firmware import key_eeprom_image
    n = native()
    assert n.board_nonce(key, boot, count) == board_nonce(key, boot, count)
    assert n.key_image(key) == key_eeprom_image(key)
    assert n.key_load(key_eeprom_image(key)) == (True, key)
    assert n.key_load(b'\xff' * 18) == (False, NULL_KEY)
    assert n.boot_count_next(0xFFFFFFFF) == 1 and n.boot_count_next(boot % 0xFFFFFFFF) == boot % 0xFFFFFFFF + 1


# ---------------------------------------------------------------- board sessions
class _ScriptHost:
    """A host scripted at random against a board pair: sessions (HELLO, retried HELLO),
    requests in the session (new, retried, stale), forgeries (random tags, bit flips,
    frames of an older session, another installation's key, version 1, PROVISION
    outside its window), garbage. It follows the Python board's answers (HELLO_REPLY)."""

    OPS = ['new'] * 6 + ['retry', 'stale', 'hello', 'hello_retry', 'forged', 'flip', 'old_session',
                         'other_key', 'version', 'garbage', 'provision', 'time']

    def __init__(self, key, rnd):
        self.key, self.rnd = key, rnd
        self.null_seq, self.session, self.tx = 0, None, 0
        self.last = self.last_hello = self.hello_nonce = None
        self.recorded = []                    # frames of earlier sessions

    def request_frame(self):
        rnd = self.rnd
        mtype = rnd.choice([0x01, 0x02, 0x04, 0x05, 0x01, 0x03, 0x10, 0x42, 0x80, 0x99, 0x06, 0x01, 0x02])
        size = {0x01: 4, 0x06: 30, 0x10: 8}.get(mtype, 0)
        payload = bytes(rnd.randrange(256) for _ in range(size if rnd.random() < 0.85 else rnd.randrange(12)))
        if mtype == 0x06 and rnd.random() < 0.5:
            payload = m.ConfigRecord.defaults(0).pack()
        return Frame(mtype, 0, payload)

    def chunk(self, op, now_ms):
        rnd = self.rnd
        if op == 'retry' and self.last is not None:
            return self.last
        if op == 'hello_retry' and self.last_hello is not None:
            return self.last_hello
        if op in ('hello', 'hello_retry') or (self.session is None and op in ('new', 'retry', 'stale')):
            self.null_seq += 1
            self.hello_nonce = rnd.randbytes(8)
            raw = encode_frame(Session(self.key).seal(HOST_TO_BOARD, self.null_seq,
                                                      m.encode(m.Hello(self.hello_nonce), 0)))
            self.last_hello = raw
            return raw
        if op == 'provision':
            self.null_seq += 1
            return encode_frame(Session(NULL_KEY).seal(HOST_TO_BOARD, self.null_seq,
                                                       m.encode(m.Provision(rnd.randbytes(16)), 0)))
        if op == 'version':
            return encode_frame(Frame(0x01, rnd.randrange(SEQ_MOD), bytes(4), version=PROTOCOL_V1, tag=b''))
        if op == 'garbage':
            return bytes(rnd.randrange(256) for _ in range(rnd.randrange(1, 20)))
        if op == 'old_session':
            return rnd.choice(self.recorded) if self.recorded else b''
        f = self.request_frame()
        if op == 'other_key':
            return encode_frame(Session(rnd.randbytes(16), rnd.randbytes(8), rnd.randbytes(8)).seal(
                HOST_TO_BOARD, self.tx, f))
        if self.session is None:
            return b''
        if op == 'stale':
            full = max(0, self.tx - rnd.randint(2, 30))
        else:
            full = self.tx
            self.tx += 1
        sealed = self.session.seal(HOST_TO_BOARD, full, f)
        if op == 'forged':
            sealed = Frame(sealed.type, sealed.seq, sealed.payload, tag=rnd.randbytes(8))
        raw = bytearray(encode_frame(sealed))
        if op == 'flip':                      # a bit flipped, the CRC made right again
            k = rnd.randrange(2, len(raw) - 2)
            raw[k] ^= 1 << rnd.randrange(8)
            raw[-2:] = crc16(bytes(raw[2:-2])).to_bytes(2, 'little')
            if raw[3] != len(raw) - 12:
                return b''                    # the length byte flipped: not one frame any more
        raw = bytes(raw)
        if op == 'new':
            self.last = raw
            self.recorded.append(raw)
        return raw

    def follow(self, out):
        """Adopt the session of a HELLO_REPLY to our latest HELLO; forget it at BOOT."""
        for f in Framer().feed(out):
            if f.type == m.HelloReply.TYPE and self.hello_nonce is not None:
                cand = Session(self.key, self.hello_nonce, m.decode(f).nonce)
                if cand.verify(BOARD_TO_HOST, f.seq, f):
                    self.session, self.tx = cand, 0
            elif f.type == m.Boot.TYPE:
                self.session = None


@settings(deadline=None, max_examples=150)
@given(st.lists(st.sampled_from(_ScriptHost.OPS), min_size=1, max_size=60), st.randoms(use_true_random=False))
def test_board_session_equals_simboard(ops, rnd):
    """The firmware's session + common requests answer byte for byte like the simulators'
    SimBoard (the Python model of the board protocol), counters included, through
    sessions, retries, replays and forgeries."""
    from sslfr_sim.fw_native import BOARD_COUNTERS
    from sslfr_sim.base import SimBoard
    key = rnd.randbytes(16)
    py = SimBoard(board_id=7, key=key)
    fwb = native().Board(kind=0, board_id=7, key=key)
    assert fwb.boot_bytes == py.take_output()
    host, now_ms = _ScriptHost(key, rnd), 0
    names = [k for k in BOARD_COUNTERS if k not in ('watchdog_trips', 'boot_count')]
    since_boot = dict.fromkeys(names, 0)      # the firmware's counters restart at a reset
    boot = py._boot

    def rebooted(now):
        since_boot.update({k: getattr(py, k) for k in names})
        boot(now)
    py._boot = rebooted
    for op in ops:
        if op == 'time':
            now_ms += rnd.choice([0, 125, 250, 10_000])
            py.tick(now_ms / 1000)
            continue
        chunk = host.chunk(op, now_ms)
        py.receive(chunk)
        out = py.take_output()
        assert fwb.receive(chunk, now_ms) == out, (op, chunk.hex(' '))
        host.follow(out)
    c = fwb.counters()
    assert {k: c[k] for k in names} == {k: getattr(py, k) - since_boot[k] for k in names}
    assert c['boot_count'] == py.boot_count


def test_forged_frames_never_executed_counters_exact():
    """On the firmware's session code: 200 requests each with a random tag, 200 with one
    bit flipped, 50 replays of answered requests, 50 under another key, 20 of an earlier
    session: none is executed (no ACK, no frames_in), every one counted once; the
    refusals are rate-limited (at most one per 50 ms)."""
    rnd = random.Random(19)
    key = rnd.randbytes(16)
    b = native().Board(kind=0, board_id=3, key=key)
    host = _ScriptHost(key, rnd)
    host.follow(b.receive(host.chunk('hello', 0), 0))
    old = host.session
    sent = [host.chunk('new', 0) for _ in range(5)]
    for raw in sent:
        b.receive(raw, 0)
    host.follow(b.receive(host.chunk('hello', 0), 0))
    assert host.session is not old
    b.receive(encode_frame(host.session.seal(HOST_TO_BOARD, host.tx, m.encode(m.Ping(1), 0))), 0)
    host.tx += 1
    answered = [encode_frame(host.session.seal(HOST_TO_BOARD, host.tx + i, m.encode(m.Ping(i), 0)))
                for i in range(50)]
    host.tx += 50
    for raw in answered:
        b.receive(raw, 0)
    before = b.counters()
    t, nacks = 0, []
    forged = [host.chunk('forged', 0) for _ in range(200)]
    flipped = []
    while len(flipped) < 200:
        raw = host.chunk('flip', 0)
        if raw:
            flipped.append(raw)
    others = [host.chunk('other_key', 0) for _ in range(50)]
    for raw in forged + flipped + answered[:49] + others + sent[:5] * 4:
        t += 10
        out = b.receive(raw, t)
        nacks += [m.decode(f) for f in Framer().feed(out)]
    c = b.counters()
    assert c['frames_in'] == before['frames_in']           # nothing executed
    # a flipped bit makes the tag fail (or, in the version byte, a foreign version)
    assert c['auth_failures'] - before['auth_failures'] + c['version_errors'] - before['version_errors'] \
        == 200 + 200 + 50 + 20
    assert c['requests_stale'] - before['requests_stale'] == 49
    assert c['requests_duplicate'] == before['requests_duplicate']
    assert all(isinstance(n, m.Nack) and n.code in (m.ErrorCode.AUTH, m.ErrorCode.REPLAY, m.ErrorCode.VERSION)
               for n in nacks)
    assert 0 < len(nacks) <= t // 50 + 1


def test_board_watchdog_after_one_second_of_silence():
    key = bytes(range(16))
    b = native().Board(key=key)
    host = _ScriptHost(key, random.Random(1))
    host.follow(b.receive(host.chunk('hello', 0), 0))
    forged = host.chunk('forged', 0)
    ping = [encode_frame(host.session.seal(HOST_TO_BOARD, i, m.encode(m.Ping(1), 0))) for i in range(2)]
    assert not b.watchdog(5000)                       # nothing heard yet: not armed
    b.receive(forged, now_ms=50)                       # a forgery does not arm or feed it
    assert not b.watchdog(5000)
    b.receive(ping[0], now_ms=100)
    b.receive(forged, now_ms=1000)
    assert not b.watchdog(1100) and b.watchdog(1101) and not b.watchdog(5000)
    b.receive(ping[1], now_ms=6000)
    assert b.watchdog(7001) and b.counters()['watchdog_trips'] == 2


def test_provisioning_only_in_the_window_after_an_external_reset():
    """PROVISION is refused LOCKED (counted) without the window and after it closes; in
    it the board takes the key, answers ACK under the new key and then opens sessions
    only with it. Python SimBoard and firmware alike."""
    from sslfr_sim.base import SimBoard
    old, new = bytes(range(16)), bytes(range(100, 116))
    for b in (native().Board(kind=0, key=old), None):
        py = SimBoard(key=old) if b is None else None
        py and py.take_output()

        def rx(raw, now_ms, b=b, py=py):
            if b is not None:
                return b.receive(raw, now_ms)
            py.tick(now_ms / 1000)
            py.receive(raw)
            return py.take_output()

        def provision(seq, key, now_ms):
            raw = encode_frame(Session(NULL_KEY).seal(HOST_TO_BOARD, seq, m.encode(m.Provision(key), 0)))
            return [(f, m.decode(f)) for f in Framer().feed(rx(raw, now_ms))]

        ((f, nack),) = provision(1, new, 0)
        assert nack == m.Nack(m.Provision.TYPE, m.ErrorCode.LOCKED) and Session(old).verify(BOARD_TO_HOST, f.seq, f)
        if b is not None:
            b.open_provisioning(1000)
        else:
            py.tick(1.0)
            py.open_provisioning()
        ((f, ack),) = provision(2, new, 1500)
        assert ack == m.Ack(m.Provision.TYPE) and Session(new).verify(BOARD_TO_HOST, f.seq, f)
        assert provision(3, old, 11_000)[0][1].code == m.ErrorCode.LOCKED       # the window closed
        host = _ScriptHost(new, random.Random(2))
        host.follow(rx(host.chunk('hello', 0), 11_100))
        assert host.session is not None
        stale = _ScriptHost(old, random.Random(3))
        stale.follow(rx(stale.chunk('hello', 0), 11_200))
        assert stale.session is None
        counters = b.counters() if b is not None else {'provision_refused': py.provision_refused}
        assert counters['provision_refused'] == 2
