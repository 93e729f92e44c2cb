"""The axis driver's threads (no rclpy): the control loop's timing and wake-ups, the
board opening in the background."""
from __future__ import annotations

import threading
import time

from sslfr_drivers.axis.control_loop import BackgroundOpen, ControlLoop


def test_control_loop_runs_after_the_wait_it_returns_and_at_once_when_woken():
    times = []

    def step():
        times.append(time.monotonic())
        return 10.0                       # the next step only when woken
    loop = ControlLoop(step).start()
    try:
        deadline = time.monotonic() + 2.0
        while len(times) < 1 and time.monotonic() < deadline:
            time.sleep(0.005)
        time.sleep(0.2)
        assert len(times) == 1            # the first at once, then it waits
        t0 = time.monotonic()
        loop.wake()
        while len(times) < 2 and time.monotonic() < deadline:
            time.sleep(0.001)
        assert len(times) == 2 and times[1] - t0 < 0.1
    finally:
        loop.stop()
    n = len(times)
    loop.wake()
    time.sleep(0.05)
    assert len(times) == n, 'no step after stop'


def test_control_loop_keeps_its_rate_when_a_step_takes_time():
    starts = []

    def step():
        starts.append(time.monotonic())
        time.sleep(0.02)                  # board I/O inside the step
        return 0.05
    loop = ControlLoop(step).start()
    time.sleep(0.55)
    loop.stop()
    periods = [b - a for a, b in zip(starts, starts[1:])]
    assert periods and sum(periods) / len(periods) < 0.06, periods     # 50 ms, not 70 ms


def test_control_loop_paces_itself_and_survives_a_failing_step():
    calls = []

    def step():
        calls.append(time.monotonic())
        if len(calls) == 2:
            raise RuntimeError('board vanished')
        return 0.05
    loop = ControlLoop(step, retry=0.05).start()
    time.sleep(0.5)
    loop.stop()
    assert 6 <= len(calls) <= 12, len(calls)            # ~20 Hz, not a busy loop, not stopped by the error


class _Session:
    def __init__(self):
        self.closed = False

    def close(self):
        self.closed = True


def test_background_open_hands_over_a_slow_board_and_closes_an_untaken_one():
    gate = threading.Event()
    session = _Session()

    def slow_open():
        gate.wait(2.0)
        return session
    op = BackgroundOpen('/dev/x', slow_open)
    assert op.result(0.05) is None                      # still under way: configure fails for now
    gate.set()
    assert op.result(1.0) == (session, None)            # the next attempt takes it
    op.discard(_Session.close)
    assert not session.closed, 'a taken session is the driver\'s'
    other = _Session()
    op2 = BackgroundOpen('/dev/y', lambda: other)
    time.sleep(0.05)
    op2.discard(_Session.close)
    assert other.closed
    failing = BackgroundOpen('/dev/z', lambda: (_ for _ in ()).throw(ConnectionError('no INFO')))
    session, exc = failing.result(1.0)
    assert session is None and isinstance(exc, ConnectionError)
