"""The recorder node's parameters and decisions (pure Python, no rclpy).

- :data:`TABLE`: every parameter once (sslfr_common.params), with its unit and range;
- :func:`make_session`: the recording session a configuration asks for;
- :func:`needs_new_bag`: which run-time changes only apply from a new bag;
- :func:`wanted`: whether a topic is recorded (list / exclude / always excluded);
- :func:`log_line_kept`: whether a ``/rosout`` line delivered on subscribing is kept;
- :func:`subscription_qos`: what to ask of a topic's publishers (rosbag2's rule);
- :func:`qos_to_dict`: a publisher's offered QoS as rosbag2 v9 stores it.
"""
from __future__ import annotations

import functools

import os
from typing import Any, Iterable

from sslfr_common.contract import CLOCK
from sslfr_common.params import ParamSpec, ParamTable, writable_directory
from sslfr_common.timeconv import to_sec

from .policy import DiskGuard, SplitPolicy
from .qos import duration_dict
from .session import RecordingSession, probe_output_dir
from .writer import WriterOptions

#: Never recorded, whatever the lists say (every node's parameter changes, which a
#: parameter service answers; ``ros2 bag record -a`` keeps it, we leave it out).
ALWAYS_EXCLUDED = ('/parameter_events',)
#: The nodes' log lines (rcl_interfaces/msg/Log): recorded like any topic.

#: Changes that apply from a new bag (the current one is closed cleanly).
WRITER_KEYS = frozenset({'output_dir', 'prefix', 'per_day', 'max_file_size', 'max_file_duration',
                         'chunk_duration', 'chunk_size', 'compression', 'fsync', 'min_free_bytes',
                         'min_free_fraction', 'disk_check_period'})


def _cross_check(v: dict[str, Any]) -> list[str]:
    errors = []
    if not str(v['output_dir']).strip():
        errors.append('output_dir is empty')
    p = v['prefix']
    if not p or '/' in p or '\0' in p or p in ('.', '..'):
        errors.append('prefix must be a non-empty name without /')
    return errors


TABLE = ParamTable((
    ParamSpec('output_dir', '~/sslfr_bags', 'directory where bag directories are created '
              '(must be writable, or creatable)',
              validator=functools.partial(writable_directory, empty_ok=False)),
    ParamSpec('prefix', 'sslfr', 'bag directory name prefix: <prefix>_YYYY-MM-DD'),
    ParamSpec('topics', [''], 'topics to record (relative names are resolved in the node '
                              'namespace); empty = every topic with a publisher'),
    ParamSpec('exclude', [CLOCK.name], 'topics never recorded (besides /parameter_events)'),
    ParamSpec('discovery_period', 1.0, 'period of topic discovery [s]', 's', 0.1, 60.0),
    ParamSpec('per_day', True, 'one bag per UTC day of ROS time (else one bag per run)'),
    ParamSpec('max_file_size', 0, 'split the bag into a new .mcap at this size [bytes]; 0 = off',
              'bytes', 0, 2**62),
    ParamSpec('max_file_duration', 0.0, 'split into a new .mcap after this much log time [s]; 0 = off',
              's', 0.0, 1e7),
    ParamSpec('chunk_duration', 2.0, 'max age of unwritten data [s]: bounds what a crash loses',
              's', 0.05, 60.0),
    ParamSpec('chunk_size', 1048576, 'MCAP chunk size [bytes]', 'bytes', 1024, 1 << 30),
    ParamSpec('compression', 'zstd', 'MCAP chunk compression: zstd | lz4 | none',
              choices=('zstd', 'lz4', 'none')),
    ParamSpec('fsync', True, 'fsync every chunk (power-cut safety)'),
    ParamSpec('min_free_bytes', 500 * 1024 * 1024, 'stop recording below this free space [bytes]',
              'bytes', 0, 2**62),
    ParamSpec('min_free_fraction', 0.02, 'stop recording below this free fraction of the disk [-]',
              '-', 0.0, 0.99),
    ParamSpec('disk_check_period', 5.0, 'period of the free-disk check [s]', 's', 0.1, 3600.0),
    ParamSpec('queue_depth', 100, 'subscription history depth [messages]', '-', 1, 100000),
), _cross_check)


def output_error(cfg: dict[str, Any]) -> str:
    """Why ``output_dir`` cannot hold bags ('' when it can): a real write probe."""
    why = probe_output_dir(os.path.expanduser(str(cfg['output_dir'])))
    return f'output_dir {cfg["output_dir"]!r}: {why}' if why else ''


def make_session(cfg: dict[str, Any]) -> RecordingSession:
    """The recording session (writer options, split and disk policies) of ``cfg``."""
    opts = WriterOptions(chunk_size=int(cfg['chunk_size']), chunk_duration_s=float(cfg['chunk_duration']),
                         compression=cfg['compression'], fsync=bool(cfg['fsync']),
                         split=SplitPolicy(int(cfg['max_file_size']), float(cfg['max_file_duration'])))
    guard = DiskGuard(min_free_bytes=int(cfg['min_free_bytes']),
                      min_free_fraction=float(cfg['min_free_fraction']))
    return RecordingSession(os.path.expanduser(cfg['output_dir']), cfg['prefix'], bool(cfg['per_day']),
                            opts, guard, float(cfg['disk_check_period']))


def needs_new_bag(old: dict[str, Any], new: dict[str, Any]) -> bool:
    """Whether the change from ``old`` to ``new`` applies only from a new bag."""
    return any(old[k] != new[k] for k in WRITER_KEYS)


def wanted(topic: str, listed: Iterable[str], excluded: Iterable[str]) -> bool:
    """Whether ``topic`` (resolved) is recorded: never the always-excluded ones nor
    ``excluded``; when ``listed`` is not empty, only those (all names resolved)."""
    listed = [t for t in listed if t]
    return topic not in ALWAYS_EXCLUDED and topic not in set(excluded) and (not listed or topic in listed)


def log_line_kept(source_ns: int, started_ns: int) -> bool:
    """Whether a ``/rosout`` line published at ``source_ns`` (the DDS source timestamp,
    system clock [ns]; 0 = unknown) is recorded by a recorder that started at
    ``started_ns`` (system clock [ns]).

    Every node offers ``/rosout`` transient local (rcl: keep last 1000, lifespan 10 s),
    so a subscriber gets each publisher's last 10 s again when it matches: the start-up
    lines of a node that starts after the recorder are kept, but a restarted recorder
    would get lines its previous run already wrote (or lost with its last chunk),
    stamped with the new reception time. Those, older than this recorder, are dropped.
    """
    return source_ns <= 0 or source_ns >= started_ns


def subscription_qos(offered: list[tuple[bool, bool]]) -> tuple[bool, bool]:
    """``(reliable, transient_local)`` to ask of a topic whose publishers offer
    ``offered`` = [(reliable, transient_local), ...]: reliable only if all are,
    transient local only if all are (rosbag2's rule, so every publisher matches)."""
    return all(r for r, _ in offered), all(t for _, t in offered)


def qos_to_dict(qos) -> dict:
    """An rclpy QoSProfile -> rosbag2 v9 profile dict (durations as {sec, nsec})."""
    def name(enum_value) -> str:
        return getattr(enum_value, 'name', str(enum_value)).lower()

    def dur(d) -> dict:
        ns = getattr(d, 'nanoseconds', 0)
        return duration_dict(None) if ns >= 0x7FFFFFFFFFFFFFFF else duration_dict(to_sec(ns)) \
            if ns >= 0 else duration_dict(0.0)

    return {'history': name(qos.history), 'depth': int(qos.depth),
            'reliability': name(qos.reliability), 'durability': name(qos.durability),
            'deadline': dur(qos.deadline), 'lifespan': dur(qos.lifespan),
            'liveliness': name(qos.liveliness),
            'liveliness_lease_duration': dur(qos.liveliness_lease_duration),
            'avoid_ros_namespace_conventions': bool(qos.avoid_ros_namespace_conventions)}
