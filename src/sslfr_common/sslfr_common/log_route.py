"""Which ROS node a Python ``logging`` line belongs to (pure Python, no rclpy).

Library code (board links, control loops) logs through ``logging``; the process's
:class:`sslfr_common.node.LogBridge` forwards the lines to a node's rclpy logger, hence
to ``/rosout`` and the day's bag. A process running several nodes (the ``composed``
layout) must not put one driver's lines under another's name: a call made on behalf of
a node passes ``extra=log_extra(name)``, and the bridge sends it to that node.
"""
from __future__ import annotations

#: the ``logging.LogRecord`` attribute naming the node
NODE_ATTR = 'sslfr_node'


def log_extra(node_name: str) -> dict:
    """``extra=`` for a ``logging`` call made on behalf of node ``node_name`` ('': none)."""
    return {NODE_ATTR: node_name} if node_name else {}
