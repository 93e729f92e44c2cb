"""Crash-safe rosbag2-layout MCAP bag writer (pure Python, no rclpy).

A bag is a directory ``<name>/`` holding ``<name>_0.mcap``, ``<name>_1.mcap`` ...
and ``metadata.yaml`` (written when a file is closed and at the end). Each file has
profile ``ros2``, one ``ros2msg`` schema per type (full text with dependencies, see
:mod:`.schema`), one ``cdr`` channel per topic with the ``offered_qos_profiles`` and
``topic_type_hash`` metadata keys rosbag2 writes, and a ``rosbag2`` metadata record.

Crash safety: messages are grouped in chunks with CRC-32 of their uncompressed data.
A chunk is closed, written and (optionally) fsync'ed when it reaches ``chunk_size``
bytes or when its first message is ``chunk_duration_s`` old on the monotonic clock,
checked on every write and by :meth:`BagWriter.poll` (call it from a timer). A
SIGKILL or power cut therefore loses at most ``chunk_duration_s`` plus the poll
period; :func:`sslfr_recording.bag.recover.recover_bag` rebuilds the rest.
"""
from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from .mcapfile import COMPRESSION, McapFile, TopicEntry
from .metadata import BagError, BagMetadata, TopicInfo, write_metadata
from .recover import recover_bag
from .policy import SplitPolicy
from .schema import DefinitionCache, DefinitionNotFoundError, normalize_type
from .typehash import schema_type_hash

@dataclass
class WriterOptions:
    """Tuning of :class:`BagWriter`.

    Parameters
    ----------
    chunk_size : int
        Close a chunk at this uncompressed size [bytes].
    chunk_duration_s : float
        Close a chunk once its oldest message is this old [s, monotonic clock].
    compression : {'zstd', 'lz4', 'none'}
        MCAP chunk compression.
    fsync : bool
        fsync after every chunk (power-cut safety; costs one disk sync per chunk).
    split : SplitPolicy
        When to start a new file inside the bag.
    """

    chunk_size: int = 1024 * 1024
    chunk_duration_s: float = 2.0
    compression: str = 'zstd'
    fsync: bool = True
    split: SplitPolicy = field(default_factory=SplitPolicy)

    def __post_init__(self):
        if self.compression not in COMPRESSION:
            raise ValueError(f'compression must be one of zstd, lz4, none (got {self.compression!r})')
        if self.chunk_size <= 0 or self.chunk_duration_s <= 0:
            raise ValueError('chunk_size and chunk_duration_s must be > 0')


class BagWriter:
    """Write a rosbag2-layout MCAP bag directory.

    Parameters
    ----------
    directory : path
        The bag directory; created if missing. When it already holds a bag and
        ``resume`` is true, that bag is recovered if needed and continued with new
        files (one bag per day survives recorder restarts); otherwise it must not exist.
    options : WriterOptions
    definitions : DefinitionCache, optional
        Where ``.msg`` texts come from (default: the ament index).
    resume : bool
    monotonic : callable
        Monotonic clock [s] for the chunk-duration bound (injectable for tests).
    """

    def __init__(self, directory: str | os.PathLike, options: WriterOptions | None = None, *,
                 definitions: DefinitionCache | None = None, resume: bool = False,
                 monotonic: Callable[[], float] = time.monotonic,
                 custom_data: dict[str, str] | None = None):
        self.directory = Path(directory)
        self.options = options or WriterOptions()
        self.definitions = definitions or DefinitionCache()
        self._monotonic = monotonic
        self._lock = threading.RLock()
        self._topics: dict[str, TopicEntry] = {}
        self.meta = BagMetadata(custom_data=dict(custom_data or {}))
        self._file: McapFile | None = None
        self._next_index = 0
        self.closed = False
        if self.directory.exists() and any(self.directory.iterdir()):
            if not resume:
                raise BagError(f'{self.directory} already exists and is not empty')
            self._resume()
        self.directory.mkdir(parents=True, exist_ok=True)

    # -- set-up -----------------------------------------------------------------------
    def _resume(self) -> None:
        report = recover_bag(self.directory, verify=False)  # trust closed files: fast restarts
        self.meta = report.metadata
        for name, info in self.meta.topics.items():
            schema_text = report.schemas.get(info.type) or self._schema_text(info.type)
            self._topics[name] = TopicEntry(info, schema_text)
        self._next_index = len(self.meta.files)

    def _schema_text(self, type_name: str) -> str:
        return self.definitions.full_text(type_name)

    def _type_hash(self, type_name: str, schema_text: str) -> str:
        """RIHS01 hash: generated .json, else computed from the .msg files, else from the schema."""
        try:
            return self.definitions.type_hash(type_name)
        except DefinitionNotFoundError:
            pass
        try:
            return schema_type_hash(schema_text, type_name)
        except (KeyError, ValueError):
            return ''

    def add_topic(self, name: str, type_name: str, qos_profiles: list[dict] | None = None, *,
                  type_hash: str | None = None, schema_text: str | None = None,
                  serialization_format: str = 'cdr') -> None:
        """Declare a topic (idempotent). The schema comes from the ament index unless given.

        Raises
        ------
        DefinitionNotFoundError
            When no ``.msg`` definition exists for the type (and none is given).
        """
        type_name = normalize_type(type_name)
        with self._lock:
            if name in self._topics:
                return
            text = schema_text if schema_text is not None else self._schema_text(type_name)
            info = TopicInfo(name=name, type=type_name, serialization_format=serialization_format,
                             offered_qos_profiles=list(qos_profiles or []),
                             type_description_hash=type_hash or self._type_hash(type_name, text))
            topic = TopicEntry(info, text)
            self._topics[name] = topic
            self.meta.topics[name] = info
            if self._file is not None:
                self._file.add_topic(topic)

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Declared topics with their message counts."""
        return {k: v.info for k, v in self._topics.items()}

    # -- writing ----------------------------------------------------------------------
    def _open_file(self) -> McapFile:
        path = self.directory / f'{self.directory.name}_{self._next_index}.mcap'
        self._next_index += 1
        f = McapFile(path, chunk_size=self.options.chunk_size, compression=self.options.compression,
                     fsync=self.options.fsync, monotonic=self._monotonic)
        for topic in self._topics.values():
            f.add_topic(topic)
        self.meta.files.append(f.info)
        f.add_metadata_record(self.meta)  # as rosbag2 does at open (sequential_writer.cpp 168)
        return f

    def _close_file(self) -> None:
        if self._file is None:
            return
        f, self._file = self._file, None
        f.finish(self.meta)
        write_metadata(self.directory, self.meta, fsync=self.options.fsync)

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None,
              sequence: int = 0) -> None:
        """Record one serialized (CDR) message of a declared topic.

        Parameters
        ----------
        topic : str
        data : bytes
            The serialized message, stored as is.
        log_time_ns : int
            Receive time [ns since the Unix epoch] (rosbag2 ``recv_timestamp``).
        publish_time_ns : int, optional
            Publisher's send time [ns] (defaults to ``log_time_ns``).
        sequence : int
            Publisher sequence number (stored modulo 2**32).
        """
        with self._lock:
            if self.closed:
                raise BagError('bag writer is closed')
            entry = self._topics.get(topic)
            if entry is None:
                raise KeyError(f'topic {topic!r} was not declared with add_topic()')
            f, split = self._file, self.options.split
            # the file's size (a seek of the OS file) only when a size limit asks for it
            if f is not None and f.info.message_count and split.should_split(
                    f.size() if split.max_bytes else 0, f.info.starting_time_ns, log_time_ns):
                self._close_file()
                f = None
            if f is None:
                f = self._file = self._open_file()
            f.write(f.channels[topic], data, int(log_time_ns),
                    int(log_time_ns if publish_time_ns is None else publish_time_ns), sequence)
            entry.info.message_count += 1
            if f.chunk_age() >= self.options.chunk_duration_s:
                f.flush()

    def poll(self) -> None:
        """Write out the open chunk if it is older than ``chunk_duration_s`` (timer hook)."""
        with self._lock:
            f = self._file
            if f is not None and f.chunk_age() >= self.options.chunk_duration_s:
                f.flush()

    def flush(self) -> None:
        """Write out the open chunk now."""
        with self._lock:
            if self._file is not None:
                self._file.flush()

    def split(self) -> None:
        """Close the current file now; the next message opens a new one."""
        with self._lock:
            self._close_file()

    def close(self) -> BagMetadata:
        """Finish the open file and write ``metadata.yaml``; return the metadata."""
        with self._lock:
            if not self.closed:
                self._close_file()
                write_metadata(self.directory, self.meta, fsync=self.options.fsync)
                self.closed = True
            return self.meta

    def abort(self) -> None:
        """Stop without finishing the file (simulates a crash; for tests)."""
        with self._lock:
            if self._file is not None:
                self._file.abort()
                self._file = None
            self.closed = True

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
