"""Shared helpers of the firmware tests (tests/test_fw_*.py).

:func:`require` builds the firmware parts a test needs (``make -C firmware``) and skips
the test with the reason (printed in pytest's summary, ``-ra``) when the toolchain is
missing; with ``CI=true`` a missing toolchain FAILS instead (CI must run them).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

# one polling helper for every test package
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'sslfr_drivers' / 'test'))
from drivers_testutil import wait_for  # noqa: E402,F401


def require(*parts: str) -> None:
    """Build ``parts`` ('firmware', 'sim', 'host'); skip / fail (CI) when impossible."""
    from sslfr_drivers import firmware as fw
    targets = {'firmware': 'all', 'sim': 'sim', 'host': 'host'}
    problem = fw.toolchain_problem(*parts)
    if problem:
        if os.environ.get('CI', '').lower() in ('1', 'true', 'yes'):
            pytest.fail(f'CI=true and {problem}')
        pytest.skip(problem)
    try:
        fw.build(*(targets[p] for p in parts))
    except fw.FirmwareError as exc:
        pytest.fail(str(exc))


class RawHost:
    """A minimal host on a board's pty: sends frames with chosen seq / version / payload
    and returns the decoded frames the board sends (no retries, no link logic)."""

    def __init__(self, path: str):
        import termios
        import tty
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self.fd)
        termios.tcflush(self.fd, termios.TCIOFLUSH)
        from sslfr_drivers.link.protocol import Framer
        self.framer = Framer()
        self.seq = 0
        self.received = []
        import threading
        self._lock = threading.Lock()

    def send_raw(self, data: bytes) -> None:
        os.write(self.fd, data)

    def send(self, msg, seq: int | None = None, version: int = 1, payload: bytes | None = None,
             mtype: int | None = None) -> int:
        """Send ``msg`` (or ``mtype`` + ``payload``) with ``seq`` (default: next)."""
        from sslfr_drivers.link.protocol import Frame, encode_frame
        with self._lock:
            if seq is None:
                self.seq = (self.seq + 1) % 65536
                seq = self.seq
            seq %= 65536
            mtype = msg.TYPE if mtype is None else mtype
            payload = msg.pack() if payload is None else payload
            self.send_raw(encode_frame(Frame(mtype, seq, payload, 0, 0, version)))
        return seq

    def poll(self, timeout: float = 0.0) -> list:
        import select
        import time
        deadline = time.monotonic() + timeout
        out = []
        while True:
            r, _, _ = select.select([self.fd], [], [], max(0.0, deadline - time.monotonic()))
            if r:
                try:
                    out += self.framer.feed(os.read(self.fd, 4096))
                except BlockingIOError:
                    pass
            if time.monotonic() >= deadline:
                break
        self.received += out
        return out

    def answer(self, seq: int, timeout: float = 2.0):
        """The decoded answer to request ``seq`` (None if none in ``timeout`` s)."""
        import time
        from sslfr_drivers.link import messages as m
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for f in self.poll(0.02):
                if f.is_response and f.ref == seq:
                    return m.decode(f)
        return None

    def request(self, msg, **kw):
        return self.answer(self.send(msg, **kw))

    def heartbeat(self, period: float = 0.25) -> 'RawHost':
        """PING every ``period`` s from a thread (keeps the 1 s board watchdog quiet)."""
        import threading
        from sslfr_drivers.link import messages as m
        self._beat = threading.Event()
        self.beat_paused = threading.Event()

        def run():
            while not self._beat.wait(period):
                if self.beat_paused.is_set():
                    continue
                try:
                    self.send(m.Ping(0))
                except OSError:
                    return
        threading.Thread(target=run, daemon=True).start()
        return self

    def stop_heartbeat(self) -> None:
        if getattr(self, '_beat', None):
            self._beat.set()

    def close(self) -> None:
        if getattr(self, '_beat', None):
            self._beat.set()
        os.close(self.fd)
