"""``sslfr record``: run the recorder in the foreground (Ctrl-C stops it cleanly).

Same node as the ``recorder`` executable of the node set; options map to its
parameters. Example: ``sslfr record -o /data/bags --topics gps/fix tracker/phase``.

Every option is checked before anything starts (one-line refusal, exit status 2):
the output directory must be writable (or creatable), numbers finite and within
the node's parameter ranges, names valid ROS names. Exit status 1 when the run
recorded nothing (no publisher, or write errors), 0 otherwise.
"""
from __future__ import annotations

from sslfr_planner.cli_input import (CliError, OneLineParser, file_name, output_dir, ranged_float, ros_node_name,
                                     ros_topic, run)

from .bag.session import probe_output_dir

MIB = 1024 * 1024


def build_ros_args(ns) -> list[str]:
    """Translate CLI options into ``--ros-args -p name:=value`` arguments."""
    params = {'output_dir': str(ns.output), 'prefix': ns.prefix, 'per_day': not ns.single_bag,
              'chunk_duration': ns.chunk_duration, 'compression': ns.compression,
              'max_file_size': int(ns.max_file_size_mib * MIB),
              'max_file_duration': ns.max_file_duration, 'fsync': not ns.no_fsync,
              'min_free_bytes': int(ns.min_free_mib * MIB)}
    if ns.topics:
        params['topics'] = ns.topics
    if ns.exclude is not None:
        params['exclude'] = ns.exclude or ['']
    out = ['--ros-args']
    for key, value in params.items():
        if isinstance(value, bool):
            value = 'true' if value else 'false'
        elif isinstance(value, list):
            value = '[' + ','.join(f"'{v}'" for v in value) + ']'
        elif isinstance(value, float):
            value = repr(value)
        elif isinstance(value, str):
            value = "'" + value.replace("'", "\\'") + "'" if key != 'compression' else value
        out += ['-p', f'{key}:={value}']
    if ns.use_sim_time:
        out += ['-p', 'use_sim_time:=true']
    out += ['-r', f'__node:={ns.node_name}']
    return out


def parser() -> OneLineParser:
    p = OneLineParser(prog='sslfr record', description=__doc__)
    p.add_argument('-o', '--output', default='~/sslfr_bags', type=output_dir,
                   help='bag root directory (created if missing)')
    p.add_argument('--prefix', default='sslfr', type=file_name,
                   help='bag name prefix (<prefix>_YYYY-MM-DD)')
    p.add_argument('--topics', nargs='*', default=None, type=ros_topic,
                   help='topics to record (default: every topic with a publisher)')
    p.add_argument('--exclude', nargs='*', default=None, type=ros_topic,
                   help='topics never recorded (default /clock)')
    p.add_argument('--single-bag', action='store_true', help='one bag for the run, not one per UTC day')
    p.add_argument('--chunk-duration', type=ranged_float(0.05, 60.0, unit='s'), default=2.0,
                   help='max seconds of data a crash can lose (chunk age bound) [s], 0.05..60')
    p.add_argument('--compression', choices=('zstd', 'lz4', 'none'), default='zstd')
    p.add_argument('--max-file-size-mib', type=ranged_float(1.0, 1024.0 * 1024.0, zero=True, unit='MiB'),
                   default=0.0, help='split size [MiB], 0 = off, else 1..1048576')
    p.add_argument('--max-file-duration', type=ranged_float(1.0, 1e7, zero=True, unit='s'),
                   default=0.0, help='split duration [s], 0 = off, else 1..1e7')
    p.add_argument('--min-free-mib', type=ranged_float(0.0, 1024.0 * 1024.0 * 16, unit='MiB'),
                   default=500.0, help='free-disk floor [MiB], 0..16777216')
    p.add_argument('--no-fsync', action='store_true', help='do not fsync each chunk')
    p.add_argument('--use-sim-time', action='store_true', help='log times from /clock (replays)')
    p.add_argument('--node-name', default='recorder', type=ros_node_name)
    return p


def _body(argv: list[str]) -> int:
    ns = parser().parse_args(argv)
    why = probe_output_dir(ns.output)
    if why:
        raise CliError(f'argument -o/--output: {why}')
    from . import recorder_node  # imports rclpy only when really recording
    return int(recorder_node.main(args=['sslfr-record', *build_ros_args(ns)], require_data=True) or 0)


def main(argv: list[str]) -> int:
    return run('record', _body, argv)
