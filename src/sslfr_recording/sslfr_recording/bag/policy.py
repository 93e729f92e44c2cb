"""Recording policies: bag naming per UTC day, file splitting, free-disk guard.

Times are integer nanoseconds since the Unix epoch (UTC) unless a name says ``_s``.
"""
from __future__ import annotations

import datetime as _dt
import os
import shutil
from dataclasses import dataclass

from sslfr_common.timeconv import NS_PER_S


def utc_day(t_ns: int) -> str:
    """UTC calendar day ``YYYY-MM-DD`` of a time [ns since the Unix epoch]."""
    return _dt.datetime.fromtimestamp(t_ns // NS_PER_S, tz=_dt.timezone.utc).strftime('%Y-%m-%d')


def bag_name(prefix: str, t_ns: int, per_day: bool = True) -> str:
    """Directory name of the bag that holds a message logged at ``t_ns``.

    ``<prefix>_YYYY-MM-DD`` with one bag per UTC day (the "recorded mcap days"),
    else ``<prefix>_YYYY-MM-DD-HH-MM-SS`` of the first message (rosbag2 style).
    """
    stamp = _dt.datetime.fromtimestamp(t_ns // NS_PER_S, tz=_dt.timezone.utc)
    return f'{prefix}_{stamp:%Y-%m-%d}' if per_day else f'{prefix}_{stamp:%Y-%m-%d-%H-%M-%S}'


@dataclass
class SplitPolicy:
    """When to start a new ``.mcap`` file inside a bag (rosbag2 ``--max-bag-size/-duration``).

    Parameters
    ----------
    max_bytes : int
        Split once the current file reaches this size [bytes]; 0 = no limit.
    max_duration_s : float
        Split once the current file spans this much log time [s]; 0 = no limit.
    """

    max_bytes: int = 0
    max_duration_s: float = 0.0

    def __post_init__(self):
        if self.max_bytes < 0 or self.max_duration_s < 0:
            raise ValueError('split limits must be >= 0 (0 = no limit)')

    def should_split(self, file_bytes: int, file_start_ns: int | None, t_ns: int) -> bool:
        """True when a message logged at ``t_ns`` must go to a new file."""
        if self.max_bytes and file_bytes >= self.max_bytes:
            return True
        if self.max_duration_s and file_start_ns is not None:
            return (t_ns - file_start_ns) >= self.max_duration_s * NS_PER_S
        return False


@dataclass
class DiskStatus:
    """Result of a free-disk check."""

    ok: bool
    free_bytes: int
    total_bytes: int
    message: str


@dataclass
class DiskGuard:
    """Stop recording before the disk is full.

    Recording must stop when free space falls below ``min_free_bytes`` or below
    ``min_free_fraction`` of the file system, whichever is larger; it may resume
    once free space is back above that threshold plus ``hysteresis_bytes``.

    Parameters
    ----------
    min_free_bytes : int
        Absolute free-space floor [bytes].
    min_free_fraction : float
        Relative floor [0..1] of the file system size.
    hysteresis_bytes : int
        Extra free space [bytes] required to resume after a stop.
    """

    min_free_bytes: int = 500 * 1024 * 1024
    min_free_fraction: float = 0.02
    hysteresis_bytes: int = 50 * 1024 * 1024
    stopped: bool = False

    def threshold(self, total_bytes: int) -> int:
        """The free-space floor [bytes] for a file system of ``total_bytes``."""
        return max(int(self.min_free_bytes), int(self.min_free_fraction * total_bytes))

    def evaluate(self, free_bytes: int, total_bytes: int) -> DiskStatus:
        """Update the stopped state from a free/total reading [bytes] and return it."""
        floor = self.threshold(total_bytes)
        need = floor + (self.hysteresis_bytes if self.stopped else 0)
        ok = free_bytes >= need
        self.stopped = not ok
        mib = 1024 * 1024
        if ok:
            msg = f'{free_bytes / mib:.0f} MiB free (floor {floor / mib:.0f} MiB)'
        else:
            msg = (f'recording stopped: only {free_bytes / mib:.0f} MiB free on the bag disk, '
                   f'below the floor of {floor / mib:.0f} MiB (min_free_bytes/min_free_fraction); '
                   'free space or move the bags, recording resumes by itself')
        return DiskStatus(ok, int(free_bytes), int(total_bytes), msg)

    def check(self, path: str | os.PathLike) -> DiskStatus:
        """Check the file system holding ``path`` (its nearest existing parent)."""
        probe = os.fspath(path)
        while probe and not os.path.exists(probe):
            parent = os.path.dirname(probe)
            if parent == probe:
                break
            probe = parent
        usage = shutil.disk_usage(probe or '.')
        return self.evaluate(usage.free, usage.total)
