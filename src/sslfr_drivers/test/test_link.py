"""Transports (loop://, pty) and BoardLink against a simulated board on a real pty."""
import os
import random
import time
import tty

import pytest

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.board_link import BoardLink, BoardLinkState, LinkDown, NackError
from sslfr_drivers.link.protocol import Frame, Framer, encode_frame
from sslfr_sim.axis import AxisConfig, AxisSim
from sslfr_sim.base import FaultInjector
from sslfr_sim.runner import SimThread
from sslfr_drivers.link.transport import SerialTransport, TransportError, make_transport

from drivers_testutil import wait_for


def test_loop_url_transport_roundtrip():
    t = make_transport('loop://')
    t.open()
    framer = Framer()
    frames = [Frame(0x10, i, bytes([i]) * i) for i in range(20)]
    t.write(b''.join(encode_frame(f) for f in frames))
    got = []
    end = time.monotonic() + 2
    while len(got) < 20 and time.monotonic() < end:
        got += framer.feed(t.read(0.05))
    assert got == frames
    t.close()
    with pytest.raises(TransportError):
        t.read(0.01)


def test_pty_transport_both_ways_and_loss():
    master, slave = os.openpty()
    tty.setraw(slave)
    t = SerialTransport(os.ttyname(slave))
    t.open()
    os.write(master, encode_frame(Frame(1, 7, b'hi')))
    framer = Framer()
    got = []
    assert wait_for(lambda: got.extend(framer.feed(t.read(0.05))) or got, 2)
    assert got == [Frame(1, 7, b'hi')]
    t.write(b'\x01\x02\x03')
    assert os.read(master, 10) == b'\x01\x02\x03'
    os.close(slave)
    os.close(master)     # the "device" disappears
    with pytest.raises(TransportError):
        for _ in range(50):
            t.read(0.01)
    t.close()
    with pytest.raises(TransportError):
        SerialTransport('/dev/does-not-exist').open()


@pytest.fixture
def sim():
    board = AxisSim(AxisConfig.for_axis('mirrors'), rng=random.Random(3))
    s = SimThread.plain(board, FaultInjector(rng=random.Random(4))).start()
    yield s
    s.stop()


@pytest.fixture
def link(sim):
    lk = BoardLink(SerialTransport(sim.path), timeout=0.15, retries=3, heartbeat=0.2).start()
    assert lk.wait_up(3)
    yield lk
    lk.stop()


def test_link_info_nack_home_move(sim, link):
    assert link.info.board_kind == m.BoardKind.AXIS_STEPPER and link.info.is_simulator
    assert not link.last_status.homed and link.last_status.fault_bits & m.FaultBits.RESET
    with pytest.raises(NackError) as err:
        link.move_to(1000, 1000)
    assert err.value.code == m.ErrorCode.NOT_HOMED and 'NOT_HOMED' in str(err.value)
    link.set_zero(15000)                     # at the sleep switch = +90 deg
    link.move_to(14000, 3000)
    assert wait_for(lambda: not link.get_status().moving, 3)
    st = link.get_status()
    assert st.position == 14000 and st.homed
    assert abs(st.sensor_angle - sim.board.angle) < 1e-3    # sensor noise 0.003 deg
    assert abs(sim.board.angle - m.DEFAULT_STEP_RAD * 14000) < 1e-9
    c = link.counters()
    assert c['nacks'] == 1 and c['frames_lost'] == 0 and c['timeouts'] == 0


def test_submit_is_nonblocking_future(link):
    fut = link.submit(m.GetStatus())
    assert isinstance(fut.result(1.0), m.Status)


def test_lost_answers_retried_not_reexecuted_and_loss_exact(sim, link):
    """1 % ... here 20 % of board frames corrupted: every request still answered,
    duplicates served from the board's cache, frames_lost == frames corrupted."""
    sim.command('set_angle 0')
    link.set_zero(0)
    sim.command('corrupt_frames 0.2')
    for i in range(60):
        link.move_to(10 * (i % 3), 2000)
    sim.command('corrupt_frames 0')
    link.ping()           # a clean frame after the last corrupted one closes the gap
    time.sleep(0.05)
    with sim.locked():
        corrupted = sim.faults.frames_corrupted
        dups = sim.board.requests_duplicate
    assert corrupted > 5
    assert link.frames_lost == corrupted
    assert link.retries_sent >= dups > 0
    assert link.counters()['timeouts'] == 0


def test_corrupted_host_bytes_never_move_wrongly(sim, link):
    sim.command('set_angle 0')
    link.set_zero(0)
    sim.command('corrupt 0.01')
    targets = [random.Random(9).randrange(-500, 500) for _ in range(40)]
    for tgt in targets:
        try:
            link.move_to(tgt, 3000)
        except Exception:   # noqa: BLE001 - a request may time out under corruption
            pass
        with sim.locked():
            assert round(sim.board.target) in targets or sim.board.target == 0
    sim.command('corrupt 0')


def test_board_reset_detected_and_state_reread(sim, link):
    link.set_zero(100)
    resets = link.resets
    states = []
    link.add_state_listener(lambda s, lk: states.append(s))
    sim.command('reset')
    assert wait_for(lambda: link.resets > resets and link.state == BoardLinkState.UP, 3)
    st = link.last_status
    assert not st.homed and st.fault_bits & m.FaultBits.RESET and st.position == 0
    assert BoardLinkState.CONNECTING in states and states[-1] == BoardLinkState.UP
    with pytest.raises(NackError):
        link.move_to(50, 100)    # no move before re-homing


def test_silence_then_recovery(sim, link):
    sim.command('disconnect 1.6')
    assert wait_for(lambda: link.state == BoardLinkState.SILENT, 2.5)
    assert wait_for(lambda: link.state == BoardLinkState.UP, 4)
    assert link.get_status().fault_bits & m.FaultBits.RESET   # state re-read


def test_unplug_reconnects_with_backoff(tmp_path):
    board = AxisSim(AxisConfig.for_axis('mobile_structure'), rng=random.Random(5))
    link_path = str(tmp_path / 'ttySIM')
    with SimThread.plain(board, link=link_path) as sim:
        lk = BoardLink(SerialTransport(link_path), timeout=0.15, heartbeat=0.2,
                       backoff_min=0.05, backoff_max=0.4).start()
        try:
            assert lk.wait_up(3)
            lk.set_zero(0)
            sim.command('unplug 1.0')
            assert wait_for(lambda: lk.state == BoardLinkState.DOWN, 2)
            with pytest.raises(LinkDown):
                lk.ping()
            assert wait_for(lambda: lk.state == BoardLinkState.UP, 5)
            assert lk.reconnects == 1
            assert lk.get_status().homed       # same board, not reset: position kept
        finally:
            lk.stop()


def test_old_protocol_version_refused():
    board = AxisSim(rng=random.Random(1), protocol_version=7)
    with SimThread.plain(board) as sim:
        lk = BoardLink(SerialTransport(sim.path), timeout=0.1, retries=1).start()
        try:
            assert wait_for(lambda: lk.state == BoardLinkState.REFUSED, 3)
            assert 'protocol version 7' in str(lk.version_error)
            with pytest.raises(Exception, match='version 7'):
                lk.move_to(1, 1)
            assert not lk.wait_up(0.3)
        finally:
            lk.stop()


def test_version_1_board_is_read_for_info_and_refused_for_motion():
    """Issue 19: a board of protocol version 1 (no authentication) still tells what it
    is (INFO read with a version-1 request) and is refused for motion with the clear
    version message, whose text names both versions."""
    board = AxisSim(rng=random.Random(1), protocol_version=1)
    with SimThread.plain(board) as sim:
        lk = BoardLink(SerialTransport(sim.path), timeout=0.1, retries=1).start()
        try:
            assert wait_for(lambda: lk.state == BoardLinkState.REFUSED and lk.info is not None, 3)
            assert lk.info.protocol == 1 and lk.info.board_kind == m.BoardKind.AXIS_STEPPER
            assert lk.info.firmware == '1.0.0'
            assert 'protocol version 1, this host speaks version 2' in str(lk.version_error)
            with pytest.raises(Exception, match='protocol version 1'):
                lk.move_to(1, 1)
        finally:
            lk.stop()


def test_loss_counter_exact_across_board_sequence_wrap():
    """Board sequence numbers run across 65535 -> 0 (the session's frame count into its
    second epoch, which the tags cover) while 5 % of board frames are corrupted:
    frames_lost stays exactly the corrupted count, and every frame verifies."""
    from sslfr_drivers.link.protocol import SequenceCounter
    board = AxisSim(AxisConfig.for_axis('mobile_structure'), rng=random.Random(8))
    with SimThread.plain(board, FaultInjector(rng=random.Random(9))) as sim:
        lk = BoardLink(SerialTransport(sim.path), timeout=0.1, retries=4).start()
        try:
            assert lk.wait_up(3)
            lk.set_zero(0)
            with sim.locked():                 # a long session: the board near its wrap
                sim.board._cur.tx = SequenceCounter(65450)
                lk.tracker.last = 65449
            sim.command('corrupt_frames 0.05')
            for i in range(150):
                lk.move_to(i, 3000)
            sim.command('corrupt_frames 0')
            lk.ping()
            with sim.locked():
                corrupted = sim.faults.frames_corrupted
                wrapped_to = sim.board._cur.tx.peek()
            assert wrapped_to < 1000               # the board's counter wrapped
            assert corrupted > 0
            assert lk.frames_lost == corrupted
            assert lk.counters()['auth_failures'] == 0
        finally:
            lk.stop()


def test_reader_thread_feeds_a_framing_protocol():
    """The reader owns the port; a protocol object only parses (pyserial's
    serial/threaded shape): frames split over 7-byte writes and after junk arrive whole."""
    from sslfr_drivers.link.reader import Protocol, ReaderThread
    got = []

    class FrameCollector(Protocol):
        def __init__(self):
            self.framer = Framer()

        def data_received(self, data):
            got.extend(self.framer.feed(data))

    reader = ReaderThread(make_transport('loop://'), FrameCollector()).start()
    try:
        assert wait_for(lambda: reader.connected, 2)
        frames = [Frame(0x83, i, bytes(range(i))) for i in range(30)]
        wire = b'junk' + b''.join(encode_frame(f) for f in frames)
        for i in range(0, len(wire), 7):
            reader.write(wire[i:i + 7])
        assert wait_for(lambda: len(got) == 30, 3)
    finally:
        reader.stop()
    assert got == frames


def test_backoff_doubles_to_its_cap_and_resets():
    from sslfr_drivers.link.reader import Backoff
    b = Backoff(0.1, 1.0)
    assert [b.next() for _ in range(6)] == pytest.approx([0.1, 0.2, 0.4, 0.8, 1.0, 1.0])
    b.reset()
    assert b.next() == 0.1
    assert Backoff().lo == 0.1 and Backoff().hi == 2.0      # the one policy of every board port
    for lo, hi in ((0.0, 1.0), (0.5, 0.1), (-1.0, 1.0)):
        with pytest.raises(ValueError):
            Backoff(lo, hi)


def test_reader_retries_an_unopenable_port_with_backoff():
    """Open attempts on a missing device are spaced by the back-off delays (lower
    bounds only: a loaded machine may add to them)."""
    from sslfr_drivers.link.reader import Backoff, Protocol, ReaderThread
    attempts = []

    class Watch(Protocol):
        def open_failed(self, exc):
            attempts.append((time.monotonic(), str(exc)))

    reader = ReaderThread(SerialTransport('/dev/does-not-exist'), Watch(),
                          backoff=Backoff(0.05, 0.2)).start()
    try:
        assert wait_for(lambda: len(attempts) >= 5, 5)
    finally:
        reader.stop()
    gaps = [b[0] - a[0] for a, b in zip(attempts, attempts[1:])]
    for gap, delay in zip(gaps, [0.05, 0.1, 0.2, 0.2]):
        assert gap >= delay - 0.005
    assert 'cannot open /dev/does-not-exist' in attempts[0][1]
    assert reader.last_error == attempts[-1][1]
    assert reader.opens == 0 and not reader.connected


def test_reader_survives_a_failing_protocol_and_stops_cleanly():
    from sslfr_drivers.link.reader import Protocol, ReaderThread
    got = []

    class Flaky(Protocol):
        def data_received(self, data):
            if data.startswith(b'boom'):
                raise RuntimeError('parser bug')
            got.append(data)

    reader = ReaderThread(make_transport('loop://'), Flaky()).start()
    assert wait_for(lambda: reader.connected, 2)
    reader.write(b'boom')
    assert wait_for(lambda: reader.bytes_received == 4, 2)
    reader.write(b'fine')
    assert wait_for(lambda: got == [b'fine'], 2)
    reader.stop()
    assert not reader.connected and reader.opens == 1 and reader.reconnects == 0
    with pytest.raises(TransportError):
        reader.write(b'x')


class _CountingTransport:
    """Wraps a transport and counts its reads (each read is one reader wake-up)."""

    def __init__(self, inner):
        self.inner = inner
        self.name = inner.name
        self.reads = 0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def read(self, timeout):
        self.reads += 1
        return self.inner.read(timeout)


def test_idle_link_reader_sleeps_until_its_deadlines(sim):
    """The reader wakes for a frame or the link's next deadline (here the 0.2 s
    heartbeat), not every 20 ms: an idle link over 1.5 s costs about 8-16 reads, where
    the former fixed 20 ms poll cost 75 (issue 16). Its heartbeats keep the board's
    1 s watchdog quiet and it stays UP."""
    t = _CountingTransport(SerialTransport(sim.path))
    lk = BoardLink(t, timeout=0.15, retries=3, heartbeat=0.2).start()
    try:
        assert lk.wait_up(3)
        time.sleep(0.3)
        r0, sent0 = t.reads, lk.frames_sent
        time.sleep(1.5)
        reads, pings = t.reads - r0, lk.frames_sent - sent0
        assert lk.state == BoardLinkState.UP
        assert 5 <= pings <= 9, pings                 # a PING per 0.2 s of silence
        assert reads <= 4 * pings + 4, (reads, pings)  # PING, its answer, the deadline
    finally:
        lk.stop()


def test_a_request_deadline_is_kept_while_the_reader_sleeps(sim, link):
    """A request submitted while the reader sleeps (up to its 0.25 s read_timeout)
    with a shorter time-out than that pokes the read: the unanswered request is retried
    and ends at its own deadline, not at the end of the reader's sleep."""
    sim.command('disconnect 3')
    time.sleep(0.1)
    t0 = time.monotonic()
    fut = link.submit(m.Ping(1), timeout=0.05, retries=0)
    with pytest.raises(Exception, match='no answer'):
        fut.result(timeout=2.0)
    took = time.monotonic() - t0
    assert took < 0.2, f'time-out seen after {took:.3f} s (deadline 0.05 s)'


def test_reader_stop_interrupts_a_long_read():
    """stop() ends a read under way at once (pyserial's abort pipe), not at its
    time-out: closing a session does not wait for the reader's sleep."""
    from sslfr_drivers.link.reader import Protocol, ReaderThread
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        reader = ReaderThread(SerialTransport(os.ttyname(slave)), Protocol(), read_timeout=5.0).start()
        assert wait_for(lambda: reader.connected, 2)
        time.sleep(0.1)                       # the reader is now in its 5 s read
        t0 = time.monotonic()
        reader.stop()
        assert time.monotonic() - t0 < 0.5
    finally:
        os.close(master)
        os.close(slave)


def test_link_and_sensor_modules_never_import_the_simulators():
    """Production code (board link, xbee_hub, sensor nodes) runs without sim/."""
    import ast
    from pathlib import Path
    import sslfr_drivers
    root = Path(sslfr_drivers.__file__).parent
    offenders = []
    for path in sorted([*root.glob('link/*.py'), *root.glob('sensors/*.py')]):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ''] if isinstance(node, ast.ImportFrom) else []
            offenders += [f'{path.relative_to(root)}: {n}' for n in names
                          if n.startswith('sslfr_sim') or (isinstance(node, ast.ImportFrom)
                                                                   and node.level and 'sim' in n)]
    assert len(list(root.glob('link/*.py'))) >= 8 and not offenders, offenders
