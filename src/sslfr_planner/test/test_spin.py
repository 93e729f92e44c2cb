"""sslfr_planner.spin: one failing take does not end the node's process."""
import rclpy
from rclpy.executors import SingleThreadedExecutor

from sslfr_planner.spin import SpinStats, spin


class FlakyExecutor(SingleThreadedExecutor):
    """Raises like rclpy's take_message did under load, then shuts the context down."""

    def __init__(self, context, failures):
        super().__init__(context=context)
        self.calls = 0
        self.failures = failures

    def spin_once(self, timeout_sec=None):
        self.calls += 1
        if self.calls <= self.failures:
            raise RuntimeError("Unable to convert call argument '0' to Python object")
        rclpy.try_shutdown(context=self.context)


def test_runtime_errors_are_counted_not_fatal(ros_domain):
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=ros_domain)
    node = rclpy.create_node('spin_test', context=ctx)
    try:
        ex = FlakyExecutor(ctx, failures=3)
        stats = spin(node, ex, SpinStats())
        assert stats.errors == 3 and 'Unable to convert' in stats.last
        assert ex.calls == 4
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
