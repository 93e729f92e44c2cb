"""Frame codec, framer, sequence tracking and payload codecs (pure bytes, no I/O)."""
import math
import random
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.auth import HOST_TO_BOARD, Session
from sslfr_drivers.link.protocol import (FLAG_RESPONSE, MAX_PAYLOAD, PROTOCOL_V1, PROTOCOL_VERSION, SEQ_MOD,
                                         Frame, FrameError, Framer, PayloadError, ProtocolError,
                                         SequenceTracker, crc16, decode_frame, encode_frame)
from sslfr_drivers.link.siphash import siphash24_bytes

frames = st.builds(
    Frame,
    type=st.integers(0, 255),
    seq=st.integers(0, SEQ_MOD - 1),
    payload=st.binary(max_size=MAX_PAYLOAD),
    ref=st.integers(0, SEQ_MOD - 1),
    flags=st.sampled_from([0, FLAG_RESPONSE]),
    tag=st.binary(min_size=8, max_size=8),
)


def test_crc16_check_value():
    # CRC-16/CCITT-FALSE catalogue check value (reveng.sourceforge.io)
    assert crc16(b'123456789') == 0x29B1
    assert crc16(b'') == 0xFFFF


def test_known_frame_bytes():
    """A hand-checked frame (docs/protocol.md example): PING seq 1, host_ms 0x64, key
    00..0f, session nonces Nh = 01..08, Nb = 11..18; the tag is SipHash-2-4 of the
    24-byte prefix and bytes 2..13 of the frame."""
    key, nh, nb = bytes(range(16)), bytes(range(1, 9)), bytes(range(0x11, 0x19))
    raw = encode_frame(Session(key, nh, nb).seal(HOST_TO_BOARD, 1, m.encode(m.Ping(100), 0)))
    header = bytes([PROTOCOL_VERSION, 4 + 8, 0, 1, 0, 0, 0, 0x01])
    payload = struct.pack('<I', 100)
    prefix = b'sslfr' + bytes([1]) + b'\x00\x00' + nh + nb
    tag = siphash24_bytes(key, prefix + header + payload)
    body = header + payload + tag
    assert raw == b'\xa5\x5a' + body + struct.pack('<H', crc16(body))
    assert raw.hex(' ') == 'a5 5a 02 0c 00 01 00 00 00 01 64 00 00 00 ' + tag.hex(' ') + ' ' + \
        ' '.join(f'{b:02x}' for b in struct.pack('<H', crc16(body)))
    assert len(raw) == 12 + 4 + 8


def test_version1_frame_still_delimited_and_read():
    """A version-1 frame (no tag) is still found and decoded: the board is refused with
    a clear message and its INFO stays readable."""
    v1 = Frame(m.Info.TYPE, 3, m.Info(1, 1, 0, 0, 1, 7, b'old').pack(), 2, FLAG_RESPONSE,
               PROTOCOL_V1)
    assert v1.tag == b''
    raw = encode_frame(v1)
    assert raw[2:4] == bytes([1, 25]) and len(raw) == 12 + 25
    framer = Framer()
    (got,) = framer.feed(raw)
    assert got == v1 and framer.foreign_version == 1
    assert m.decode(got).protocol == 1


def test_version2_frame_shorter_than_its_tag_is_a_length_error():
    """A CRC-valid version-2 frame whose length cannot hold the tag is never delivered."""
    body = bytes([PROTOCOL_VERSION, 5, 0, 1, 0, 0, 0, 0x01]) + bytes(5)
    raw = b'\xa5\x5a' + body + struct.pack('<H', crc16(body))
    framer = Framer()
    assert framer.feed(raw) == [] and framer.length_errors == 1
    with pytest.raises(FrameError):
        decode_frame(raw)
    with pytest.raises(FrameError):          # and no frame is encoded without a whole tag
        encode_frame(Frame(1, 0, b'', version=PROTOCOL_VERSION, tag=b'1234'))


@settings(deadline=None)
@given(frames)
def test_roundtrip(frame):
    assert decode_frame(encode_frame(frame)) == frame


def test_payload_too_long_refused():
    with pytest.raises(FrameError):
        encode_frame(Frame(1, 0, bytes(MAX_PAYLOAD + 1)))
    assert MAX_PAYLOAD == 80
    assert len(encode_frame(Frame(1, 0, bytes(MAX_PAYLOAD)))) == 100   # one XBee packet
    assert len(encode_frame(Frame(1, 0, bytes(88), version=PROTOCOL_V1))) == 100


@settings(deadline=None)
@given(st.lists(frames, min_size=1, max_size=8), st.data())
def test_framer_any_chunking(frame_list, data):
    """Frames split across reads and merged in one read come out intact, in order."""
    wire = b''.join(encode_frame(f) for f in frame_list)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(wire)), max_size=12)))
    framer = Framer()
    out = []
    prev = 0
    for c in cuts + [len(wire)]:
        out += framer.feed(wire[prev:c])
        prev = c
    assert out == frame_list
    assert framer.pending == 0 and framer.bytes_discarded == 0


@settings(deadline=None)
@given(st.binary(max_size=300), frames, st.binary(max_size=300))
def test_resync_after_garbage(before, frame, after):
    framer = Framer()
    # garbage may itself contain valid frames by chance; the real one must be found
    out = framer.feed(before) + framer.feed(encode_frame(frame)) + framer.feed(after)
    assert frame in out


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=2000), st.integers(1, 64))
def test_fuzz_random_bytes(blob, chunk):
    framer = Framer()
    for i in range(0, len(blob), chunk):
        for f in framer.feed(blob[i:i + chunk]):
            # anything yielded re-encodes to bytes with a correct CRC
            assert decode_frame(encode_frame(f)) == f
            try:
                m.decode(f)
            except PayloadError:
                pass


def test_fuzz_one_percent_corrupted_frames():
    """10 000 frames, 1 % get 1-3 random bytes changed: no exception, no frame with a
    wrong CRC, every untouched frame recovered, corrupted ones never delivered."""
    rng = random.Random(1234)
    sent, corrupted = [], set()
    wire = bytearray()
    for i in range(10_000):
        f = Frame(rng.choice([0x01, 0x10, 0x83, 0xC1]), i % SEQ_MOD,
                  bytes(rng.randrange(256) for _ in range(rng.randrange(0, 40))))
        raw = bytearray(encode_frame(f))
        if rng.random() < 0.01:
            for _ in range(rng.randint(1, 3)):
                raw[rng.randrange(len(raw))] ^= rng.randrange(1, 256)
            if bytes(raw) != encode_frame(f):
                corrupted.add(i)
        sent.append(f)
        wire += raw
    framer = Framer()
    got = []
    pos = 0
    while pos < len(wire):
        n = rng.randint(1, 200)
        got += framer.feed(bytes(wire[pos:pos + n]))
        pos += n
    good = [f for i, f in enumerate(sent) if i not in corrupted]
    assert got == good            # exactly the intact frames, nothing invented
    assert 50 < len(corrupted) < 150
    assert framer.crc_errors > 0 and framer.bytes_discarded > 0


def test_decode_frame_errors_are_declared():
    good = encode_frame(Frame(1, 2, b'abc'))
    for bad in (b'', good[:-1], b'\x00' + good[1:], good[:-1] + bytes([good[-1] ^ 1]),
                good + b'x'):
        with pytest.raises(FrameError):
            decode_frame(bad)
    assert issubclass(FrameError, ProtocolError) and issubclass(PayloadError, ProtocolError)


# ------------------------------------------------------------ sequence tracking
def test_duplicate_and_stale_detected():
    t = SequenceTracker()
    assert [t.accept(s) for s in (10, 11, 11, 9, 12, 5, 14)] == \
        ['new', 'new', 'duplicate', 'stale', 'new', 'stale', 'new']
    assert (t.duplicates, t.stale, t.lost, t.received) == (1, 2, 1, 4)


@settings(deadline=None)
@given(st.integers(0, SEQ_MOD - 1), st.lists(st.integers(1, 300), min_size=1, max_size=400))
def test_loss_counter_exact_across_wrap(start, gaps):
    """Receive a subsequence of a stream that wraps 65535 -> 0: lost == skipped."""
    t = SequenceTracker()
    seq = start
    t.accept(seq)
    skipped = 0
    for g in gaps:
        seq = (seq + g) % SEQ_MOD
        skipped += g - 1
        assert t.accept(seq) == 'new'
    assert t.lost == skipped


@settings(deadline=None)
@given(st.integers(0, 2**32 - 1), st.lists(st.integers(-40000, 40000), min_size=1, max_size=50))
def test_expand_gives_the_full_number_within_the_window(start, steps):
    """The receiver recovers the sender's 32-bit frame number (the tag covers its
    epoch) from the 16 bits on the wire, for any frame within half the window of the
    last new one: new ones ahead, late or replayed ones behind."""
    t = SequenceTracker()
    t.last = start
    for d in steps:
        full = (t.last + d) % 2**32
        if abs(d) < SEQ_MOD // 2:
            assert t.expand(full % SEQ_MOD) == full
        verdict = t.accept(full % SEQ_MOD)
        if 0 < d < SEQ_MOD // 2:
            assert verdict == 'new' and t.last == full


def test_wrap_boundary_exact():
    t = SequenceTracker()
    for s in (65533, 65534, 1, 2, 2, 65535):
        t.accept(s)
    # 65535 and 0 lost; then a duplicate of 2; 65535 after 2 is stale (late)
    assert (t.lost, t.duplicates, t.stale) == (2, 1, 1)


# ------------------------------------------------------------ payload codecs
def _msg_strategy():
    i32 = st.integers(-2**31, 2**31 - 1)
    u8 = st.integers(0, 255)
    u16 = st.integers(0, 65535)
    u32 = st.integers(0, 2**32 - 1)
    f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
    return st.one_of(
        st.builds(m.Ping, u32), st.just(m.GetInfo()), st.just(m.GetStatus()),
        st.just(m.Stop()), st.just(m.Reset()),
        st.builds(m.MoveTo, i32, f32), st.builds(m.Home, u8, f32, i32), st.builds(m.SetZero, i32),
        st.builds(m.Ack, u8), st.builds(m.Nack, u8, u8),
        st.builds(m.Info, u8, u8, u8, u8, u8, u32, st.binary(max_size=16).map(
            lambda b: b + bytes(16 - len(b)))),
        st.builds(m.Status, i32, i32, f32, u8, u8, u16, f32, u32),
        st.builds(m.Boot, u8, u8),
    )


@settings(deadline=None)
@given(_msg_strategy(), st.integers(0, SEQ_MOD - 1))
def test_message_roundtrip(msg, seq):
    frame = decode_frame(encode_frame(m.encode(msg, seq)))
    assert m.decode(frame) == msg


@settings(deadline=None)
@given(st.integers(0, 255), st.binary(max_size=MAX_PAYLOAD))
def test_payload_decode_raises_only_payload_error(mtype, payload):
    try:
        m.decode(Frame(mtype, 0, payload))
    except PayloadError:
        pass


def test_nan_speed_refused_at_decode():
    frame = Frame(m.MoveTo.TYPE, 0, struct.pack('<if', 10, math.nan))
    with pytest.raises(PayloadError):
        m.decode(frame)


def test_registry_ranges_and_uniqueness():
    import sslfr_drivers.link.sensor_messages  # noqa: F401 - registers the sensor messages
    for code, cls in m.registry().items():
        in_sensor_range = code in m.SENSOR_REQUEST_RANGE or code in m.SENSOR_REPLY_RANGE
        assert in_sensor_range == (cls.__module__ != 'sslfr_drivers.link.messages'), cls
        assert cls.TYPE == code
    with pytest.raises(ValueError):
        @m.register
        class Clash(m.Message):  # noqa: F811 - deliberately reuses PING's code
            TYPE = 0x01
