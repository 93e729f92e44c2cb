"""Read rosbag2-layout MCAP bags (directory with metadata.yaml, or one ``.mcap`` file).

Messages come out in log-time order as :class:`RawMessage` (serialized CDR bytes
untouched); :meth:`BagReader.decoded` also decodes them through the bag's own
``ros2msg`` schemas with mcap-ros2-support, so no ROS installation is needed.
A bag whose files lack a summary (a crashed recording) or fail a CRC check raises
:class:`~sslfr_bringup.bag.metadata.BagError` with a hint to run ``sslfr bag recover``.
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

from .metadata import METADATA_FILENAME, BagError, BagMetadata, FileInfo, TopicInfo, read_metadata
from .qos import load_profiles
from .recover import mcap_files


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
    if compression == 'zstd':
        import zstandard
        payload = zstandard.ZstdDecompressor().decompress(payload, max_output_size=usize)
    elif compression == 'lz4':
        import lz4.frame
        payload = lz4.frame.decompress(payload)
    elif compression:
        raise ValueError(f'unsupported chunk compression {compression!r}')
    if len(payload) != usize:
        raise ValueError('chunk size mismatch')
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
                self.meta = read_metadata(self.path)
                self.files = [self.path / f.path for f in self.meta.files]
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
                    try:
                        qos = load_profiles(ch.metadata.get('offered_qos_profiles', ''))
                    except ValueError:
                        qos = []
                    info = self.topics[ch.topic] = TopicInfo(
                        ch.topic, schema.name if schema else '', ch.message_encoding, qos,
                        ch.metadata.get('topic_type_hash', ''))
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
        """``ros2 bag info``-like summary."""
        import datetime as dt
        start, end = self.start_ns, self.end_ns
        fmt = (lambda t: dt.datetime.fromtimestamp(t / 1e9, tz=dt.timezone.utc)
               .strftime('%Y-%m-%d %H:%M:%S.%f UTC'))
        size = sum(p.stat().st_size for p in self.files)
        lines = [f'Files:             {", ".join(p.name for p in self.files)}',
                 f'Bag size:          {size / 1024 / 1024:.2f} MiB',
                 'Storage id:        mcap',
                 f'Duration:          {(end - start) / 1e9:.3f} s',
                 f'Start:             {fmt(start) if self.message_count else "-"} ({start / 1e9:.9f})',
                 f'End:               {fmt(end) if self.message_count else "-"} ({end / 1e9:.9f})',
                 f'Messages:          {self.message_count}',
                 'Topic information:']
        width = max((len(t) for t in self.topics), default=0)
        for name in sorted(self.topics):
            t = self.topics[name]
            q = t.offered_qos_profiles[0] if t.offered_qos_profiles else None
            qtxt = f'{q["reliability"]}/{q["durability"]}/depth {q["depth"]}' if q else 'no QoS'
            lines.append(f'  {name:<{width}}  {t.type:<36} {t.message_count:>9} msgs  '
                         f'{t.serialization_format}  {qtxt}')
        return '\n'.join(lines)
