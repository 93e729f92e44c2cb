"""``sslfr replay BAG``: republish a recorded bag with its original timing and /clock.

::

    sslfr replay BAG [--rate X] [--topics T ...] [--remap a:=b ...] [--start T] [--end T]
    sslfr replay BAG --what-if [--out DIR]      # see docs/bags.md

Messages are published as the recorded serialized bytes (no decode/re-encode) on
publishers with the recorded QoS (reliability, durability), at their log times scaled
by ``--rate`` (``--rate 0``: as fast as possible). ``/clock`` (rosgraph_msgs/Clock)
follows the bag time: before each message whose time advanced, and at ``--clock-hz``
while waiting, so nodes started with ``use_sim_time:=true`` live on the recorded day.
A progress bar goes to stderr; Ctrl-C stops cleanly.

``--what-if`` plays only the sensor inputs (GPS fix, absorber temperatures,
irradiance, limit switches) into a freshly started ``planner`` and ``safety`` on a
private ROS domain, records their decisions (tracker/phase, safety/state,
tracker/trajectory) and compares them with the recorded ones
(:mod:`sslfr_bringup.bag.whatif`).
"""
from __future__ import annotations

import argparse
import importlib
import sys
import threading
import time

from sslfr_planner.cli_input import (CliError, OneLineParser, bounded_int, output_dir, ranged_float,
                                     read_text_file, ros_remap, ros_topic, run)

from .bag.metadata import BagError
from .bag.playback import Timeline, absolute, parse_time_spec, progress_line
from .bag.reader import BagReader

#: Inputs played in what-if mode (relative names): the sensors (GPS, absorber
#: temperatures, irradiance, limit switches) and the axes' measured state, which the
#: safety supervisor watches (heartbeat watchdogs) and the planner does not produce.
WHATIF_INPUTS = ['gps/fix', 'gps/time_reference', 'absorber/inlet_temperature',
                 'absorber/outlet_temperature', 'irradiance/beam', 'irradiance/illuminance',
                 'limit_switches', 'joint_states', 'axes/mirrors/status',
                 'axes/mobile_structure/status', 'axes/secondary_reflector/status']
#: Decisions compared in what-if mode.
WHATIF_DECISIONS = ['tracker/phase', 'safety/state', 'tracker/trajectory']


def _import_message(type_name: str):
    pkg, _, typ = type_name.split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), typ)


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
                cls = _import_message(info.type)
            except (ImportError, AttributeError, ValueError) as exc:
                self.skipped[name] = f'type {info.type} not available ({exc})'
                continue
            out = remaps.get(name, name)
            self.publishers[name] = node.create_publisher(
                cls, out, _qos_for(info, QoSProfile, ReliabilityPolicy, DurabilityPolicy))
        self.clock_pub = node.create_publisher(
            Clock, '/clock', QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)) \
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
        msg = self._Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(int(t_ns), 1_000_000_000)
        self.clock_pub.publish(msg)
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


def run_player(reader: BagReader, *, topics=None, remaps=None, rate=1.0, start_ns=None,
               end_ns=None, clock_hz=100.0, progress=True, node_name='sslfr_replay',
               domain_id=None, wait_subscribers: float = 0.0, wait_for: list[str] | None = None,
               before_play=None) -> Player:
    """Create a node, play the bag (blocking until done or Ctrl-C), return the Player."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    context = rclpy.Context()
    kwargs = {'context': context}
    if domain_id is not None:
        kwargs['domain_id'] = int(domain_id)
    rclpy.init(**kwargs)
    node = rclpy.create_node(node_name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    player = Player(node, reader, topics, remaps, rate, start_ns, end_ns, clock_hz, progress)
    try:
        if before_play is not None:
            before_play(node, executor)
        deadline = time.monotonic() + wait_subscribers
        while time.monotonic() < deadline:
            player.publish_start_clock()  # sim-time subscribers get a clock before any data
            pubs = [p for t, p in player.publishers.items() if wait_for is None or t in wait_for]
            if pubs and all(p.get_subscription_count() > 0 for p in pubs):
                break
            executor.spin_once(timeout_sec=0.05)
        player.start()
        while not player.done.is_set():
            executor.spin_once(timeout_sec=0.05)
    except KeyboardInterrupt:
        player.interrupted = True
        player.stop()
        sys.stderr.write('\nreplay: interrupted\n')
    finally:
        player.stop()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return player


def parser() -> OneLineParser:
    p = OneLineParser(prog='sslfr replay', description=__doc__,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('bag', help='bag directory (or .mcap file)')
    p.add_argument('--rate', type=ranged_float(0.001, 1e6, zero=True), default=1.0,
                   help='speed factor 0.001..1e6, 0 = as fast as possible')
    p.add_argument('--topics', nargs='+', default=None, type=ros_topic,
                   help='topics to play (default: all)')
    p.add_argument('--remap', nargs='+', default=[], metavar='FROM:=TO', type=ros_remap,
                   help='rename topics')
    p.add_argument('--start', default=None, help='seconds from start, -s from end, HH:MM[:SS] UTC or ISO')
    p.add_argument('--end', default=None, help='same forms as --start')
    p.add_argument('--clock-hz', type=ranged_float(0.1, 10000.0, unit='Hz'), default=100.0,
                   help='/clock rate while waiting [Hz wall], 0.1..10000')
    p.add_argument('--no-progress', action='store_true')
    p.add_argument('--wait-subscribers', type=ranged_float(0.0, 3600.0, unit='s'), default=0.0,
                   help='wait up to this long [s] (0..3600) for a subscriber on every played topic')
    p.add_argument('--what-if', action='store_true',
                   help='play sensor inputs into a fresh planner + safety and compare decisions')
    p.add_argument('--out', default=None, type=output_dir,
                   help='what-if: where to keep the decisions bag and report')
    p.add_argument('--config', default=None, help='what-if: site params file for planner/safety')
    p.add_argument('--domain', type=bounded_int(0, 232), default=None,
                   help='what-if: ROS domain id 0..232 (default: a free one)')
    p.add_argument('--inputs', nargs='+', default=None, type=ros_topic,
                   help='what-if: input topics to play')
    return p


def remap_table(pairs: list[tuple[str, str]], recorded: list[str]) -> dict[str, str]:
    """Recorded name -> published name, refusing remaps that would collide.

    Two played topics must never end up on one name (one node cannot publish two
    types on a name; rclpy would raise).

    Raises
    ------
    CliError
        A remap of a topic the bag does not hold, or a collision.
    """
    out: dict[str, str] = {}
    for src, dst in pairs:
        a = absolute(src)
        if a not in recorded:
            raise CliError(f'argument --remap: {src}:={dst}: the bag has no topic {a}')
        out[a] = dst if not dst.startswith('/') else absolute(dst)
    final: dict[str, str] = {}
    for name in recorded:
        target = absolute(out.get(name, name))
        if target in final:
            raise CliError(f'argument --remap: {final[target]} and {name} would both be published '
                           f'on {target}')
        final[target] = name
    return out


def _body(argv: list[str]) -> int:
    ns = parser().parse_args(argv)
    if ns.config is not None:
        read_text_file(ns.config, '--config')
    if ns.domain is not None and not ns.what_if:
        raise CliError('argument --domain: only with --what-if')
    try:
        reader = BagReader(ns.bag)
    except BagError as exc:
        raise CliError(f'bag {ns.bag}: {exc}') from None
    try:
        start = parse_time_spec(ns.start, reader.start_ns, reader.end_ns) if ns.start else None
        end = parse_time_spec(ns.end, reader.start_ns, reader.end_ns) if ns.end else None
    except ValueError as exc:
        raise CliError(f'argument --start/--end: {exc}') from None
    remaps = remap_table(ns.remap, list(reader.topics))
    if ns.what_if:
        from .whatif_run import run_whatif
        return run_whatif(reader, ns, start, end)
    topics = [absolute(t) for t in ns.topics] if ns.topics else None
    if topics:
        missing = [t for t in topics if t not in reader.topics]
        if missing:
            raise CliError(f'argument --topics: not in the bag: {", ".join(missing)}')
    player = run_player(reader, topics=topics, remaps=remaps, rate=ns.rate, start_ns=start,
                        end_ns=end, clock_hz=ns.clock_hz, progress=not ns.no_progress,
                        wait_subscribers=ns.wait_subscribers)
    for name, why in player.skipped.items():
        print(f'sslfr replay: skipped {name}: {why}', file=sys.stderr)
    if player.error:
        print(f'sslfr replay: {player.error}', file=sys.stderr)
        return 1
    span = (player.last_ns - player.start_ns) / 1e9
    print(f'replayed {player.count} messages in {player.wall_elapsed:.2f} s'
          + (f' (x{span / player.wall_elapsed:.0f} real time)' if player.wall_elapsed > 0 else '')
          + (' - interrupted' if player.interrupted else ''))
    return 130 if player.interrupted else 0


def main(argv: list[str]) -> int:
    return run('replay', _body, argv)
