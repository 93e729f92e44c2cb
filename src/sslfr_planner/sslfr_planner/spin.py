"""Spin a node so that one message rclpy cannot take never ends the process.

Under heavy load we saw rclpy's ``take_message`` raise ``RuntimeError: Unable to
convert call argument '0' to Python object`` for a received message (the planner and
the safety supervisor each died of it once in a simulated day; compare
ros2/rclpy#848). ``rclpy.spin`` lets that exception end the process. A tracker node
must not die of one bad message: :func:`spin` drops it, logs it (throttled) and
counts it, and goes on. Used by every node of the project (sslfr_planner is the
lowest Python package of the workspace; sslfr_drivers and sslfr_bringup depend on it).
"""
from __future__ import annotations

from rclpy.executors import Executor, SingleThreadedExecutor


class SpinStats:
    """What :func:`spin` dropped: ``errors`` [-] and the ``last`` error text."""

    def __init__(self):
        self.errors = 0
        self.last = ''


def spin(node, executor: Executor | None = None, stats: SpinStats | None = None) -> SpinStats:
    """Spin ``node`` (in ``executor``, default a single-threaded one) until shutdown.

    A ``RuntimeError`` raised by the executor (a message that could not be taken or
    converted, or a callback failing with it) is logged and counted in ``stats``
    instead of ending the process. ``KeyboardInterrupt`` and
    ``ExternalShutdownException`` pass through to the caller's Jazzy
    ``try/except/finally`` as with ``rclpy.spin``.
    """
    stats = stats or SpinStats()
    if executor is None:
        executor = SingleThreadedExecutor(context=node.context)
    if node not in executor.get_nodes():
        executor.add_node(node)
    while node.context.ok():
        try:
            executor.spin_once(timeout_sec=0.5)
        except RuntimeError as exc:
            stats.errors += 1
            stats.last = str(exc)
            node.get_logger().error(f'a message or callback failed and was dropped ({stats.errors} so far): {exc}',
                                    throttle_duration_sec=5.0)
    return stats
