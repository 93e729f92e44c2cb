"""Read rosbag2-layout MCAP bags (directory with metadata.yaml, or one ``.mcap`` file).

Messages come out in log-time order as :class:`RawMessage` (serialized CDR bytes
untouched); :meth:`BagReader.decoded` also decodes them through the bag's own
``ros2msg`` schemas with mcap-ros2-support, so no ROS installation is needed.
A bag whose files lack a summary (a crashed recording) or fail a CRC check raises
:class:`~sslfr_recording.bag.metadata.BagError` with a hint to run ``sslfr bag recover``.
"""
from __future__ import annotations

import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator

from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from sslfr_common.timeconv import NS_PER_S, to_sec

from .metadata import (METADATA_FILENAME, BagError, BagMetadata, FileInfo, MetadataError, TopicInfo,
                       read_metadata)
from .scan import decompress, mcap_files, topic_from_channel


def _chunk_payload(record: bytes, validate_crc: bool) -> bytes:
    """Uncompressed records of a Chunk record (opcode + length + body), CRC-checked."""
    if len(record) < 9 or record[0] != 0x06:
        raise ValueError('chunk index points at something that is not a chunk')
    start, end, usize, crc, clen = struct.unpack_from('<QQQII', record, 9)
    off = 9 + 32
    compression = record[off:off + clen].decode()
    off += clen
    (rlen,) = struct.unpack_from('<Q', record, off)
    off += 8
    payload = record[off:off + rlen]
    if len(payload) != rlen:
        raise EOFError('chunk cut short')
    payload = decompress(compression, payload, usize)
    if validate_crc and crc and zlib.crc32(payload) != crc:
        raise ValueError(f'chunk CRC mismatch (expected {crc:#010x})')
    return payload


@dataclass(frozen=True)
class RawMessage:
    """One recorded message; times [ns since the Unix epoch]."""

    topic: str
    type: str
    data: bytes
    log_time: int
    publish_time: int
    sequence: int


class BagReader:
    """Open a bag for reading.

    Parameters
    ----------
    path : path
        A bag directory (rosbag2 layout) or a single ``.mcap`` file.
    validate_crcs : bool
        Check every chunk's CRC-32 while reading.
    """

    def __init__(self, path: str | os.PathLike, validate_crcs: bool = True):
        self.path = Path(path)
        self.validate_crcs = validate_crcs
        if self.path.is_dir():
            self.directory = self.path
            if (self.path / METADATA_FILENAME).exists():
                try:
                    self.meta = read_metadata(self.path)
                except MetadataError as exc:
                    raise BagError(f'{exc}; `sslfr bag recover {self.path}` rebuilds it from the '
                                   '.mcap files') from None
                self.files = [self.path / p for p in self.meta.file_paths()]
            else:
                self.meta = None
                self.files = mcap_files(self.path)
                if not self.files:
                    raise BagError(f'{self.path}: no metadata.yaml and no .mcap file: not a bag')
        elif self.path.is_file():
            self.directory = self.path.parent
            self.meta = None
            self.files = [self.path]
        else:
            raise BagError(f'{self.path}: no such bag')
        self.topics: dict[str, TopicInfo] = {}
        self.schemas: dict[str, str] = {}
        self._summaries = []
        self._decoders: dict[str, object] = {}
        file_infos = []
        for f in self.files:
            summary = self._summary(f)
            self._summaries.append(summary)
            st = summary.statistics
            file_infos.append(FileInfo(f.name, st.message_start_time if st.message_count else 0,
                                       st.message_end_time - st.message_start_time
                                       if st.message_count else 0, st.message_count))
            for cid, ch in summary.channels.items():
                schema = summary.schemas.get(ch.schema_id)
                info = self.topics.get(ch.topic)
                if info is None:
                    info = self.topics[ch.topic] = topic_from_channel(ch, schema)
                info.message_count += st.channel_message_counts.get(cid, 0)
                if schema is not None:
                    self.schemas.setdefault(schema.name, schema.data.decode('utf-8', 'replace'))
        if self.meta is None:
            self.meta = BagMetadata(topics=self.topics, files=file_infos)

    def _summary(self, path: Path):
        hint = f'; try `sslfr bag recover {self.directory}`'
        try:
            with open(path, 'rb') as fh:
                summary = SeekingReader(fh).get_summary()
        except FileNotFoundError as exc:
            raise BagError(f'{path}: listed in metadata.yaml but missing') from exc
        except (McapError, OSError, struct.error, ValueError, KeyError, IndexError) as exc:
            raise BagError(f'{path}: not a complete MCAP file ({exc or type(exc).__name__})'
                           + hint) from exc
        if summary is None or summary.statistics is None:
            raise BagError(f'{path}: MCAP file has no summary (recording was cut)' + hint)
        return summary

    # -- properties ---------------------------------------------------------------------
    @property
    def message_count(self) -> int:
        """Total messages [-]."""
        return sum(s.statistics.message_count for s in self._summaries)

    @property
    def start_ns(self) -> int:
        """First log time [ns]."""
        starts = [s.statistics.message_start_time for s in self._summaries if s.statistics.message_count]
        return min(starts) if starts else 0

    @property
    def end_ns(self) -> int:
        """Last log time [ns]."""
        ends = [s.statistics.message_end_time for s in self._summaries if s.statistics.message_count]
        return max(ends) if ends else 0

    # -- iteration ----------------------------------------------------------------------
    def messages(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[RawMessage]:
        """Messages in log-time order, optionally filtered by topic and [start, end) [ns].

        Raises
        ------
        BagError
            On a damaged chunk (CRC mismatch, bad compression, cut file).
        """
        wanted = None if topics is None else set(topics)
        for path, summary in zip(self.files, self._summaries):
            st = summary.statistics
            if not st.message_count:
                continue
            if start_ns is not None and st.message_end_time < start_ns:
                continue
            if end_ns is not None and st.message_start_time >= end_ns:
                continue
            names = {ch.topic for ch in summary.channels.values()}
            sel = None if wanted is None else sorted(names & wanted)
            if sel is not None and not sel:
                continue
            chunks = sorted(summary.chunk_indexes,
                            key=lambda c: (c.message_start_time, c.chunk_start_offset))
            if chunks and all(b.message_start_time >= a.message_end_time
                              for a, b in zip(chunks, chunks[1:])):
                # Chunks in time order without overlap (what our writer produces): read
                # them one after the other, no merge heap needed.
                yield from self._linear(path, summary, chunks, sel, start_ns, end_ns)
                continue
            try:
                with open(path, 'rb') as fh:
                    reader = SeekingReader(fh, validate_crcs=self.validate_crcs)
                    reader._summary = summary  # already read and checked above
                    for schema, channel, msg in reader.iter_messages(
                            topics=sel, start_time=start_ns, end_time=end_ns, log_time_order=True):
                        yield RawMessage(channel.topic, schema.name if schema else '', msg.data,
                                         msg.log_time, msg.publish_time, msg.sequence)
            except (McapError, struct.error, zlib.error, ValueError, EOFError, OSError) as exc:
                raise BagError(f'{path}: damaged data ({exc or type(exc).__name__}); '
                               f'try `sslfr bag recover {self.directory}`') from exc

    def _linear(self, path, summary, chunks, sel, start_ns, end_ns) -> Iterator[RawMessage]:
        channels = {cid: (ch.topic, summary.schemas[ch.schema_id].name if ch.schema_id in
                          summary.schemas else '')
                    for cid, ch in summary.channels.items() if sel is None or ch.topic in sel}
        lo = -1 if start_ns is None else start_ns
        hi = (1 << 64) if end_ns is None else end_ns
        unpack_rec = struct.Struct('<BQ').unpack_from
        unpack_msg = struct.Struct('<HIQQ').unpack_from
        try:
            with open(path, 'rb') as fh:
                for ci in chunks:
                    if ci.message_end_time < lo or ci.message_start_time >= hi:
                        continue
                    fh.seek(ci.chunk_start_offset)
                    raw = fh.read(ci.chunk_length)
                    data = _chunk_payload(raw, self.validate_crcs)
                    out = []
                    pos, n = 0, len(data)
                    while pos < n:
                        op, length = unpack_rec(data, pos)
                        body = pos + 9
                        pos = body + length
                        if op != 0x05:  # only Message records matter here
                            continue
                        cid, seq, log, pub = unpack_msg(data, body)
                        ch = channels.get(cid)
                        if ch is None or log < lo or log >= hi:
                            continue
                        out.append((log, len(out), ch, data[body + 22:pos], pub, seq))
                    out.sort()
                    for log, _, (topic, typ), payload, pub, seq in out:
                        yield RawMessage(topic, typ, payload, log, pub, seq)
        except (struct.error, zlib.error, ValueError, EOFError, OSError, McapError) as exc:
            raise BagError(f'{path}: damaged data ({exc or type(exc).__name__}); '
                           f'try `sslfr bag recover {self.directory}`') from exc

    def decoder(self, type_name: str):
        """A function bytes -> decoded message object for a recorded type (from its schema)."""
        dec = self._decoders.get(type_name)
        if dec is None:
            text = self.schemas.get(type_name)
            if text is None:
                raise BagError(f'no schema for {type_name} in the bag')
            dec = DecoderFactory().decoder_for('cdr', Schema(id=1, name=type_name, encoding='ros2msg', data=text.encode()))
            self._decoders[type_name] = dec
        return dec

    def decoded(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                end_ns: int | None = None) -> Iterator[tuple[RawMessage, object]]:
        """(raw, decoded) pairs in log-time order."""
        for raw in self.messages(topics, start_ns, end_ns):
            try:
                obj = self.decoder(raw.type)(raw.data)
            except BagError:
                raise
            except Exception as exc:  # noqa: BLE001 - decoder errors vary
                raise BagError(f'cannot decode a {raw.type} message on {raw.topic} at '
                               f'{raw.log_time} ns: {exc}') from exc
            yield raw, obj

    def info_text(self) -> str:
        """What ``ros2 bag info`` prints (rosbag2_py ``format_bag_metadata.cpp``), plus QoS.

        Like rosbag2, a bag directory is described from its metadata.yaml, a single
        file from its summary; dates are local time. The offered QoS of each topic
        follows rosbag2's block.
        """
        m = self.meta
        if m.read_totals is not None:
            count, start, duration = m.read_totals
        else:
            count, start, duration = m.message_count, m.starting_time_ns, m.duration_ns
        topics = list(m.topics.values())
        if self.path.is_dir():
            size = sum(p.stat().st_size for p in self.path.rglob('*') if p.is_file())
        else:
            size = self.path.stat().st_size
        pad = ' ' * 19
        paths = m.file_paths() if self.path.is_dir() else [self.path.name]
        lines = ['', 'Files:             ' + (f'\n{pad}'.join(paths)),
                 f'Bag size:          {format_size(size)}',
                 f'Storage id:        {m.storage_identifier}',
                 f'ROS Distro:        {m.ros_distro or "unknown"}',
                 f'Duration:          {seconds_text(duration)}s',
                 f'Start:             {time_point_text(start)}',
                 f'End:               {time_point_text(start + duration)}',
                 f'Messages:          {count}']
        first = 'Topic information: '
        for i, t in enumerate(topics):
            lines.append((first if i == 0 else pad) + f'Topic: {t.name} | Type: {t.type} | '
                         f'Count: {t.message_count} | Serialization Format: {t.serialization_format}')
        if not topics:
            lines.append(first)
        lines += ['Service:           0', 'Service information: ']
        for i, t in enumerate(topics):
            lines.append(('Offered QoS:       ' if i == 0 else pad) + f'{t.name}: {qos_text(t)}')
        return '\n'.join(lines)


def message_time(header, log_time_ns: int) -> float:
    """When a recorded message happened [s since the epoch]: its ``header.stamp``, or
    its log time when the stamp is zero (never set by the publisher)."""
    t = to_sec(header.stamp)
    return t if t != 0 else to_sec(log_time_ns)


def seconds_text(ns: int) -> str:
    """``S.NNNNNNNNN`` of a time or duration [ns] (rosbag2's time_in_sec)."""
    return f'{ns // NS_PER_S}.{ns % NS_PER_S:09d}'


def time_point_text(ns: int) -> str:
    """``Jun 21 2026 12:00:00.000000000 (1782043200.000000000)`` in local time, as rosbag2."""
    import time as _time
    t = _time.localtime(ns // NS_PER_S)
    return (_time.strftime('%b %e %Y %H:%M:%S', t) + f'.{ns % NS_PER_S:09d} '
            f'({seconds_text(ns)})')


def format_size(size: int) -> str:
    """rosbag2's ``format_file_size``: B, KiB, MiB ... with one decimal above bytes."""
    units = ['B', 'KiB', 'MiB', 'GiB', 'TiB']
    value, i = float(size), 0
    while value >= 1024 and i < 4:
        value /= 1024
        i += 1
    return f'{value:.0f} B' if i == 0 else f'{value:.1f} {units[i]}'


def qos_text(t: TopicInfo) -> str:
    """One line per topic: the offered profiles, e.g. ``reliable transient_local keep_last 1``."""
    if not t.offered_qos_profiles:
        return 'none recorded'
    parts = []
    for q in t.offered_qos_profiles:
        depth = f' {q["depth"]}' if q['history'] == 'keep_last' else ''
        parts.append(f'{q["reliability"]} {q["durability"]} {q["history"]}{depth}')
    uniq = sorted(set(parts))
    return '; '.join(uniq) + f' ({len(t.offered_qos_profiles)} publisher(s))'
