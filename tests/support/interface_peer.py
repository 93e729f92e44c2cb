"""A second process for the interface round-trip test: echoes SafetyState messages
from `peer/in` to `peer/out` (level + 1) and serves `peer/set_mode` (SetMode)."""
import sys

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sslfr_interfaces.msg import SafetyState
from sslfr_interfaces.srv import SetMode


class Peer(Node):
    def __init__(self):
        super().__init__('interface_peer')
        self.pub = self.create_publisher(SafetyState, 'peer/out', 10)
        self.create_subscription(SafetyState, 'peer/in', self.on_msg, 10)
        self.create_service(SetMode, 'peer/set_mode', self.on_set_mode)
        self.get_logger().info('peer ready')

    def on_msg(self, msg):
        msg.level = msg.level + 1
        msg.reasons = list(msg.reasons) + ['echoed']
        self.pub.publish(msg)

    def on_set_mode(self, request, response):
        response.success = request.mode in ('auto', 'stow')
        response.message = 'ok' if response.success else f'unknown mode {request.mode!r}'
        response.mode = request.mode if response.success else 'auto'
        return response


def main():
    rclpy.init()
    node = Peer()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
