"""Authentication of the board protocol on the host (issue 19): SipHash, tags, key files,
and BoardLink against forged, bit-flipped, replayed and foreign-key board frames (a
simulated board behind a real pty, frames injected into its stream)."""
import os
import random
import select
import stat
import threading
import time
import tty

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.auth import BOARD_TO_HOST, HOST_TO_BOARD, NULL_KEY, Session, key_id
from sslfr_drivers.link.board_link import BoardLink, BoardLinkState
from sslfr_drivers.link.keys import (KeyFileError, link_key, load_key, permission_problem, write_key_file)
from sslfr_drivers.link.protocol import (MAX_PAYLOAD, SEQ_MOD, Frame, Framer, crc16, decode_frame,
                                         encode_frame)
from sslfr_drivers.link.siphash import SipHash, siphash24_bytes
from sslfr_drivers.link.transport import SerialTransport
from sslfr_sim.axis import AxisConfig, AxisSim

from drivers_testutil import wait_for

KEY = bytes(range(16))


# ------------------------------------------------------------------ SipHash and tags
def test_siphash_reference_vectors():
    """SipHash-2-4 paper, appendix A (key 00..0f, message 00..0e) and its vectors.h."""
    assert siphash24_bytes(KEY, bytes(range(15))) == bytes.fromhex('e545be4961ca29a1')
    assert siphash24_bytes(KEY, b'') == bytes.fromhex('310e0edd47db6f72')
    assert siphash24_bytes(KEY, bytes(range(8))) == bytes.fromhex('6224939a79f5f593')


@settings(deadline=None)
@given(st.binary(min_size=16, max_size=16), st.binary(max_size=100), st.integers(0, 12))
def test_resumed_state_equals_one_shot(key, data, blocks):
    """absorb() of whole blocks then tag() of the rest is the one-shot SipHash."""
    n = min(blocks * 8, len(data) - len(data) % 8)
    assert SipHash(key).absorb(data[:n]).tag(data[n:]).to_bytes(8, 'little') == siphash24_bytes(key, data)


frames = st.builds(Frame, type=st.integers(0, 255), seq=st.integers(0, SEQ_MOD - 1),
                   payload=st.binary(max_size=MAX_PAYLOAD), ref=st.integers(0, SEQ_MOD - 1),
                   flags=st.integers(0, 1))
nonce = st.binary(min_size=8, max_size=8)


@settings(deadline=None, max_examples=300)
@given(st.binary(min_size=16, max_size=16), nonce, nonce, frames, st.integers(0, 2**32 - 1), st.data())
def test_every_bit_flip_fails_the_tag(key, nh, nb, frame, full, data):
    """A frame sealed in a session verifies there; with any one bit flipped in what the
    tag covers or in the tag (CRC made right again), it never does."""
    s = Session(key, nh, nb)
    sealed = s.seal(HOST_TO_BOARD, full, frame)
    raw = bytearray(encode_frame(sealed))
    assert s.verify(HOST_TO_BOARD, full, decode_frame(bytes(raw)))
    k = data.draw(st.integers(4, len(raw) - 3))           # flags .. last tag byte (length kept)
    raw[k] ^= 1 << data.draw(st.integers(0, 7))
    raw[-2:] = crc16(bytes(raw[2:-2])).to_bytes(2, 'little')
    assert not s.verify(HOST_TO_BOARD, full, decode_frame(bytes(raw)))


@settings(deadline=None)
@given(st.binary(min_size=16, max_size=16), nonce, nonce, frames, st.integers(0, 2**32 - 1))
def test_tag_binds_key_session_direction_and_epoch(key, nh, nb, frame, full):
    s = Session(key, nh, nb)
    sealed = s.seal(HOST_TO_BOARD, full, frame)
    flip = bytes([nh[0] ^ 1]) + nh[1:]
    assert not Session(key, flip, nb).verify(HOST_TO_BOARD, full, sealed)          # another session
    assert not Session(key, nh, flip).verify(HOST_TO_BOARD, full, sealed)
    assert not Session(bytes([key[0] ^ 0x80]) + key[1:], nh, nb).verify(HOST_TO_BOARD, full, sealed)
    assert not s.verify(BOARD_TO_HOST, full, sealed)                               # reflected
    assert not s.verify(HOST_TO_BOARD, (full + SEQ_MOD) % 2**32, sealed)          # 65536 frames later


# ------------------------------------------------------------------ key files
def test_key_file_written_owner_only_and_never_overwritten(tmp_path):
    path = tmp_path / 'cfg' / 'installation.key'
    write_key_file(path, KEY)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    assert load_key(path) == KEY and key_id(KEY) in path.read_text()
    with pytest.raises(KeyFileError, match='refusing to overwrite'):
        write_key_file(path, bytes(range(1, 17)))
    assert load_key(path) == KEY
    write_key_file(path, bytes(range(1, 17)), force=True)
    assert load_key(path) == bytes(range(1, 17)) and stat.S_IMODE(path.stat().st_mode) == 0o600


def test_exposed_or_bad_key_files_refused_with_the_fix(tmp_path):
    path = write_key_file(tmp_path / 'k', KEY)
    os.chmod(path, 0o644)
    with pytest.raises(KeyFileError, match=r'readable by every user \(mode 0644\).*chmod 600'):
        link_key(str(path))
    os.chmod(path, 0o620)
    with pytest.raises(KeyFileError, match='writable by other users'):
        load_key(path)
    assert permission_problem(stat.S_IFDIR | 0o700) == 'is not a regular file'
    os.chmod(path, 0o600)
    path.write_text('# comment\n' + '00' * 16 + '\n')
    with pytest.raises(KeyFileError, match='null key'):
        load_key(path)
    path.write_text('abc\n')
    with pytest.raises(KeyFileError, match='32 hex digits'):
        load_key(path)
    with pytest.raises(KeyFileError, match='does not exist.*sslfr keys new'):
        load_key(tmp_path / 'missing')
    assert link_key('') is None


def test_keys_cli_new_refuses_overwrite_and_prints_the_id(tmp_path, capsys):
    from sslfr_drivers.link import keys_cli
    path = tmp_path / 'site.key'
    assert keys_cli.main(['new', str(path)]) == 0
    kid = key_id(load_key(path))
    assert kid in capsys.readouterr().out and stat.S_IMODE(path.stat().st_mode) == 0o600
    assert keys_cli.main(['new', str(path)]) == 2
    assert 'refusing to overwrite' in capsys.readouterr().err and key_id(load_key(path)) == kid
    assert keys_cli.main(['new', str(path), '--force']) == 0 and key_id(load_key(path)) != kid
    assert keys_cli.main(['id', str(path)]) == 0 and key_id(load_key(path)) in capsys.readouterr().out


def test_board_source_never_starts_a_link_with_an_exposed_key(tmp_path):
    from sslfr_drivers.sensors.source import BoardSource
    path = write_key_file(tmp_path / 'k', KEY)
    os.chmod(path, 0o604)
    src = BoardSource(str(tmp_path / 'nowhere'), key_file=str(path)).start()
    try:
        assert src.link is None and 'not starting the board link' in src.last_error \
            and 'readable by every user' in src.last_error
    finally:
        src.stop()


# ------------------------------------------------------------------ the link against forgeries
class Pump:
    """An in-process simulated board behind a real pty: the host's bytes go to the board,
    the board's frames come back (recorded in :attr:`sent`), and :meth:`inject` adds
    bytes to the board->host stream (what a transmitter within radio range can do)."""

    def __init__(self, board):
        self.board = board
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        self._slave = slave
        self.sent: list[bytes] = []
        self._inject: list[bytes] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._framer = Framer()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def inject(self, data: bytes) -> None:
        with self._lock:
            self._inject.append(data)

    def _run(self) -> None:
        while not self._stop.is_set():
            r, _, _ = select.select([self.master], [], [], 0.005)
            with self._lock:
                if r:
                    try:
                        self.board.receive(os.read(self.master, 4096))
                    except OSError:
                        return
                self.board.tick(time.monotonic())
                out = self.board.take_output()
                self.sent += [encode_frame(f) for f in self._framer.feed(out)]
                out += b''.join(self._inject)
                self._inject.clear()
            if out:
                os.write(self.master, out)

    def close(self) -> None:
        self._stop.set()
        self._t.join(2)
        os.close(self.master)
        os.close(self._slave)


@pytest.fixture
def pump():
    p = Pump(AxisSim(AxisConfig.for_axis('mirrors'), rng=random.Random(3), key=KEY))
    yield p
    p.close()


def _link(path, key=KEY, **kw):
    return BoardLink(SerialTransport(path), timeout=0.15, retries=3, heartbeat=0.2, key=key, **kw).start()


def _status_frames(pump):
    return [raw for raw in pump.sent if decode_frame(raw).type == m.Status.TYPE]


def test_forged_board_frames_dropped_and_counted(pump):
    """Into a live session: 50 STATUS with random tags, 50 real STATUS frames with one
    bit flipped, 30 replayed STATUS frames of this session, 30 frames of an earlier host
    session (before a host restart), 20 under another key. None reaches the listeners or
    last_status; auth_failures / stale count them exactly; the link stays UP."""
    rnd = random.Random(7)
    lk = _link(pump.path)
    try:
        assert lk.wait_up(3)
        for _ in range(3):
            lk.get_status()
        earlier = _status_frames(pump)
    finally:
        lk.stop()
    lk = _link(pump.path)                       # the host restarts: a new session
    seen = []
    lk.add_listener(lambda msg, f: seen.append(msg))
    try:
        assert lk.wait_up(3)
        for _ in range(5):
            lk.get_status()
        mine = _status_frames(pump)[len(earlier):]
        assert len(mine) >= 5 and len(earlier) >= 3
        lk.heartbeat = None                     # only our frames from here: exact counts
        time.sleep(0.3)
        c0, n_seen, status0 = lk.counters(), len(seen), lk.last_status
        fake = m.Status(123456, 123456, 0.0, int(m.StatusFlags.HOMED), 0, 0, 0.0, 999_999)
        forged = [encode_frame(Frame(m.Status.TYPE, rnd.randrange(SEQ_MOD), fake.pack(), 0, 0, tag=rnd.randbytes(8)))
                  for _ in range(50)]
        flipped = []
        for _ in range(50):
            raw = bytearray(rnd.choice(mine))
            raw[rnd.randrange(4, len(raw) - 2)] ^= 1 << rnd.randrange(8)
            raw[-2:] = crc16(bytes(raw[2:-2])).to_bytes(2, 'little')
            flipped.append(bytes(raw))
        replayed = [rnd.choice(mine) for _ in range(30)]
        old = [rnd.choice(earlier) for _ in range(30)]
        other = Session(os.urandom(16), os.urandom(8), os.urandom(8))
        foreign = [encode_frame(other.seal(BOARD_TO_HOST, i, m.encode(fake, 0))) for i in range(20)]
        attack = forged + flipped + replayed + old + foreign
        rnd.shuffle(attack)
        for i in range(0, len(attack), 20):
            pump.inject(b''.join(attack[i:i + 20]))
            time.sleep(0.02)
        time.sleep(0.3)
        c = lk.counters()
        assert c['auth_failures'] - c0['auth_failures'] == 50 + 50 + 30 + 20
        assert c['stale'] + c['duplicates'] - c0['stale'] - c0['duplicates'] == 30
        assert c['frames_received'] == c0['frames_received'] and c['version_errors'] == c0['version_errors']
        assert len(seen) == n_seen and lk.last_status == status0
        assert lk.state == BoardLinkState.UP and lk.get_status().position != 123456
    finally:
        lk.stop()


def test_replayed_boot_probes_but_is_no_reset(pump):
    """A recorded BOOT (null session, valid tag) while UP: counted out of session, one
    probe HELLO shows the same boot count: no reset is reported."""
    lk = _link(pump.path)
    try:
        assert lk.wait_up(3)
        boot = next(raw for raw in pump.sent if decode_frame(raw).type == m.Boot.TYPE)
        resets = lk.resets
        for _ in range(5):
            pump.inject(boot)
        assert wait_for(lambda: lk.out_of_session >= 5, 2)
        time.sleep(0.5)
        assert lk.resets == resets and lk.state == BoardLinkState.UP
        pump.board.reset()                    # a real reset: the boot count changes
        assert wait_for(lambda: lk.resets == resets + 1, 3) and lk.wait_up(3)
    finally:
        lk.stop()


@pytest.mark.parametrize('board_key,host_key,message', [
    (bytes(range(1, 17)), KEY, "does not accept this host's key"),
    (None, KEY, 'not provisioned'),
    (KEY, None, 'this host has none: set the key_file parameter'),
])
def test_key_mismatch_is_a_clear_refusal(board_key, host_key, message):
    p = Pump(AxisSim(AxisConfig.for_axis('mirrors'), rng=random.Random(3), key=board_key))
    lk = _link(p.path, key=host_key)
    try:
        assert wait_for(lambda: lk.state == BoardLinkState.REFUSED, 3), lk.state
        assert message in lk.last_error
        with pytest.raises(Exception, match=message.split(':')[0][:20]):
            lk.move_to(1, 1)
    finally:
        lk.stop()
        p.close()


def test_unprovisioned_board_with_no_key_works_unauthenticated():
    p = Pump(AxisSim(AxisConfig.for_axis('mirrors'), rng=random.Random(3)))
    lk = _link(p.path, key=None)
    try:
        assert lk.wait_up(3) and lk.get_info().board_kind == m.BoardKind.AXIS_STEPPER
        assert NULL_KEY == lk.key
    finally:
        lk.stop()
        p.close()
