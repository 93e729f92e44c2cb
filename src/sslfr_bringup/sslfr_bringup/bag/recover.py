"""Rebuild a readable bag from what survived a crash (``sslfr bag recover DIR``).

A file cut by a SIGKILL or a power failure has a valid header and a run of complete
chunks, then (maybe) a partial chunk and no summary or footer. Recovery scans each
``.mcap`` file record by record: every complete chunk whose CRC-32 matches is kept,
a damaged chunk is skipped (the scan continues after it, since its length is
known), and the scan stops where the file is cut. Damaged files are rewritten
(temp file + atomic rename) with their schemas, channels and messages unchanged
(same bytes, log/publish times, sequence numbers), then ``metadata.yaml`` is
rebuilt from all files. Complete files are checked through their summary, and with
``verify=True`` every chunk's CRC is checked too.
"""
from __future__ import annotations

import io
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Header, Message, Schema
from mcap.stream_reader import breakup_chunk
from mcap.writer import CompressionType, Writer

from .metadata import BagError, BagMetadata, FileInfo, TopicInfo, read_metadata, write_metadata, \
    METADATA_FILENAME
from .qos import load_profiles

MAGIC = b'\x89MCAP0\r\n'
_MAX_RECORD = 1 << 31


@dataclass
class FileReport:
    """What recovery found in one file."""

    path: str
    status: str  # 'ok' | 'rebuilt' | 'unreadable'
    messages: int = 0
    chunks_kept: int = 0
    chunks_bad: int = 0
    truncated_bytes: int = 0
    detail: str = ''


@dataclass
class RecoveryReport:
    """Result of :func:`recover_bag`."""

    metadata: BagMetadata
    files: list[FileReport] = field(default_factory=list)
    schemas: dict[str, str] = field(default_factory=dict)

    def text(self) -> str:
        """Human-readable summary."""
        lines = []
        for f in self.files:
            extra = []
            if f.chunks_bad:
                extra.append(f'{f.chunks_bad} damaged chunk(s) dropped')
            if f.truncated_bytes:
                extra.append(f'{f.truncated_bytes} trailing byte(s) of an unfinished chunk dropped')
            if f.detail:
                extra.append(f.detail)
            lines.append(f'{f.path}: {f.status}, {f.messages} messages'
                         + (f' ({"; ".join(extra)})' if extra else ''))
        m = self.metadata
        lines.append(f'bag: {m.message_count} messages in {len(m.files)} file(s), '
                     f'{m.duration_ns / 1e9:.1f} s, metadata.yaml rewritten')
        return '\n'.join(lines)


@dataclass
class _Salvage:
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    chunks_kept: int = 0
    chunks_bad: int = 0
    truncated_bytes: int = 0
    complete: bool = False
    library: str = ''


def _salvage(data: bytes) -> _Salvage:
    """Scan an MCAP byte string record by record, keeping every intact record."""
    out = _Salvage()
    if not data.startswith(MAGIC):
        raise BagError('not an MCAP file (bad magic)')
    pos = len(MAGIC)
    n = len(data)
    while pos < n:
        if pos + 9 > n:
            out.truncated_bytes = n - pos
            break
        opcode = data[pos]
        (length,) = struct.unpack_from('<Q', data, pos + 1)
        body_start = pos + 9
        if length > _MAX_RECORD or body_start + length > n:
            out.truncated_bytes = n - pos
            break
        body = data[body_start:body_start + length]
        pos = body_start + length
        try:
            stream = ReadDataStream(io.BytesIO(body))
            if opcode == Opcode.CHUNK:
                chunk = Chunk.read(stream)
                records = breakup_chunk(chunk, validate_crc=True)
                out.chunks_kept += 1
            elif opcode == Opcode.SCHEMA:
                records = [Schema.read(stream)]
            elif opcode == Opcode.CHANNEL:
                records = [Channel.read(stream)]
            elif opcode == Opcode.MESSAGE:
                records = [Message.read(stream, length)]
            elif opcode == Opcode.HEADER:
                out.library = Header.read(stream).library
                continue
            elif opcode == Opcode.DATA_END:
                out.complete = True
                break
            else:
                continue
        except Exception:  # noqa: BLE001 - any decoding failure means a damaged record
            if opcode == Opcode.CHUNK:
                out.chunks_bad += 1
            continue
        for rec in records:
            if isinstance(rec, Schema):
                out.schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                out.channels[rec.id] = rec
            elif isinstance(rec, Message):
                out.messages.append(rec)
    return out


def _summary_ok(path: Path):
    """Summary of a complete file, or None when the file has none / is cut."""
    try:
        with open(path, 'rb') as fh:
            reader = SeekingReader(fh)
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                return None
            return summary
    except (McapError, OSError, struct.error, ValueError, KeyError):
        return None


def _rewrite(path: Path, salvage: _Salvage, compression: str = 'zstd') -> None:
    tmp = path.with_suffix('.mcap.recovering')
    with open(tmp, 'wb') as fh:
        w = Writer(fh, compression={'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
                                    'none': CompressionType.NONE}[compression], enable_crcs=True)
        w.start(profile='ros2', library=(salvage.library or 'sslfr_bringup') + ' (recovered)')
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        for sid, s in salvage.schemas.items():
            schema_ids[sid] = w.register_schema(s.name, s.encoding, s.data)
        for cid, c in salvage.channels.items():
            if c.schema_id and c.schema_id not in schema_ids:
                continue
            channel_ids[cid] = w.register_channel(c.topic, c.message_encoding,
                                                  schema_ids.get(c.schema_id, 0), dict(c.metadata))
        for m in sorted(salvage.messages, key=lambda m: m.log_time):
            if m.channel_id in channel_ids:
                w.add_message(channel_ids[m.channel_id], m.log_time, m.data, m.publish_time,
                              m.sequence)
        w.finish()
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _file_index(path: Path) -> tuple[int, str]:
    stem = path.stem
    tail = stem.rsplit('_', 1)[-1]
    return (int(tail) if tail.isdigit() else 1 << 30, path.name)


def mcap_files(directory: Path) -> list[Path]:
    """The ``.mcap`` files of a bag directory in split order (``name_0``, ``name_1`` ...)."""
    return sorted((p for p in directory.glob('*.mcap') if p.is_file()), key=_file_index)


def recover_bag(directory: str | os.PathLike, *, verify: bool = False,
                write: bool = True) -> RecoveryReport:
    """Make every file of a bag readable and rebuild ``metadata.yaml``.

    Parameters
    ----------
    directory : path
        The bag directory.
    verify : bool
        Also check the CRC of every chunk of files that look complete.
    write : bool
        Rewrite damaged files and metadata.yaml (False: report only).

    Raises
    ------
    BagError
        When the directory holds no ``.mcap`` file at all.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise BagError(f'{directory} is not a bag directory')
    files = mcap_files(directory)
    if not files:
        raise BagError(f'{directory} holds no .mcap file')
    old_meta = None
    if (directory / METADATA_FILENAME).exists():
        try:
            old_meta = read_metadata(directory)
        except BagError:
            old_meta = None
    meta = BagMetadata()
    if old_meta is not None:
        meta.custom_data = dict(old_meta.custom_data)
    report = RecoveryReport(metadata=meta)
    topics: dict[str, TopicInfo] = {}

    def add_channel(ch: Channel, schema: Schema | None, count: int) -> None:
        info = topics.get(ch.topic)
        if info is None:
            try:
                qos = load_profiles(ch.metadata.get('offered_qos_profiles', ''))
            except ValueError:
                qos = []
            info = topics[ch.topic] = TopicInfo(
                name=ch.topic, type=schema.name if schema else '',
                serialization_format=ch.message_encoding, offered_qos_profiles=qos,
                type_description_hash=ch.metadata.get('topic_type_hash', ''))
        info.message_count += count
        if schema is not None:
            report.schemas.setdefault(schema.name, schema.data.decode('utf-8', 'replace'))

    for path in files:
        summary = _summary_ok(path)
        if summary is not None and not verify:
            st = summary.statistics
            for cid, ch in summary.channels.items():
                add_channel(ch, summary.schemas.get(ch.schema_id),
                            st.channel_message_counts.get(cid, 0))
            meta.files.append(FileInfo(path.name, st.message_start_time if st.message_count else 0,
                                       (st.message_end_time - st.message_start_time)
                                       if st.message_count else 0, st.message_count))
            report.files.append(FileReport(path.name, 'ok', st.message_count, len(summary.chunk_indexes)))
            continue
        try:
            salvage = _salvage(path.read_bytes())
        except (BagError, OSError) as exc:
            report.files.append(FileReport(path.name, 'unreadable', detail=str(exc)))
            continue
        intact = summary is not None and salvage.chunks_bad == 0 and salvage.complete
        counts: dict[int, int] = {}
        for m in salvage.messages:
            counts[m.channel_id] = counts.get(m.channel_id, 0) + 1
        for cid, ch in salvage.channels.items():
            add_channel(ch, salvage.schemas.get(ch.schema_id), counts.get(cid, 0))
        times = [m.log_time for m in salvage.messages if m.channel_id in salvage.channels]
        meta.files.append(FileInfo(path.name, min(times) if times else 0,
                                   (max(times) - min(times)) if times else 0, len(times)))
        status = 'ok' if intact else 'rebuilt'
        if not intact and write:
            _rewrite(path, salvage)
        report.files.append(FileReport(path.name, status if write or intact else 'damaged',
                                       len(times), salvage.chunks_kept, salvage.chunks_bad,
                                       salvage.truncated_bytes))
    if not any(f.status != 'unreadable' for f in report.files):
        raise BagError(f'no readable .mcap file in {directory}: '
                       + '; '.join(f'{f.path}: {f.detail}' for f in report.files))
    # Drop unreadable files from the metadata: readers would fail on them.
    keep = {f.path for f in report.files if f.status != 'unreadable'}
    meta.files = [f for f in meta.files if f.path in keep]
    meta.topics = topics
    if write:
        write_metadata(directory, meta)
    return report
