"""The Node base class of the three sensor nodes (``gps``, ``absorber_board``,
``irradiance``): only the ROS wiring they share.

What it wires, and where the logic lives:

- parameters: the node's table (:mod:`sslfr_drivers.sensors.sensor_params`) declared
  with ``sslfr_common.node.declare_parameters`` (a bad start-up value: exit 2), run-time
  changes through ``ParameterGuard`` (refused with the reason, last good set kept);
- the board: :class:`~sslfr_drivers.sensors.source.BoardSource` (reconnecting reader),
  reopened when ``port``/``baudrate``/``heartbeat``/``framing`` change;
- samples: reader thread -> :class:`~sslfr_drivers.sensors.source.SampleQueue` (with
  the ROS receive time) -> the subclass's ``_drain``, woken by a guard condition when
  the queue stops being empty (no polling timer);
- diagnostics: :func:`~sslfr_drivers.sensors.health.board_report` every second;
- clean-up: :meth:`SensorBoardNode.on_exit` stops the board (called by ``run_node``).
"""
from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from sslfr_common.contract import DIAGNOSTICS, collector_id
from sslfr_common.node import LeanEvents, ParameterGuard, declare_parameters, qos
from sslfr_common.params import ParamTable
from sslfr_drivers.sensors.health import RateMeter, Report, board_report
from sslfr_drivers.sensors.sensor_params import SOURCE_KEYS
from sslfr_drivers.sensors.source import BoardSource, SampleQueue


class _LoggingGuard(ParameterGuard):
    """ParameterGuard that also logs every refusal on the node's logger."""

    def __init__(self, node, *args):
        self._node = node
        super().__init__(node, *args)

    def _refuse(self, reason: str):
        self._node.get_logger().error(f'parameter change refused: {reason}')
        return super()._refuse(reason)


class SensorBoardNode(LeanEvents, Node):
    """What the gps, absorber_board and irradiance nodes share (module docstring).

    ``__init__`` declares ``table`` (``ValueError`` on a bad start-up value), creates
    the sample queue, the steady clock, the sample :class:`RateMeter` and the
    ``diagnostics`` publisher. The subclass then creates its own state and
    publishers and calls :meth:`_start_board`. It provides ``_on_message(msg)``
    (reader thread), ``_apply(new)`` (may raise ValueError to refuse a change),
    ``_drain()`` and ``_diagnostics()``.
    """

    def __init__(self, name: str, table: ParamTable, queue_len: int, **kwargs):
        super().__init__(name, **kwargs)
        self._table = table
        self._values = declare_parameters(self, table)
        self._queue = SampleQueue(queue_len)
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._meter = RateMeter()
        self._diag_name = f'{name}: board'
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, qos(DIAGNOSTICS))
        self._source: BoardSource | None = None
        self._guard: ParameterGuard | None = None

    # -------------------------------------------------------------- board
    def _start_board(self) -> None:
        """Open the board, accept run-time parameter changes, drain samples as they
        arrive (guard condition) and publish diagnostics (1 s steady-clock timer)."""
        self._wake = self.create_guard_condition(self._drain)
        self._source = self._make_source(self._values).start()
        self._guard = _LoggingGuard(self, self._table, self._values, self._change)
        self.create_timer(1.0, self._diagnostics, clock=self._steady)

    def _make_source(self, v: dict) -> BoardSource:
        return BoardSource(v['port'], v.get('framing', 'protocol'), v['baudrate'],
                           on_message=self._on_message, on_bytes=self._enqueue,
                           heartbeat=v['heartbeat'], key_file=v.get('key_file', ''),
                           on_up=self._on_link_up, owner=self.get_name())

    def _change(self, new: dict) -> None:
        """ParameterGuard's apply: reopen the board if needed, then the subclass's
        ``_apply`` (may refuse); the new set is in force once both pass."""
        self._apply(new)
        if any(new.get(k) != self._values.get(k) for k in SOURCE_KEYS):
            self._source.stop()
            self._source = self._make_source(new).start()
        self._values.update(new)

    def _apply(self, new: dict) -> None:
        """Subclass hook: take a validated new parameter set (``self._values`` still
        holds the old one); raise ValueError to refuse it."""

    # -------------------------------------------------------------- samples
    def _on_message(self, msg) -> None:
        """Subclass hook: one decoded board message (reader thread)."""

    def _on_link_up(self, link) -> None:
        """Subclass hook: the board link came up (reader thread; submit, never block)."""

    def _enqueue(self, item) -> None:
        """Queue a sample (reader thread) with its ROS receive time."""
        if self._queue.put(item, self.get_clock().now()):
            self._wake.trigger()

    # -------------------------------------------------------------- diagnostics
    def _publish_diagnostics(self, faults: list[str], extra: dict,
                             *more: tuple[str, Report]) -> None:
        """Publish the ``<node>: board`` status (:func:`board_report`) and ``more``
        (name, report) statuses in one DiagnosticArray."""
        reports = [(self._diag_name, board_report(self._source, self._meter,
                                                  self._values['max_sample_age'], faults, extra)),
                   *more]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        hw = collector_id(self.get_namespace())
        arr.status = [DiagnosticStatus(name=name, hardware_id=hw, level=getattr(DiagnosticStatus, r.level),
                                       message=r.message,
                                       values=[KeyValue(key='port', value=self._values['port'] or '(none)'),
                                               *(KeyValue(key=k, value=v) for k, v in r.values.items())])
                      for name, r in reports]
        self._diag_pub.publish(arr)

    # -------------------------------------------------------------- clean-up
    def on_exit(self) -> None:
        """Stop the board source (its reader thread and port); called by run_node once
        spinning ends, while the context is still valid."""
        if self._source is not None:
            self._source.stop()
