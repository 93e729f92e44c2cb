"""Shared plumbing of the sensor-board nodes (gps, absorber_board, irradiance).

* :func:`declare_parameters` / :func:`check_parameters`: one table per node
  (name -> default, description with unit, bounds or choices), declared with
  ParameterDescriptor; a runtime change is validated and refused with a reason while
  the node keeps its last good configuration.
* :class:`BoardSource`: the board behind ``port``, either through the board protocol
  (:class:`~sslfr_drivers.link.board_link.BoardLink`, which reopens a lost port with back-off) or
  - GPS only - a raw NMEA byte stream (``framing: raw_nmea``) read by a thread that
  also reopens the port. Either way callbacks run in the reader thread; nodes put
  samples in a queue that an executor timer drains.
* :func:`board_status`: the DiagnosticStatus every sensor node publishes (rate,
  last-sample age, link state, frames lost, counters).
* :class:`SensorBoardNode`: the Node base class of the three sensor nodes (parameter
  table, sample queue, board source, diagnostics publisher, clean-up).
"""
from __future__ import annotations

import collections
import logging
import math
import threading
import time
from typing import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from sslfr_drivers.link import sensor_messages  # noqa: F401 - registers the sensor message types
from sslfr_drivers.link.board_link import BoardLink
from sslfr_drivers.link.transport import TransportError, make_transport

_log = logging.getLogger(__name__)


# ------------------------------------------------------------------ parameters
def declare_parameters(node, table: dict) -> dict:
    """Declare every parameter of ``table`` and return their values.

    ``table``: name -> (default, description (with unit), bounds) where bounds is
    (min, max) for numbers, a tuple of allowed strings, or None.
    """
    for name, (default, text, bounds) in table.items():
        desc = ParameterDescriptor(description=text)
        if isinstance(bounds, tuple) and len(bounds) == 2 and all(
                isinstance(b, (int, float)) for b in bounds) and not isinstance(default, str):
            if isinstance(default, int) and not isinstance(default, bool):
                desc.integer_range = [IntegerRange(from_value=int(bounds[0]), to_value=int(bounds[1]), step=1)]
            else:
                desc.floating_point_range = [FloatingPointRange(from_value=float(bounds[0]),
                                                                to_value=float(bounds[1]))]
        elif isinstance(bounds, tuple):
            desc.additional_constraints = 'one of: ' + ', '.join(map(str, bounds))
        node.declare_parameter(name, default, desc)
    return {n: node.get_parameter(n).value for n in table}


def check_parameters(table: dict, values: dict) -> None:
    """Raise ValueError naming the first value outside its bounds or choices."""
    for name, (default, _, bounds) in table.items():
        v = values[name]
        if bounds is None:
            continue
        if isinstance(default, str):
            if v not in bounds:
                raise ValueError(f'{name}={v!r}: must be one of {", ".join(bounds)}')
        elif not (isinstance(v, (int, float)) and math.isfinite(v) and bounds[0] <= v <= bounds[1]):
            raise ValueError(f'{name}={v!r}: must be within [{bounds[0]}, {bounds[1]}]')


def parameter_callback(node, table: dict, values: dict, apply: Callable[[dict], None]):
    """An on-set-parameters callback: validate the new set, apply it or refuse it."""
    def _cb(params) -> SetParametersResult:
        new = dict(values)
        for p in params:
            if p.name in new:
                new[p.name] = p.value
        try:
            check_parameters(table, new)
            apply(new)
        except (ValueError, TypeError) as exc:
            node.get_logger().error(f'parameter change refused: {exc}')
            return SetParametersResult(successful=False, reason=str(exc))
        values.update(new)
        return SetParametersResult(successful=True)
    return _cb


# ------------------------------------------------------------------ the board
class BoardSource:
    """The board (or bare NMEA module) behind ``port``.

    Parameters
    ----------
    port : str
        pyserial URL / device path / ``xbee:...`` port; '' = no board configured.
    framing : str
        ``protocol`` (board protocol frames) or ``raw_nmea`` (bare NMEA bytes).
    baudrate : int
        [bit/s].
    on_message : callable(msg)
        Every decoded board message (protocol framing), reader thread.
    on_bytes : callable(bytes)
        Every chunk of raw bytes (raw framing), reader thread.
    heartbeat : float
        PING period keeping the link's silence detection alive [s].
    """

    def __init__(self, port: str, framing: str = 'protocol', baudrate: int = 115200,
                 on_message: Callable | None = None, on_bytes: Callable | None = None,
                 heartbeat: float = 0.5):
        self.port = port
        self.framing = framing
        self.baudrate = baudrate
        self.on_message = on_message or (lambda msg: None)
        self.on_bytes = on_bytes or (lambda data: None)
        self.heartbeat = heartbeat
        self.link: BoardLink | None = None
        self._transport = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.raw_state = 'down'
        self.raw_reconnects = 0
        self.raw_bytes = 0
        self.last_error = '' if port else 'no port configured (parameter port is empty)'

    def start(self) -> 'BoardSource':
        """Open the port and start reading (board link or raw reader thread). A bad
        port is reported by :attr:`state`/:meth:`error`, not raised; returns self."""
        if not self.port:
            return self
        try:
            self._transport = make_transport(self.port, self.baudrate)
        except (ValueError, TransportError, OSError) as exc:
            self.last_error = f'bad port {self.port!r}: {exc}'
            return self
        if self.framing == 'protocol':
            self.link = BoardLink(self._transport, name=self.port, heartbeat=self.heartbeat,
                                  silence=max(1.0, 4 * self.heartbeat), backoff_max=2.0)
            self.link.add_listener(lambda msg, frame: self.on_message(msg))
            self.link.start()
        else:
            self._stop.clear()
            self._thread = threading.Thread(target=self._raw_loop, name=f'raw-{self.port}',
                                            daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop reading and close the port (idempotent)."""
        if self.link is not None:
            self.link.stop()
            self.link = None
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._transport is not None and self.framing != 'protocol':
            try:
                self._transport.close()
            except TransportError:
                pass

    def _raw_loop(self) -> None:
        backoff, opened = 0.1, 0
        t = self._transport
        while not self._stop.is_set():
            if not t.is_open:
                try:
                    t.open()
                except (TransportError, ValueError) as exc:
                    self.last_error = str(exc)
                    self.raw_state = 'down'
                    self._stop.wait(backoff)
                    backoff = min(2 * backoff, 2.0)
                    continue
                backoff = 0.1
                opened += 1
                self.raw_reconnects = opened - 1
                self.raw_state = 'up'
            try:
                data = t.read(0.05)
            except TransportError as exc:
                self.last_error = str(exc)
                self.raw_state = 'down'
                try:
                    t.close()
                except TransportError:
                    pass
                continue
            if data:
                self.raw_bytes += len(data)
                try:
                    self.on_bytes(data)
                except Exception:  # noqa: BLE001 - the reader must survive any input
                    _log.exception('%s: byte handler failed', self.port)

    @property
    def state(self) -> str:
        """'unconfigured', 'down', 'connecting', 'up', 'silent', 'refused'."""
        if not self.port:
            return 'unconfigured'
        if self.link is not None:
            return self.link.state.value
        if self.framing != 'protocol':
            return self.raw_state
        return 'down'

    def counters(self) -> dict:
        """Link counters (protocol framing) or bytes received and reconnects (raw)."""
        if self.link is not None:
            return self.link.counters()
        return {'bytes_received': self.raw_bytes, 'reconnects': self.raw_reconnects}

    def error(self) -> str:
        """The last error text of the port or link (empty when none)."""
        if self.link is not None:
            return self.link.last_error
        return self.last_error


# ------------------------------------------------------------------ diagnostics
class RateMeter:
    """Samples per second over the last diagnostics period, and last-sample age."""

    def __init__(self, clock: Callable[[], float] = time.monotonic):
        self.clock = clock
        self.count = 0
        self.total = 0
        self.last: float | None = None
        self._t0 = clock()

    def tick(self) -> None:
        """Count one sample at the current clock time."""
        self.count += 1
        self.total += 1
        self.last = self.clock()

    def rate(self) -> float:
        """[Hz] since the previous call."""
        now = self.clock()
        r = self.count / max(1e-6, now - self._t0)
        self.count, self._t0 = 0, now
        return r

    def age(self) -> float:
        """Seconds since the last sample (inf before the first) [s]."""
        return math.inf if self.last is None else self.clock() - self.last


def board_status(name: str, source: BoardSource, meter: RateMeter, max_age: float,
                 faults: list[str], extra: dict) -> DiagnosticStatus:
    """DiagnosticStatus of one sensor board.

    Level: ERROR when the board is unconfigured/down/refused or a sensor reports a
    fault; WARN when the link is not up or the last sample is older than ``max_age``
    [s]; OK otherwise.
    """
    st = DiagnosticStatus(name=name, hardware_id=source.port or '(none)')
    rate = meter.rate()
    age = meter.age()
    state = source.state
    if state in ('unconfigured', 'down', 'refused'):
        level, msg = DiagnosticStatus.ERROR, f'board {state}: {source.error() or "no data"}'
    elif faults:
        level, msg = DiagnosticStatus.ERROR, 'sensor fault: ' + '; '.join(faults)
    elif state not in ('up',) and source.framing == 'protocol':
        level, msg = DiagnosticStatus.WARN, f'link {state}'
    elif age > max_age:
        level, msg = DiagnosticStatus.WARN, f'no sample for {age:.1f} s'
    else:
        level, msg = DiagnosticStatus.OK, 'ok'
    st.level, st.message = level, msg
    values = {'port': source.port or '(none)', 'framing': source.framing, 'link_state': state,
              'rate_hz': f'{rate:.2f}', 'samples': str(meter.total),
              'last_sample_age_s': 'never' if math.isinf(age) else f'{age:.2f}',
              'sensor_faults': '; '.join(faults) or 'none'}
    for k, v in source.counters().items():
        values[k] = str(v)
    values.update({k: str(v) for k, v in extra.items()})
    st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
    return st


# ------------------------------------------------------------------ node base
class SensorBoardNode(Node):
    """What the gps, absorber_board and irradiance nodes share.

    ``__init__`` declares and checks the ``params`` table (``ValueError`` on a bad
    start-up value), creates the sample queue (filled in the reader thread, drained by
    the subclass's ``_drain`` on an executor timer), the steady clock, the sample
    :class:`RateMeter` and the ``diagnostics`` publisher. The subclass then creates its
    own state and publishers and calls :meth:`_start_board`. It provides
    ``_on_message(msg)`` (reader thread), ``_apply(new)`` (may raise ValueError/TypeError
    to refuse a change), ``_drain()`` and ``_diagnostics()``; it overrides
    ``_make_source(values)`` for another framing than the board protocol.
    """

    #: parameters whose change reopens the board
    SOURCE_KEYS: tuple[str, ...] = ('port', 'baudrate', 'heartbeat')

    def __init__(self, name: str, params: dict, queue_len: int):
        super().__init__(name)
        self._params = params
        self._values = declare_parameters(self, params)
        check_parameters(params, self._values)
        self._queue: collections.deque = collections.deque(maxlen=queue_len)
        self._queue_dropped = 0  # oldest samples pushed out of a full queue [-]
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._meter = RateMeter()
        self._diag_pub = self.create_publisher(DiagnosticArray, 'diagnostics', 10)
        self._source: BoardSource | None = None

    def _enqueue(self, item) -> None:
        """Queue a sample (reader thread) with its ROS receive time; a full queue drops
        the oldest sample and counts it (``queue_dropped`` in diagnostics)."""
        if len(self._queue) == self._queue.maxlen:
            self._queue_dropped += 1
        self._queue.append((item, self.get_clock().now()))

    def _start_board(self, drain_period: float) -> None:
        """Open the board, accept runtime parameter changes and start the drain
        (every ``drain_period`` [s]) and diagnostics (1 s) steady-clock timers."""
        self._source = self._make_source(self._values).start()
        self.add_on_set_parameters_callback(
            parameter_callback(self, self._params, self._values, self._apply))
        self.create_timer(drain_period, self._drain, clock=self._steady)
        self.create_timer(1.0, self._diagnostics, clock=self._steady)

    def _make_source(self, v: dict) -> BoardSource:
        """The board behind ``v['port']``, board-protocol framing."""
        return BoardSource(v['port'], 'protocol', v['baudrate'], on_message=self._on_message,
                           heartbeat=v['heartbeat'])

    def _reopen_if_changed(self, new: dict) -> None:
        """Restart the board source when a :attr:`SOURCE_KEYS` parameter changes."""
        if any(new[k] != self._values[k] for k in self.SOURCE_KEYS):
            self._source.stop()
            self._source = self._make_source(new).start()

    def _publish_diagnostics(self, *statuses: DiagnosticStatus) -> None:
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = list(statuses)
        self._diag_pub.publish(arr)

    def on_exit(self) -> None:
        """Stop the board source (its reader thread and port); called by run_node once
        spinning ends, while the context is still valid."""
        if self._source is not None:
            self._source.stop()
