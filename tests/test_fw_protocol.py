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
from sslfr_drivers.link.protocol import (FLAG_RESPONSE, MAX_PAYLOAD, SEQ_MOD, Frame, FrameError, Framer,
                                    SequenceTracker, crc16, decode_frame, encode_frame)


@pytest.fixture(scope='module', autouse=True)
def _hostlib():
    require('host')


def native():
    from sslfr_drivers.firmware import native as n
    return n


frames = st.builds(Frame, type=st.integers(0, 255), seq=st.integers(0, SEQ_MOD - 1),
                   payload=st.binary(max_size=MAX_PAYLOAD), ref=st.integers(0, SEQ_MOD - 1),
                   flags=st.sampled_from([0, FLAG_RESPONSE]), version=st.sampled_from([1, 1, 1, 2]))


def test_crc16_check_value_and_doc_example():
    n = native()
    assert n.crc16(b'123456789') == 0x29B1 == crc16(b'123456789')
    assert n.crc16(b'') == 0xFFFF
    raw = n.encode_frame(m.encode(m.Ping(100), 1))
    assert raw == encode_frame(m.encode(m.Ping(100), 1))
    assert raw.hex(' ').startswith('a5 5a 01 04 00 01 00 00 00 01 64 00 00 00')


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
                                           bytes(rng.randrange(256) for _ in range(rng.randrange(0, 40))))))
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
            m.MoveTo.TYPE: m.MoveTo, m.Stop.TYPE: m.Stop, m.Home.TYPE: m.Home, m.SetZero.TYPE: m.SetZero}


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


i32, u8, u16, u32 = (st.integers(-2**31, 2**31 - 1), st.integers(0, 255), st.integers(0, 65535),
                     st.integers(0, 2**32 - 1))
f32 = st.floats(width=32, allow_nan=False)


@settings(deadline=None)
@given(st.builds(m.Status, i32, i32, f32, u8, u8, u16, st.one_of(f32, st.just(math.nan)), u32))
def test_status_payload_equal(status):
    raw = native().pack_status(status)
    assert raw == status.pack()


@settings(deadline=None)
@given(st.builds(m.Info, u8, u8, u8, u8, st.just(1), u32,
                 st.text('abcdefghijklmnopqrstuvwxyz-0123456789', max_size=16).map(
                     lambda t: t.encode().ljust(16, b'\0'))))
def test_info_payload_equal(info):
    assert native().pack_info(info) == info.pack()


@settings(deadline=None)
@given(st.one_of(st.builds(ms.ThermocoupleSample, u32, u16, u16),
                 st.builds(ms.SwitchSample, u32, st.integers(0, 31)),
                 st.builds(ms.AlsSample, u32, u16, u8, u8)))
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


# ---------------------------------------------------------------- board sessions
def _session_frames(draw_ops, rnd):
    """A scripted host: new requests, retries (same seq), stale seqs, foreign versions,
    bad payloads, unknown types, garbage; returns wire chunks."""
    out, seq = [], 0
    last = None
    for op in draw_ops:
        if op == 'retry' and last is not None:
            out.append(last)
            continue
        if op == 'stale':
            s = (seq - rnd.randint(2, 30)) % SEQ_MOD
        elif op == 'jump':
            seq = (seq + rnd.randint(2, 40000)) % SEQ_MOD
            s = seq
        else:
            seq = (seq + 1) % SEQ_MOD
            s = seq
        mtype = rnd.choice([0x01, 0x02, 0x04, 0x05, 0x01, 0x03, 0x10, 0x42, 0x80, 0x99, 0x06])
        size = {0x01: 4, 0x06: 30, 0x10: 8}.get(mtype, 0)
        payload = bytes(rnd.randrange(256) for _ in range(size if rnd.random() < 0.85 else rnd.randrange(12)))
        if mtype == 0x06 and rnd.random() < 0.5:
            payload = m.ConfigRecord.defaults(0).pack()
        version = 2 if op == 'version' else 1
        raw = encode_frame(Frame(mtype, s, payload, 0, 0, version))
        if op == 'garbage':
            raw = bytes(rnd.randrange(256) for _ in range(rnd.randrange(20))) + raw
        last = raw
        out.append(raw)
    return out


@settings(deadline=None, max_examples=150)
@given(st.lists(st.sampled_from(['new', 'new', 'new', 'retry', 'stale', 'version', 'garbage', 'jump']),
                min_size=1, max_size=60), st.randoms(use_true_random=False))
def test_board_session_equals_simboard(ops, rnd):
    """The firmware's session + common requests answer byte for byte like the
    simulators' SimBoard (the Python model of the board protocol)."""
    from sslfr_drivers.sim.base import SimBoard
    py = SimBoard(board_id=7)
    fwb = native().Board(kind=0, board_id=7, name='sim-board')
    assert fwb.boot_bytes == py.take_output()
    for chunk in _session_frames(ops, rnd):
        py.receive(chunk)
        assert fwb.receive(chunk) == py.take_output(), chunk.hex(' ')


def test_board_watchdog_after_one_second_of_silence():
    b = native().Board()
    assert not b.watchdog(5000)                       # nothing heard yet: not armed
    b.receive(encode_frame(m.encode(m.Ping(1), 0)), now_ms=100)
    assert not b.watchdog(1100) and b.watchdog(1101) and not b.watchdog(5000)
    b.receive(encode_frame(m.encode(m.Ping(1), 1, None)), now_ms=6000)
    assert b.watchdog(7001) and b.counters()['watchdog_trips'] == 2
