"""One open ``.mcap`` file of a rosbag2-layout bag (ros2 profile, chunked, CRCs on):
what :class:`.writer.BagWriter` writes into and :func:`.recover.recover_bag` rebuilds
with (pure Python, no rclpy)."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from mcap.writer import CompressionType, Writer

from .metadata import BagMetadata, FileInfo, TopicInfo
from .qos import dump_profiles

LIBRARY = 'sslfr_bringup bag writer (mcap-python)'
COMPRESSION = {'none': CompressionType.NONE, '': CompressionType.NONE,
                'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4}


@dataclass
class TopicEntry:
    info: TopicInfo
    schema_text: str


class McapFile:
    """One open ``.mcap`` file of a bag (ros2 profile, chunked, CRCs on)."""

    def __init__(self, path: Path, *, chunk_size: int, compression: str, fsync: bool,
                 monotonic: Callable[[], float], library: str = LIBRARY):
        self.path = path
        self._fh = open(path, 'xb')  # noqa: SIM115 - closed in finish()/abort()
        self._writer = Writer(self._fh, chunk_size=chunk_size,
                              compression=COMPRESSION[compression], enable_crcs=True)
        self._writer.start(profile='ros2', library=library)
        self._fsync = fsync
        self._monotonic = monotonic
        self._schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        self.info = FileInfo(path=path.name)
        self._end_ns: int | None = None
        self._pending_since: float | None = None

    def add_topic(self, topic: TopicEntry) -> None:
        """Register the schema (once per type) and the channel of a topic.

        Both records go to the data section outside any chunk (the open chunk, if it
        holds messages, is closed first): a damaged chunk then never takes the
        definitions of later chunks' messages with it, so recovery keeps every intact
        chunk. rosbag2 writes the same metadata keys (``mcap_storage.cpp``
        ``create_topic``: ``offered_qos_profiles`` as the YAML of the QoS sequence,
        ``[]`` when empty, and ``topic_type_hash``).
        """
        if topic.info.name in self.channels:
            return
        if self._pending_since is not None:
            self.flush()
        typ = topic.info.type
        if typ not in self._schemas:
            self._schemas[typ] = self._unchunked(
                self._writer.register_schema, name=typ, encoding='ros2msg',
                data=topic.schema_text.encode('utf-8'))
        self.channels[topic.info.name] = self._unchunked(
            self._writer.register_channel, topic=topic.info.name,
            message_encoding=topic.info.serialization_format, schema_id=self._schemas[typ],
            metadata={'offered_qos_profiles': dump_profiles(topic.info.offered_qos_profiles),
                      'topic_type_hash': topic.info.type_description_hash})

    def _unchunked(self, register, **kwargs) -> int:
        """Call a mcap Writer ``register_*`` with chunking off for that one record.

        mcap-python (pinned in requirements.txt) keeps its chunk builder in the
        name-mangled ``_Writer__chunk_builder``; without it the record simply goes into
        the next chunk, which is still valid MCAP.
        """
        attr = '_Writer__chunk_builder'
        builder = getattr(self._writer, attr, None)
        if builder is None or builder.num_messages:
            return register(**kwargs)
        setattr(self._writer, attr, None)
        try:
            return register(**kwargs)
        finally:
            setattr(self._writer, attr, builder)

    def add_metadata_record(self, meta: BagMetadata) -> None:
        """Write the ``rosbag2`` metadata record (``mcap_storage.cpp`` ``update_metadata``)."""
        self._writer.add_metadata('rosbag2', {'serialized_metadata': meta.serialized_for_mcap()})

    def write(self, channel_id: int, data: bytes, log_ns: int, publish_ns: int, sequence: int):
        """Append one message (goes into the open chunk)."""
        if self._pending_since is None:
            self._pending_since = self._monotonic()
        self._writer.add_message(channel_id=channel_id, log_time=log_ns, data=data,
                                 publish_time=publish_ns, sequence=sequence & 0xFFFFFFFF)
        info = self.info
        if info.message_count == 0:
            info.starting_time_ns = log_ns
            self._end_ns = log_ns
        else:
            if log_ns < info.starting_time_ns:
                info.starting_time_ns = log_ns
            if log_ns > self._end_ns:
                self._end_ns = log_ns
        info.message_count += 1
        info.duration_ns = self._end_ns - info.starting_time_ns

    def chunk_age(self) -> float:
        """Seconds since the oldest message not yet written out (0 when none)."""
        return 0.0 if self._pending_since is None else self._monotonic() - self._pending_since

    def flush(self) -> None:
        """Close the open chunk, write it and flush to the OS (fsync if enabled)."""
        self._writer.flush()
        if self._fsync:
            os.fsync(self._fh.fileno())
        self._pending_since = None

    def size(self) -> int:
        """Bytes written to the file so far (excluding the open chunk)."""
        return self._fh.tell()

    def finish(self, meta: BagMetadata | None) -> None:
        """Write the ``rosbag2`` metadata record, summary, footer; close the file."""
        if meta is not None:
            self.add_metadata_record(meta)
        self._writer.finish()
        self._fh.flush()
        if self._fsync:
            os.fsync(self._fh.fileno())
        self._fh.close()

    def abort(self) -> None:
        """Close without summary (as a crash would leave it)."""
        try:
            self._fh.close()
        except OSError:
            pass
