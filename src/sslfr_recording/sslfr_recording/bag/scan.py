"""Record-level scan of one ``.mcap`` file, robust to damage (no rclpy).

Used by recovery (what can be rescued), by the conformance check (what the data
really holds, to compare with the summary and metadata.yaml) and by the reader
(topics from channels). The scan

- reads the summary section when the footer is intact (schemas, channels, chunk
  indexes, statistics, metadata index);
- walks the data section record by record from the header; a record whose length
  or content is impossible starts a **resync**: the next offset where a well-formed
  record starts (a chunk whose CRC-32 matches, or two consecutive well-formed
  records) is searched, so a damaged header or a corrupt length costs only the
  damaged bytes;
- also visits every chunk the summary's chunk index points at that the walk did not
  reach;
- checks each chunk: decompression, size, CRC-32 (when the writer stored one) and
  the exact layout of the records inside it.

Offsets are byte offsets in the file; times integer nanoseconds (MCAP log times).
"""
from __future__ import annotations

import io
import os
import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.records import Channel, Message, Metadata, Schema

from .metadata import TopicInfo
from .qos import load_profiles
from .typehash import schema_type_hash

MAGIC = b'\x89MCAP0\r\n'
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_ATTACHMENT, OP_ATTACHMENT_INDEX = 0x07, 0x08, 0x09, 0x0A
OP_STATISTICS, OP_METADATA, OP_METADATA_INDEX, OP_SUMMARY_OFFSET, OP_DATA_END = 0x0B, 0x0C, 0x0D, 0x0E, 0x0F
_DATA_OPS = (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_MESSAGE_INDEX, OP_ATTACHMENT,
             OP_METADATA, OP_DATA_END)
_RESYNC_OPS = re.compile(rb'[\x03\x04\x06\x07\x09\x0c\x0f]')
_MAX_RECORD = 1 << 34
_CHUNK_HEAD = struct.Struct('<QQQII')


class ScanError(ValueError):
    """A record that cannot be what its opcode says."""


def _parse_exact(body: bytes, reader):
    stream = ReadDataStream(io.BytesIO(body))
    rec = reader(stream)
    if stream.count != len(body):
        raise ScanError('record length does not match its content')
    return rec


def parse_record(op: int, body: bytes):
    """Schema / Channel / Message / Metadata record from its body, checked to fill it exactly."""
    try:
        if op == OP_SCHEMA:
            return _parse_exact(body, Schema.read)
        if op == OP_CHANNEL:
            return _parse_exact(body, Channel.read)
        if op == OP_METADATA:
            return _parse_exact(body, Metadata.read)
        if op == OP_MESSAGE:
            if len(body) < 22:
                raise ScanError('message record too short')
            cid, seq, log, pub = struct.unpack_from('<HIQQ', body)
            return Message(channel_id=cid, sequence=seq, log_time=log, publish_time=pub,
                           data=body[22:])
    except (struct.error, UnicodeDecodeError, EOFError, IndexError, McapError) as exc:
        raise ScanError(f'malformed record ({exc or type(exc).__name__})') from None
    raise ScanError(f'unexpected opcode {op:#04x}')


def decompress(compression: str, data: bytes, usize: int) -> bytes:
    """Uncompressed records of a chunk ('' / zstd / lz4), checked to be ``usize`` bytes.

    Raises
    ------
    ScanError
        Unknown compression, data that does not decompress, or a size mismatch.
    """
    try:
        if compression == 'zstd':
            import zstandard
            data = zstandard.ZstdDecompressor().decompress(data, max_output_size=usize)
        elif compression == 'lz4':
            import lz4.frame
            data = lz4.frame.decompress(data)
        elif compression:
            raise ScanError(f'unsupported chunk compression {compression!r}')
    except ScanError:
        raise
    except Exception as exc:  # noqa: BLE001 - zstd/lz4 raise their own error types
        raise ScanError(f'chunk does not decompress ({exc})') from None
    if len(data) != usize:
        raise ScanError('chunk uncompressed size mismatch')
    return data


def chunk_records(body: bytes, validate_crc: bool = True) -> tuple[dict, list]:
    """Decode a Chunk record body: (header fields, [Schema | Channel | Message ...]).

    Raises
    ------
    ScanError
        Bad compression, size or CRC mismatch, or records that do not fill the chunk.
    """
    try:
        start, end, usize, crc, clen = _CHUNK_HEAD.unpack_from(body, 0)
    except struct.error:
        raise ScanError('chunk header cut short') from None
    off = _CHUNK_HEAD.size
    if clen > 16:
        raise ScanError('chunk compression name too long')
    try:
        compression = body[off:off + clen].decode('ascii')
    except UnicodeDecodeError:
        raise ScanError('chunk compression name is not text') from None
    off += clen
    if off + 8 > len(body):
        raise ScanError('chunk header cut short')
    (rlen,) = struct.unpack_from('<Q', body, off)
    off += 8
    if off + rlen != len(body):
        raise ScanError('chunk records length does not match the record length')
    if usize > _MAX_RECORD:
        raise ScanError('impossible uncompressed chunk size')
    payload = decompress(compression, body[off:], usize)
    if validate_crc and crc and zlib.crc32(payload) != crc:
        raise ScanError(f'chunk CRC mismatch (stored {crc:#010x}, data {zlib.crc32(payload):#010x})')
    records = []
    pos, n = 0, len(payload)
    while pos < n:
        if pos + 9 > n:
            raise ScanError('record cut short inside the chunk')
        op = payload[pos]
        (length,) = struct.unpack_from('<Q', payload, pos + 1)
        if pos + 9 + length > n:
            raise ScanError('record inside the chunk runs past its end')
        rec_body = payload[pos + 9:pos + 9 + length]
        pos += 9 + length
        if op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
            rec = parse_record(op, rec_body)
            if op == OP_MESSAGE:
                rec._offset = pos - 9 - length  # where its message index entry must point
            records.append(rec)
        elif op == 0 or op > OP_DATA_END:
            raise ScanError(f'invalid opcode {op:#04x} inside the chunk')
    return {'start': start, 'end': end, 'usize': usize, 'crc': crc,
            'compression': compression}, records


@dataclass
class ChunkFacts:
    """One chunk found in a file."""

    offset: int
    length: int  # whole record (opcode + length + body) [bytes]
    ok: bool
    error: str = ''
    count: int = 0
    per_channel: dict[int, int] = field(default_factory=dict)
    start: int = 0  # first log time [ns]
    end: int = 0    # last log time [ns]
    via_index: bool = False  # reached only through the summary's chunk index
    indexed_count: int | None = None  # messages its Message Index records list
    entries: dict[int, list[tuple[int, int]]] = field(default_factory=dict)  # cid -> (log, offset)
    index: dict[int, list[tuple[int, int]]] = field(default_factory=dict)    # as its indexes say


@dataclass
class FileScan:
    """What one ``.mcap`` file holds, as far as it can be read."""

    path: Path
    size: int
    magic_ok: bool = False
    header_ok: bool = False
    profile: str = ''
    library: str = ''
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: list[tuple[int, Metadata]] = field(default_factory=list)  # (offset, record)
    chunks: list[ChunkFacts] = field(default_factory=list)
    loose_messages: int = 0          # Message records outside chunks
    loose_per_channel: dict[int, int] = field(default_factory=dict)
    loose_times: list[int] = field(default_factory=list)
    data_end: bool = False           # the Data End record was reached
    damaged: list[tuple[int, int, str]] = field(default_factory=list)  # (offset, length, why)
    truncated_at: int | None = None  # offset of a record cut by the end of the file
    summary: object | None = None    # mcap Summary when the footer/summary are intact
    summary_error: str = ''
    summary_schemas_only: set[int] = field(default_factory=set)   # ids known only from summary
    summary_channels_only: set[int] = field(default_factory=set)

    def unrescued_damage(self) -> list[tuple[int, int, str]]:
        """Damaged byte ranges that no intact chunk (found through the index) covers."""
        good = {c.offset: c.length for c in self.good_chunks}
        return [d for d in self.damaged if not (d[0] in good and d[1] <= good[d[0]])]

    @property
    def good_chunks(self) -> list[ChunkFacts]:
        return [c for c in self.chunks if c.ok]

    @property
    def bad_chunks(self) -> list[ChunkFacts]:
        return [c for c in self.chunks if not c.ok]

    @property
    def message_count(self) -> int:
        """Messages in intact chunks plus loose messages."""
        return sum(c.count for c in self.good_chunks) + self.loose_messages

    def per_channel(self) -> dict[int, int]:
        out = dict(self.loose_per_channel)
        for c in self.good_chunks:
            for cid, k in c.per_channel.items():
                out[cid] = out.get(cid, 0) + k
        return out

    def time_range(self) -> tuple[int, int] | None:
        times = [(c.start, c.end) for c in self.good_chunks if c.count]
        if self.loose_times:
            times.append((min(self.loose_times), max(self.loose_times)))
        if not times:
            return None
        return min(t[0] for t in times), max(t[1] for t in times)

    def index_mismatches(self) -> list[ChunkFacts]:
        """Intact chunks whose Message Index records do not list exactly their messages."""
        out = []
        for c in self.good_chunks:
            if c.via_index or not c.count:
                continue
            want = {cid: sorted(v) for cid, v in c.entries.items()}
            got = {cid: sorted(tuple(e) for e in v) for cid, v in c.index.items() if v}
            if want != got:
                out.append(c)
        return out

    @property
    def intact(self) -> bool:
        """Nothing damaged, nothing cut, summary readable, message indexes right."""
        return (self.header_ok and self.data_end and not self.damaged and self.truncated_at is None
                and not self.bad_chunks and self.summary is not None
                and not self.index_mismatches())


def _summary(path: Path):
    from mcap.exceptions import McapError
    from mcap.reader import SeekingReader
    try:
        with open(path, 'rb') as fh:
            summary = SeekingReader(fh, validate_crcs=True).get_summary()
    except (McapError, OSError, struct.error, ValueError, KeyError, IndexError, EOFError,
            UnicodeDecodeError) as exc:
        return None, f'{type(exc).__name__}: {exc}'
    if summary is None:
        return None, 'no summary section'
    return summary, ''


class _Walker:
    def __init__(self, data: bytes, scan: FileScan, on_chunk_records):
        self.data = data
        self.n = len(data)
        self.scan = scan
        self.on_chunk_records = on_chunk_records
        self.seen_chunks: set[int] = set()
        self.last_chunk = -1

    def record_at(self, pos: int):
        """(opcode, body) of a record that fits in the file at pos, else None."""
        if pos + 9 > self.n:
            return None
        op = self.data[pos]
        (length,) = struct.unpack_from('<Q', self.data, pos + 1)
        if length > _MAX_RECORD or pos + 9 + length > self.n:
            return None
        return op, self.data[pos + 9:pos + 9 + length]

    def well_formed(self, pos: int, op: int, body: bytes) -> bool:
        """Can this be a real top-level data-section record (without side effects)?"""
        try:
            if op == OP_CHUNK:
                chunk_records(body, validate_crc=True)
                return True
            if op in (OP_SCHEMA, OP_CHANNEL, OP_METADATA):
                parse_record(op, body)
                return True
            if op == OP_MESSAGE_INDEX:
                if len(body) < 6:
                    return False
                (alen,) = struct.unpack_from('<I', body, 2)
                return alen % 16 == 0 and 6 + alen == len(body)
            if op == OP_DATA_END:
                return len(body) == 4
            if op == OP_ATTACHMENT:
                return len(body) >= 20
        except ScanError:
            return False
        return False

    def resync(self, pos: int) -> int | None:
        """Next offset after ``pos`` where a well-formed record (chain) starts."""
        for m in _RESYNC_OPS.finditer(self.data, pos + 1):
            q = m.start()
            rec = self.record_at(q)
            if rec is None:
                continue
            op, body = rec
            if not self.well_formed(q, op, body):
                continue
            nxt = q + 9 + len(body)
            if op == OP_CHUNK or op == OP_DATA_END or nxt >= self.n:
                return q  # a chunk with matching CRC/layout is strong evidence on its own
            rec2 = self.record_at(nxt)
            if rec2 is not None and rec2[0] in _DATA_OPS and self.well_formed(nxt, *rec2):
                return q
        return None

    def chunk(self, pos: int, body: bytes, via_index: bool = False) -> None:
        if pos in self.seen_chunks:
            return
        self.seen_chunks.add(pos)
        facts = ChunkFacts(offset=pos, length=9 + len(body), ok=False, via_index=via_index)
        try:
            _, records = chunk_records(body, validate_crc=True)
        except ScanError as exc:
            facts.error = str(exc)
            self.scan.chunks.append(facts)
            return
        facts.ok = True
        times = []
        for rec in records:
            if isinstance(rec, Schema):
                self.scan.schemas.setdefault(rec.id, rec)
            elif isinstance(rec, Channel):
                self.scan.channels.setdefault(rec.id, rec)
            else:
                facts.count += 1
                facts.per_channel[rec.channel_id] = facts.per_channel.get(rec.channel_id, 0) + 1
                facts.entries.setdefault(rec.channel_id, []).append((rec.log_time, rec._offset))
                times.append(rec.log_time)
        if times:
            facts.start, facts.end = min(times), max(times)
        self.scan.chunks.append(facts)
        if self.on_chunk_records is not None:
            self.on_chunk_records(facts, records)

    def walk(self) -> None:
        data, scan = self.data, self.scan
        pos = len(MAGIC)
        first = True
        while pos < self.n:
            rec = self.record_at(pos)
            ok = rec is not None
            if ok:
                op, body = rec
                try:
                    if first:
                        if op != OP_HEADER:
                            raise ScanError('the file does not start with a Header record')
                        hdr = ReadDataStream(io.BytesIO(body))
                        scan.profile = hdr.read_prefixed_string()
                        scan.library = hdr.read_prefixed_string()
                        if hdr.count != len(body):
                            raise ScanError('header length does not match its content')
                        scan.header_ok = True
                    elif op == OP_CHUNK:
                        self.chunk(pos, body)
                        self.last_chunk = pos
                    elif op in (OP_SCHEMA, OP_CHANNEL):
                        r = parse_record(op, body)
                        (scan.schemas if op == OP_SCHEMA else scan.channels).setdefault(r.id, r)
                    elif op == OP_MESSAGE:
                        m = parse_record(op, body)
                        scan.loose_messages += 1
                        scan.loose_per_channel[m.channel_id] = scan.loose_per_channel.get(m.channel_id, 0) + 1
                        scan.loose_times.append(m.log_time)
                        if self.on_chunk_records is not None:
                            self.on_chunk_records(None, [m])
                    elif op == OP_METADATA:
                        scan.metadata.append((pos, parse_record(op, body)))
                    elif op == OP_DATA_END:
                        scan.data_end = True
                        return
                    elif op == OP_MESSAGE_INDEX:
                        if len(body) < 6:
                            raise ScanError('message index cut short')
                        (alen,) = struct.unpack_from('<I', body, 2)
                        if alen % 16 or 6 + alen != len(body):
                            raise ScanError('message index length does not match its content')
                        if scan.chunks and scan.chunks[-1].offset == self.last_chunk:
                            c = scan.chunks[-1]
                            c.indexed_count = (c.indexed_count or 0) + alen // 16
                            (cid,) = struct.unpack_from('<H', body, 0)
                            c.index[cid] = [struct.unpack_from('<QQ', body, 6 + 16 * k)
                                            for k in range(alen // 16)]
                    elif op == OP_ATTACHMENT:
                        pass
                    else:
                        raise ScanError(f'opcode {op:#04x} cannot appear in the data section')
                except (ScanError, EOFError, UnicodeDecodeError, struct.error, McapError) as exc:
                    ok = False
                    why = str(exc) or type(exc).__name__
                else:
                    first = False
                    pos += 9 + len(body)
                    continue
            else:
                why = 'impossible record length' if pos + 9 <= self.n else 'cut short'
            nxt = self.resync(pos)
            if first:
                first = False
                why = f'header: {why}'
            if nxt is not None:
                scan.damaged.append((pos, nxt - pos, why))
                pos = nxt
                continue
            if rec is None and self.n == len(data):
                scan.truncated_at = pos  # the file ends inside this record
            else:
                scan.damaged.append((pos, self.n - pos, why))
            return


def summary_start(data: bytes) -> int:
    """Offset of the summary section from an intact footer, else 0."""
    if len(data) < len(MAGIC) * 2 + 29 or not data.endswith(MAGIC):
        return 0
    pos = len(data) - len(MAGIC) - 29
    op, length, start = struct.unpack_from('<BQQ', data, pos)
    if op != OP_FOOTER or length != 20 or not len(MAGIC) < start <= pos:
        return 0
    return start


def scan_file(path: str | os.PathLike, on_records=None) -> FileScan:
    """Scan one ``.mcap`` file (see the module docstring).

    Parameters
    ----------
    on_records : callable, optional
        Called as ``on_records(chunk_facts_or_None, records)`` with the records of every
        intact chunk (and with loose Message records), in file order.
    """
    path = Path(path)
    data = path.read_bytes()
    scan = FileScan(path=path, size=len(data))
    scan.magic_ok = data.startswith(MAGIC)
    scan.summary, scan.summary_error = _summary(path) if scan.magic_ok else (None, 'bad magic')
    walker = _Walker(data, scan, on_records)
    start = summary_start(data)
    if scan.summary is not None and start:
        walker.n = start  # the data section ends where the summary starts
    walker.walk()
    walker.n = len(data)
    summary = scan.summary
    if summary is not None:
        for sid, s in summary.schemas.items():
            if sid not in scan.schemas:
                scan.schemas[sid] = s
                scan.summary_schemas_only.add(sid)
        for cid, c in summary.channels.items():
            if cid not in scan.channels:
                scan.channels[cid] = c
                scan.summary_channels_only.add(cid)
        for ci in summary.chunk_indexes:
            off = ci.chunk_start_offset
            if off in walker.seen_chunks:
                continue
            rec = walker.record_at(off)
            if rec is None and 9 < ci.chunk_length and off + ci.chunk_length <= len(data):
                rec = (data[off], data[off + 9:off + ci.chunk_length])  # its length field is damaged
            if rec is not None and rec[0] == OP_CHUNK:
                walker.chunk(off, rec[1], via_index=True)
        scan.chunks.sort(key=lambda c: c.offset)
    return scan


def iter_chunk_messages(path: Path, chunks: list[ChunkFacts]) -> Iterator[Message]:
    """Messages of the given intact chunks, chunk by chunk (file order)."""
    with open(path, 'rb') as fh:
        for c in chunks:
            fh.seek(c.offset)
            raw = fh.read(c.length)
            for rec in chunk_records(raw[9:], validate_crc=True)[1]:
                if isinstance(rec, Message):
                    yield rec


def mcap_files(directory: Path) -> list[Path]:
    """The ``.mcap`` files of a bag directory in split order (``name_0``, ``name_1`` ...)."""
    def index(p: Path):
        tail = p.stem.rsplit('_', 1)[-1]
        return (int(tail) if tail.isdigit() else 1 << 30, p.name)
    return sorted((p for p in Path(directory).glob('*.mcap') if p.is_file()), key=index)


def topic_from_channel(channel: Channel, schema: Schema | None, count: int = 0) -> TopicInfo:
    """rosbag2's view of a channel (``mcap_storage.cpp`` ``read_metadata``, 466-499).

    Type = schema name, serialization format = message encoding, QoS from the
    ``offered_qos_profiles`` metadata (unreadable QoS -> none: the conformance check
    reports it), type hash from ``topic_type_hash``, computed from the schema when the
    key is empty or missing.
    """
    try:
        qos = load_profiles(channel.metadata.get('offered_qos_profiles', ''))
    except ValueError:
        qos = []
    type_name = schema.name if schema is not None else ''
    type_hash = channel.metadata.get('topic_type_hash', '')
    if not type_hash.startswith('RIHS01_') and schema is not None and schema.encoding == 'ros2msg':
        try:
            type_hash = schema_type_hash(schema.data.decode('utf-8'), type_name)
        except (KeyError, ValueError):
            pass
    return TopicInfo(channel.topic, type_name, channel.message_encoding, qos, type_hash, count)
