"""Playback of a recorded bag onto the ROS graph (the node side of ``sslfr replay``).

:class:`Player` publishes the recorded serialized bytes (no decode/re-encode) from a
worker thread, on publishers with the recorded QoS (reliability, durability), at
their log times scaled by the rate (0: as fast as possible), with ``/clock``
(rosgraph_msgs/Clock) following the bag time: before each message whose time
advanced, and at ``clock_hz`` while waiting. :func:`run_player` owns the node, its
context and executor for one playback. Used by ``sslfr replay`` (:mod:`.replay`) and
its what-if mode (:mod:`.whatif_run`).
"""
from __future__ import annotations

import sys
import threading
import time

from sslfr_common.contract import CLOCK
from sslfr_common.node import message_class, qos
from sslfr_common.timeconv import stamp_from_ns

from .bag.metadata import BagError
from .bag.playback import Timeline, absolute, progress_line
from .bag.reader import BagReader


def _qos_for(info, QoSProfile, ReliabilityPolicy, DurabilityPolicy):  # noqa: N803
    """Publisher QoS from the recorded offers (rosbag2: reuse the offer if all agree)."""
    offers = info.offered_qos_profiles
    reliable = all(o.get('reliability') == 'reliable' for o in offers) if offers else True
    latched = bool(offers) and all(o.get('durability') == 'transient_local' for o in offers)
    return QoSProfile(depth=10 if not latched else 1,
                      reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                      else DurabilityPolicy.VOLATILE)


class Player:
    """Publishes a bag from a worker thread; the owning node spins in the main thread.

    Parameters
    ----------
    node : rclpy Node
    reader : BagReader
    topics : list of str or None
        Absolute recorded topic names to play (None: all).
    remaps : dict
        Recorded name -> published name.
    rate : float
        Speed factor (0: as fast as possible).
    start_ns, end_ns : int or None
        Window of log times [ns].
    clock_hz : float
        /clock publication rate while waiting [Hz, wall].
    progress : bool
        Draw a progress bar on stderr.
    """

    def __init__(self, node, reader: BagReader, topics=None, remaps=None, rate=1.0,
                 start_ns=None, end_ns=None, clock_hz=100.0, progress=True, publish_clock=True):
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        self.node = node
        self.reader = reader
        self.rate = rate
        self.start_ns = reader.start_ns if start_ns is None else max(start_ns, reader.start_ns)
        self.end_ns = reader.end_ns + 1 if end_ns is None else end_ns
        self.clock_period = 1.0 / clock_hz if clock_hz > 0 else 0.1
        self.progress = progress
        self.publish_clock = publish_clock
        self.stop_event = threading.Event()
        self.done = threading.Event()
        self.count = 0
        self.skipped: dict[str, str] = {}
        self.error: str = ''
        self.wall_elapsed = 0.0
        self.last_ns = self.start_ns
        self.interrupted = False
        self._Clock = Clock
        remaps = remaps or {}
        self.publishers = {}
        wanted = None if topics is None else {absolute(t) for t in topics}
        for name, info in reader.topics.items():
            if wanted is not None and name not in wanted:
                continue
            try:
                cls = message_class(info.type)
            except (ImportError, AttributeError, ValueError) as exc:
                self.skipped[name] = f'type {info.type} not available ({exc})'
                continue
            out = remaps.get(name, name)
            self.publishers[name] = node.create_publisher(
                cls, out, _qos_for(info, QoSProfile, ReliabilityPolicy, DurabilityPolicy))
        self.clock_pub = node.create_publisher(
            Clock, CLOCK.name, qos(CLOCK)) \
            if publish_clock else None
        self._last_clock_ns = None
        self._thread = threading.Thread(target=self._run, name='replay', daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self.stop_event.set()
        self._thread.join(5.0)

    def publish_start_clock(self) -> None:
        """Publish /clock at the start time (used while waiting for subscribers)."""
        self._last_clock_ns = None
        self._clock(self.start_ns)

    def _clock(self, t_ns: int) -> None:
        if self.clock_pub is None or t_ns == self._last_clock_ns:
            return
        self.clock_pub.publish(self._Clock(clock=stamp_from_ns(t_ns)))
        self._last_clock_ns = t_ns

    def _run(self) -> None:
        wall0 = time.monotonic()
        timeline = Timeline(self.start_ns, wall0, self.rate)
        next_progress = wall0
        next_clock = wall0
        t_ns = self.start_ns
        try:
            self._clock(self.start_ns)
            pubs = self.publishers
            messages = self.reader.messages(list(pubs), self.start_ns, self.end_ns)
            if self.rate <= 0:
                # As fast as possible: no timing; /clock and progress every few ms of wall.
                monotonic = time.monotonic
                count = 0
                for raw in messages:
                    if count & 255 == 0:
                        now = monotonic()
                        if self.stop_event.is_set():
                            break
                        if now >= next_clock:
                            self._clock(raw.log_time)
                            next_clock = now + self.clock_period
                        if self.progress and now >= next_progress:
                            sys.stderr.write('\r' + progress_line(raw.log_time, self.start_ns,
                                                                  self.end_ns, count, now - wall0))
                            sys.stderr.flush()
                            next_progress = now + 0.5
                    pubs[raw.topic].publish(raw.data)
                    count += 1
                    t_ns = raw.log_time
                self.count = count
                messages = ()
            for raw in messages:
                if self.stop_event.is_set():
                    break
                due = timeline.due(raw.log_time)
                while True:
                    now = time.monotonic()
                    if now >= due or self.stop_event.is_set():
                        break
                    step = min(due - now, self.clock_period)
                    if self.stop_event.wait(step):
                        break
                    now = time.monotonic()
                    if now >= next_clock:
                        self._clock(min(timeline.bag_time(now), raw.log_time))
                        next_clock = now + self.clock_period
                if self.stop_event.is_set():
                    break
                t_ns = raw.log_time
                self._clock(t_ns)
                pubs[raw.topic].publish(raw.data)
                self.count += 1
                if self.progress and now >= next_progress:
                    sys.stderr.write('\r' + progress_line(t_ns, self.start_ns, self.end_ns,
                                                          self.count, now - wall0))
                    sys.stderr.flush()
                    next_progress = now + 0.5
            if not self.stop_event.is_set():
                self._clock(t_ns)
        except BagError as exc:
            self.error = str(exc)
        finally:
            self.wall_elapsed = time.monotonic() - wall0
            self.last_ns = t_ns
            if self.progress:
                sys.stderr.write('\r' + progress_line(t_ns, self.start_ns, self.end_ns, self.count,
                                                      self.wall_elapsed) + '\n')
                sys.stderr.flush()
            self.done.set()


def _listens(node, name: str, topics: list[str]) -> bool:
    """Whether the node called ``name`` subscribes to every topic of ``topics`` (graph)."""
    return all(any(info.node_name == name for info in node.get_subscriptions_info_by_topic(t))
               for t in topics)


def run_player(reader: BagReader, *, topics=None, remaps=None, rate=1.0, start_ns=None,
               end_ns=None, clock_hz=100.0, progress=True, node_name='sslfr_replay',
               domain_id=None, wait_subscribers: float = 0.0,
               wait_listened: tuple[str, list[str]] | None = None,
               wait_clock_subscribers: int = 0) -> Player:
    """Create a node, play the bag (blocking until done or Ctrl-C), return the Player.

    SIGINT/SIGTERM set a flag (:class:`sslfr_common.node.StopRequest`) that the loop
    below checks at every turn, and wake the executor: the stop never depends on a
    KeyboardInterrupt, which Python does not raise at all in a process started with
    SIGINT ignored (anything run in the background by a non-interactive shell); the
    replay then played on to its end.

    Playing starts when every played topic has a subscriber and, with ``wait_listened``
    = (node name, absolute topic names), when that node (e.g. a recorder) subscribes to
    each of those topics, and when ``/clock`` has matched at least
    ``wait_clock_subscribers`` subscriptions (the sim-time nodes of a private domain: a
    node whose /clock matched late would start its decisions that late in the stretch),
    or after ``wait_subscribers`` seconds (steady clock) at most."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from sslfr_common.node import StopRequest
    stop = StopRequest()
    context = rclpy.Context()
    kwargs = {'context': context, 'signal_handler_options': SignalHandlerOptions.NO}
    if domain_id is not None:
        kwargs['domain_id'] = int(domain_id)
    rclpy.init(**kwargs)
    node = rclpy.create_node(node_name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stop.executor = executor
    player = Player(node, reader, topics, remaps, rate, start_ns, end_ns, clock_hz, progress)
    try:
        deadline = time.monotonic() + wait_subscribers
        pubs = list(player.publishers.values())
        while time.monotonic() < deadline and not stop.requested.is_set():
            player.publish_start_clock()  # sim-time subscribers get a clock before any data
            if (pubs and all(p.get_subscription_count() > 0 for p in pubs)
                    and (wait_listened is None or _listens(node, *wait_listened))
                    and (player.clock_pub is None
                         or player.clock_pub.get_subscription_count() >= wait_clock_subscribers)):
                break
            executor.spin_once(timeout_sec=0.05)
        if not stop.requested.is_set():
            player.start()
        while not player.done.is_set() and not stop.requested.is_set():
            executor.spin_once(timeout_sec=0.05)
    finally:
        stop.ignore_further()
        if stop.requested.is_set():
            player.interrupted = True
        player.stop()
        if player.interrupted:
            sys.stderr.write('\nreplay: interrupted\n')
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        stop.close()
    return player
