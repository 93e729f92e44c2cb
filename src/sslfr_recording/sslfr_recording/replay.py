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
(:mod:`sslfr_recording.bag.whatif`).
"""
from __future__ import annotations

import argparse
import sys

from sslfr_planner.cli_input import (CliError, OneLineParser, bounded_int, output_dir, ranged_float,
                                     read_text_file, ros_remap, ros_topic, run)

from .bag.metadata import BagError
from sslfr_common.timeconv import to_sec
from .bag.playback import absolute, parse_time_spec
from .bag.reader import BagReader
from .player import run_player
from .whatif_run import run_whatif


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


def _utc(ns: int) -> str:
    import datetime as dt
    try:
        return dt.datetime.fromtimestamp(ns / 1e9, dt.timezone.utc).isoformat(timespec='seconds').replace('+00:00', 'Z')
    except (OverflowError, OSError, ValueError):
        return f'{ns / 1e9:.0f} s since 1970'


def check_window(start: int | None, end: int | None, bag_start: int, bag_end: int) -> None:
    """Refuse a play window [start, end] [ns since the epoch] that is inverted or empty, or
    that lies wholly outside the bag's [bag_start, bag_end] (CliError, one line)."""
    lo = bag_start if start is None else start
    hi = bag_end if end is None else end
    if start is not None and end is not None and start >= end:
        raise CliError(f'argument --start/--end: the window {_utc(lo)} .. {_utc(hi)} is '
                       f'{"empty" if lo == hi else "inverted"} (--end must be after --start)')
    if hi < bag_start or lo > bag_end:
        raise CliError(f'argument --start/--end: the window {_utc(lo)} .. {_utc(hi)} lies outside the bag '
                       f'({_utc(bag_start)} .. {_utc(bag_end)})')


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
    check_window(start, end, reader.start_ns, reader.end_ns)
    remaps = remap_table(ns.remap, list(reader.topics))
    if ns.what_if:
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
    span = to_sec(player.last_ns - player.start_ns)
    print(f'replayed {player.count} messages in {player.wall_elapsed:.2f} s'
          + (f' (x{span / player.wall_elapsed:.0f} real time)' if player.wall_elapsed > 0 else '')
          + (' - interrupted' if player.interrupted else ''))
    return 130 if player.interrupted else 0


def main(argv: list[str]) -> int:
    return run('replay', _body, argv)
