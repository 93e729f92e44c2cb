"""``foxglove_bridge`` node: the graph's topics live to Foxglove (foxglove-sdk).

Every topic with a publisher (or the ``topics`` listed) is advertised as a channel
with the ``ros2msg`` schema rosbag2 would store (sslfr_recording.bag.schema) and
``cdr`` message encoding; a ROS subscription (raw: the serialized CDR bytes, never
decoded) exists only while a Foxglove client is subscribed to that channel. The SDK
server listens on a free loopback port behind its relay on ``bind_address:port``
(:class:`~.foxglove_front.FoxgloveFront`: allow-list, connection caps, message size and
rate limits; the SDK's own log lines counted and rate-limited). Every refusal is a count
in ``diagnostics`` (1 Hz). Off by default in the node set.
"""
from __future__ import annotations

import sys
import threading

import foxglove
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sslfr_common.contract import DIAGNOSTICS
from sslfr_common.netguard import OneLineLog
from sslfr_common.node import (CONFIG_ERRORS, LeanEvents, declare_parameters, diagnostics_msg, message_class, qos,
                               run_node)
from sslfr_recording.bag import recorder_config as rc
from sslfr_recording.bag.schema import DefinitionCache, DefinitionNotFoundError

from . import params as gp
from .foxglove_front import FoxgloveFront


class _Listener(foxglove.ServerListener):
    """Counts Foxglove subscribers per topic (SDK thread); the node applies them."""

    def __init__(self):
        self.lock = threading.Lock()
        self.subscribers: dict[str, int] = {}

    def on_subscribe(self, client, channel) -> None:  # noqa: ARG002 - SDK signature
        with self.lock:
            self.subscribers[channel.topic] = self.subscribers.get(channel.topic, 0) + 1

    def on_unsubscribe(self, client, channel) -> None:  # noqa: ARG002 - SDK signature
        with self.lock:
            self.subscribers[channel.topic] = max(0, self.subscribers.get(channel.topic, 0) - 1)

    def wanted(self) -> set[str]:
        with self.lock:
            return {t for t, n in self.subscribers.items() if n > 0}


class FoxgloveBridge(LeanEvents, Node):
    def __init__(self, **kwargs):
        super().__init__('foxglove_bridge', **kwargs)
        cfg = declare_parameters(self, gp.FOXGLOVE_PARAMS)
        self.cfg = cfg
        self.listener = _Listener()
        self.front = FoxgloveFront(cfg, self.listener, OneLineLog(self._log_line), f'sslfr {self.get_namespace()}')
        port = self.front.start()
        self.defs = DefinitionCache()
        self.channels: dict[str, tuple[foxglove.Channel, str]] = {}
        self.subs: dict[str, tuple[object, tuple[bool, bool]]] = {}   # topic -> (subscription, its QoS)
        self.bad: set[str] = set()
        self.forwarded = 0
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(float(cfg['discovery_period']), self._discover_and_recheck, clock=steady)
        self.create_timer(0.2, self._apply_subscriptions, clock=steady)
        self._diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, qos(DIAGNOSTICS))
        self.create_timer(1.0, self._diagnostics, clock=steady)
        self._discover()
        self.get_logger().info(f"Foxglove WebSocket at ws://{cfg['bind_address']}:{port} "
                               f"(clients from: {', '.join(gp.allowed(cfg['allow'])) or 'none'})")

    def _log_line(self, level: str, text: str) -> None:
        (self.get_logger().error if level == 'error' else self.get_logger().warn)(text)

    def _diagnostics(self) -> None:
        """Clients and every refusal as counts (relay, connection guard, SDK)."""
        counts = {'channels': len(self.channels), 'forwarded': self.forwarded, **self.front.counters()}
        self._diag.publish(diagnostics_msg(f'{self.get_name()}: foxglove', 0, 'serving', 'foxglove_bridge',
                                           counts, self.get_clock().now().to_msg()))

    def _topics_wanted(self, topic: str) -> bool:
        listed = [self.resolve_topic_name(t) for t in self.cfg['topics'] if t]
        return not listed or topic in listed

    def _discover_and_recheck(self) -> None:
        self._discover()
        self._apply_subscriptions(recheck=True)

    def _discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self.channels or len(types) != 1 or types[0] in self.bad or not self._topics_wanted(topic):
                continue
            if not self.get_publishers_info_by_topic(topic):
                continue
            try:
                message_class(types[0])
                text = self.defs.full_text(types[0])
            except (ImportError, AttributeError, ValueError, DefinitionNotFoundError) as exc:
                self.bad.add(types[0])
                self.get_logger().error(f'cannot carry {topic} ({types[0]}): {exc}')
                continue
            schema = foxglove.Schema(name=types[0], encoding='ros2msg', data=text.encode())
            self.channels[topic] = (foxglove.Channel(topic, schema=schema, message_encoding='cdr'), types[0])

    def _offered(self, topic: str) -> tuple[bool, bool] | None:
        """``(reliable, transient_local)`` that matches every publisher of ``topic`` now
        (the recorder's rule); None while it has none."""
        pubs = self.get_publishers_info_by_topic(topic)
        if not pubs:
            return None
        return rc.subscription_qos([(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE,
                                     p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL) for p in pubs])

    def _apply_subscriptions(self, recheck: bool = False) -> None:
        """A raw subscription per topic a client wants, made when it has a publisher and
        made again when its publishers' QoS changes (``recheck``, every discovery: a
        publisher restarted or joined with a weaker QoS would not match the old one)."""
        wanted = self.listener.wanted()
        for topic in list(self.subs):
            if topic not in wanted:
                self.destroy_subscription(self.subs.pop(topic)[0])
        for topic in wanted:
            if topic not in self.channels or (topic in self.subs and not recheck):
                continue
            offered = self._offered(topic)
            if offered is None or (topic in self.subs and self.subs[topic][1] == offered):
                continue
            if topic in self.subs:
                self.destroy_subscription(self.subs.pop(topic)[0])
            channel, type_name = self.channels[topic]
            reliable, latched = offered
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                             reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
            self.subs[topic] = (self.create_subscription(
                message_class(type_name), topic, self._forwarder(channel), qos, raw=True), offered)

    def _forwarder(self, channel):
        clock = self.get_clock()

        def forward(data: bytes) -> None:
            self.forwarded += 1
            now = clock.now().nanoseconds
            channel.log(bytes(data), log_time=now if now > 0 else None)
        return forward

    def on_exit(self) -> None:
        self.front.stop()


def main(args=None) -> int:
    return run_node('foxglove_bridge', FoxgloveBridge, args=args, config_errors=CONFIG_ERRORS + (OSError,))


if __name__ == '__main__':
    sys.exit(main())
