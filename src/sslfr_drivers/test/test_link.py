"""Transports (loop://, pty) and the one reader thread that owns a board's port."""
import os
import time
import tty

import pytest

from sslfr_drivers.link.protocol import Frame, Framer, encode_frame
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


def test_pty_read_returns_a_burst_whole_times_out_empty_and_is_interrupted():
    """A POSIX port is read with one select and one read: a burst written at once comes
    back in one read; an idle read ends empty after its time-out (not before);
    interrupt() from another thread ends a long read at once, and data written after
    it is read by the next read."""
    import threading
    master, slave = os.openpty()
    tty.setraw(slave)
    t = SerialTransport(os.ttyname(slave))
    t.open()
    try:
        burst = b''.join(encode_frame(Frame(1, i, bytes([i]) * 5)) for i in range(8))
        os.write(master, burst)
        time.sleep(0.05)
        assert t.read(0.5) == burst
        t0 = time.monotonic()
        assert t.read(0.1) == b''
        assert 0.09 <= time.monotonic() - t0 < 0.5
        assert t.interruptible
        threading.Timer(0.1, t.interrupt).start()
        t0 = time.monotonic()
        assert t.read(5.0) == b''
        assert time.monotonic() - t0 < 1.0
        os.write(master, b'after')
        assert t.read(1.0) == b'after'
    finally:
        t.close()
        os.close(master)
        os.close(slave)


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
