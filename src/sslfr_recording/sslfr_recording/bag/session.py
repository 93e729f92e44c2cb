"""A recording session: one bag per UTC day, file splits, free-disk guard (no rclpy).

The recorder node feeds every received message to :meth:`RecordingSession.write`
and calls :meth:`RecordingSession.poll` from a steady timer. The session

- opens ``<root>/<prefix>_YYYY-MM-DD`` for the UTC day of the message's log time
  (ROS time, so simulated and replayed days land in their own day bags) and closes
  the previous day's bag when the day changes; a restarted recorder continues the
  same day bag with new files (after recovering a crashed one);
- lets the writer split files by size/duration and bound chunk age;
- checks the free disk space every ``disk_check_period_s``: below the guard's floor
  it closes the bag cleanly and drops (counts) messages until space is back.
  Only recording stops; nothing else is touched.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from sslfr_common.files import user_path
from typing import Callable

from sslfr_common.timeconv import NS_PER_S

from .metadata import BagError
from .policy import DiskGuard, DiskStatus, bag_name
from .schema import DefinitionCache
from .writer import BagWriter, WriterOptions

_DAY_NS = 86_400 * NS_PER_S             # one UTC day [ns] (Unix time has no leap seconds)


def probe_output_dir(root: str | Path) -> str:
    """Why bags cannot be written under ``root`` ('' when they can).

    Creates the directory if needed and writes and removes a probe file in it: the
    only test that tells, also as root, that ``/proc/x``, a read-only mount or an
    existing regular file cannot hold bags.
    """
    path = user_path(root)
    try:
        if path.exists() and not path.is_dir():
            return f'{path} exists and is not a directory'
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f'.sslfr-write-test-{os.getpid()}'
        with open(probe, 'wb') as fh:
            fh.write(b'x')
        probe.unlink()
    except OSError as exc:
        return f'cannot write bags in {path}: {exc.strerror or exc}'
    return ''


@dataclass
class _Decl:
    type_name: str
    qos: list[dict]
    type_hash: str | None


@dataclass
class SessionStats:
    """Counters exposed in the recorder's diagnostics."""

    written: int = 0
    dropped_disk: int = 0
    write_errors: int = 0
    bags_opened: int = 0
    last_error: str = ''
    per_topic: dict[str, int] = field(default_factory=dict)


class RecordingSession:
    """Route messages to per-day bags under ``root``.

    Parameters
    ----------
    root : path
        Directory where bag directories are created.
    prefix : str
        Bag directory name prefix.
    per_day : bool
        One bag per UTC day (else one bag per session, named by its first message).
    options : WriterOptions
    guard : DiskGuard
    disk_check_period_s : float
        Seconds between free-space checks (monotonic clock).
    """

    def __init__(self, root: str | Path, prefix: str = 'sslfr', per_day: bool = True,
                 options: WriterOptions | None = None, guard: DiskGuard | None = None,
                 disk_check_period_s: float = 5.0, definitions: DefinitionCache | None = None,
                 monotonic: Callable[[], float] = time.monotonic,
                 disk_check: Callable[[Path], DiskStatus] | None = None):
        self.root = user_path(root)
        self.prefix = prefix
        self.per_day = per_day
        self.options = options or WriterOptions()
        self.guard = guard or DiskGuard()
        self.disk_check_period_s = disk_check_period_s
        self.definitions = definitions or DefinitionCache()
        self._monotonic = monotonic
        self._disk_check = disk_check or self.guard.check
        self._decls: dict[str, _Decl] = {}
        self.writer: BagWriter | None = None
        self.bag_dir: Path | None = None
        self._day: tuple[int, int] | None = None     # [start, end) ns of the open per-day bag
        self._current_key: str | None = None
        self.stats = SessionStats()
        self.disk: DiskStatus | None = None
        self._next_disk_check = 0.0
        self.closed_bags: list[Path] = []

    # ------------------------------------------------------------------------------
    def add_topic(self, name: str, type_name: str, qos: list[dict] | None = None,
                  type_hash: str | None = None) -> None:
        """Declare a topic; it is added to the open bag and to every later bag.

        Raises
        ------
        DefinitionNotFoundError
            When the type's ``.msg`` cannot be found (checked at declaration).
        """
        if name in self._decls:
            return
        self.definitions.full_text(type_name)  # fail early on unknown types
        self._decls[name] = _Decl(type_name, list(qos or []), type_hash)
        self.stats.per_topic.setdefault(name, 0)
        if self.writer is not None:
            self.writer.add_topic(name, type_name, qos, type_hash=type_hash)

    @property
    def topics(self) -> list[str]:
        """Declared topic names."""
        return list(self._decls)

    @property
    def recording(self) -> bool:
        """False while the disk guard holds recording stopped."""
        return not self.guard.stopped

    def _open(self, log_ns: int) -> None:
        name = bag_name(self.prefix, log_ns, self.per_day)
        self.root.mkdir(parents=True, exist_ok=True)
        directory = self.root / name
        self.writer = BagWriter(directory, self.options, definitions=self.definitions,
                                resume=True)
        for topic, d in self._decls.items():
            self.writer.add_topic(topic, d.type_name, d.qos, type_hash=d.type_hash)
        self.bag_dir = directory
        self._current_key = name if self.per_day else None
        day = log_ns - log_ns % _DAY_NS                     # the UTC day of this bag [ns]
        self._day = (day, day + _DAY_NS) if self.per_day else None
        self.stats.bags_opened += 1

    def _close(self) -> None:
        if self.writer is not None:
            try:
                self.writer.close()
            except (OSError, BagError) as exc:
                self.stats.write_errors += 1
                self.stats.last_error = f'closing {self.bag_dir}: {exc}'
            if self.bag_dir is not None:
                self.closed_bags.append(self.bag_dir)
        self.writer = None
        self._current_key = None
        self._day = None

    def write(self, topic: str, data: bytes, log_ns: int, publish_ns: int | None = None,
              sequence: int = 0) -> bool:
        """Record one message; return False when it was dropped (disk guard or error)."""
        self._maybe_check_disk()  # also before the very first message is written
        if self.guard.stopped:
            self.stats.dropped_disk += 1
            return False
        try:
            day = self._day          # no date formatting per message: the day's bounds [ns]
            if self.writer is not None and day is not None and not day[0] <= log_ns < day[1]:
                self._close()  # UTC day changed: close yesterday's bag
            if self.writer is None:
                self._open(log_ns)
            self.writer.write(topic, data, log_ns, publish_ns, sequence)
        except (OSError, BagError) as exc:
            self.stats.write_errors += 1
            self.stats.last_error = str(exc)
            # A failed write may leave the file inconsistent: end it, the next write opens
            # a new file in the same bag (after recovery of this one).
            if self.writer is not None:
                self.writer.abort()
            self.writer = None
            return False
        self.stats.written += 1
        self.stats.per_topic[topic] = self.stats.per_topic.get(topic, 0) + 1
        return True

    def poll(self) -> DiskStatus | None:
        """Timer hook: bound chunk age, check disk space; returns the last disk status."""
        if self.writer is not None:
            try:
                self.writer.poll()
            except OSError as exc:
                self.stats.write_errors += 1
                self.stats.last_error = str(exc)
        self._maybe_check_disk()
        return self.disk

    def _maybe_check_disk(self) -> None:
        now = self._monotonic()
        if now >= self._next_disk_check:
            self._next_disk_check = now + self.disk_check_period_s
            was_stopped = self.guard.stopped
            try:
                self.disk = self._disk_check(self.root)
            except OSError as exc:
                self.stats.last_error = f'free-space check failed: {exc}'
                return
            if self.guard.stopped and not was_stopped:
                self._close()  # leave a complete, readable bag behind

    def close(self) -> None:
        """Close the open bag (metadata.yaml written)."""
        self._close()
