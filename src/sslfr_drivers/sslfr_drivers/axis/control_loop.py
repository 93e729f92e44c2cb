"""The axis driver's own threads (no rclpy): the control loop and the board opening,
so that no executor callback ever waits for board I/O.

- :class:`ControlLoop` runs ``step()`` (read -> update -> write) in its own thread,
  again after the number of seconds ``step`` returns, or at once when :meth:`wake`
  is called (a trajectory, a safety change...). The executor stays free for the
  topics, services and heartbeats, so the node (and every node composed with it)
  can use a single-threaded executor.
- :class:`BackgroundOpen` opens a board session in a thread: configure waits for
  it at most ``wait`` seconds, a board that takes longer is picked up by the next
  configure attempt (the self-activation retries).
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Callable

from sslfr_common.log_route import log_extra

_log = logging.getLogger('sslfr_drivers.axis')


class ControlLoop:
    """``step() -> seconds until the next step`` in a thread, woken early by :meth:`wake`.

    The wait counts from the START of the step (a fixed rate, like a timer: the board
    I/O inside a step does not stretch the period). A step raising an exception is
    logged (on node ``owner``'s logger, :mod:`sslfr_common.log_route`) and the loop goes
    on after ``retry`` [s].
    """

    def __init__(self, step: Callable[[], float], name: str = 'control', retry: float = 0.05, owner: str = ''):
        self._step = step
        self._extra = log_extra(owner)
        self._retry = retry
        self._event = threading.Event()
        self._halt = False
        self.steps = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> 'ControlLoop':
        self._thread.start()
        return self

    def wake(self) -> None:
        """Run the next step now (safe from any thread)."""
        self._event.set()

    def stop(self, timeout: float = 2.0) -> None:
        """End the loop after the step under way (idempotent)."""
        self._halt = True
        self._event.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    def _run(self) -> None:
        wait = 0.0
        while not self._halt:
            self._event.wait(wait)
            self._event.clear()
            if self._halt:
                return
            started = time.monotonic()
            try:
                wait = float(self._step())
            except Exception:  # noqa: BLE001 - the control loop must survive a bad step
                _log.exception('control step failed', extra=self._extra)
                wait = self._retry
            wait = max(0.0, wait - (time.monotonic() - started))
            self.steps += 1


class BackgroundOpen:
    """``open_fn()`` (returns a session, raises on failure) in a thread for ``key``
    (the port). :meth:`result` waits at most ``wait`` [s]: ``None`` while it is
    still under way, else ``(session, None)`` or ``(None, exception)``.
    :meth:`discard` closes a session nobody took (``close_fn(session)``)."""

    def __init__(self, key: str, open_fn: Callable[[], object]):
        self.key = key
        self._done = threading.Event()
        self._value: tuple = (None, None)
        self._taken = False
        self._lock = threading.Lock()
        threading.Thread(target=self._run, args=(open_fn,), name=f'open {key}', daemon=True).start()

    def _run(self, open_fn) -> None:
        try:
            value = (open_fn(), None)
        except Exception as exc:  # noqa: BLE001 - handed to configure
            value = (None, exc)
        self._value = value
        self._done.set()

    def result(self, wait: float):
        if not self._done.wait(wait):
            return None
        with self._lock:
            self._taken = True
        return self._value

    def discard(self, close_fn: Callable[[object], None]) -> None:
        """Close the session if it opened and was not taken (now or when it ends)."""
        def close():
            self._done.wait()
            with self._lock:
                if self._taken or self._value[0] is None:
                    return
                self._taken = True
            close_fn(self._value[0])
        if self._done.is_set():
            close()
        else:
            threading.Thread(target=close, daemon=True).start()
