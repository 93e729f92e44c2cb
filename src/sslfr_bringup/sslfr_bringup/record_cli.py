"""``sslfr record``: run the recorder in the foreground (Ctrl-C stops it cleanly).

Same node as the ``recorder`` executable of the node set; options map to its
parameters. Example: ``sslfr record -o /data/bags --topics gps/fix tracker/phase``.
"""
from __future__ import annotations

import argparse


def build_ros_args(ns: argparse.Namespace) -> list[str]:
    """Translate CLI options into ``--ros-args -p name:=value`` arguments."""
    params = {'output_dir': ns.output, 'prefix': ns.prefix, 'per_day': not ns.single_bag,
              'chunk_duration': ns.chunk_duration, 'compression': ns.compression,
              'max_file_size': int(ns.max_file_size_mib * 1024 * 1024),
              'max_file_duration': ns.max_file_duration, 'fsync': not ns.no_fsync,
              'min_free_bytes': int(ns.min_free_mib * 1024 * 1024)}
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
        out += ['-p', f'{key}:={value}']
    if ns.use_sim_time:
        out += ['-p', 'use_sim_time:=true']
    out += ['-r', f'__node:={ns.node_name}']
    return out


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='sslfr record', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('-o', '--output', default='~/sslfr_bags', help='bag root directory')
    p.add_argument('--prefix', default='sslfr', help='bag name prefix (<prefix>_YYYY-MM-DD)')
    p.add_argument('--topics', nargs='*', default=None,
                   help='topics to record (default: every topic with a publisher)')
    p.add_argument('--exclude', nargs='*', default=None, help='topics never recorded (default /clock)')
    p.add_argument('--single-bag', action='store_true', help='one bag for the run, not one per UTC day')
    p.add_argument('--chunk-duration', type=float, default=2.0,
                   help='max seconds of data a crash can lose (chunk age bound) [s]')
    p.add_argument('--compression', choices=('zstd', 'lz4', 'none'), default='zstd')
    p.add_argument('--max-file-size-mib', type=float, default=0.0, help='split size [MiB], 0 = off')
    p.add_argument('--max-file-duration', type=float, default=0.0, help='split duration [s], 0 = off')
    p.add_argument('--min-free-mib', type=float, default=500.0, help='free-disk floor [MiB]')
    p.add_argument('--no-fsync', action='store_true', help='do not fsync each chunk')
    p.add_argument('--use-sim-time', action='store_true', help='log times from /clock (replays)')
    p.add_argument('--node-name', default='recorder')
    return p


def main(argv: list[str]) -> int:
    ns = parser().parse_args(argv)
    from . import recorder_node  # imports rclpy only when really recording
    return int(recorder_node.main(args=['sslfr-record', *build_ros_args(ns)]) or 0)
