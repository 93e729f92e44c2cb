"""Rebuild a readable bag from whatever survived (``sslfr bag recover DIR``).

Never makes a bag worse:

- every ``.mcap`` is scanned record by record (:mod:`.scan`): every chunk whose
  CRC-32 matches is kept, wherever it is (a damaged header, a corrupt length or a
  damaged chunk costs only the damaged bytes; chunks the walk cannot reach are found
  through the summary's chunk index); schemas and channels come from the data
  section or, when theirs were damaged, from the summary;
- a file that is not intact (or intact but written before rosbag2's v9 metadata
  rules were followed) is rebuilt into ``<file>.recovering`` through the recorder's
  own writer (:class:`~sslfr_recording.bag.writer.McapFile`), then **verified** (re-scanned:
  intact, the planned message count per channel) and swapped in only when it holds
  at least as many messages as a reader gets from the original; the damaged original
  is kept beside it as ``<file>.damaged`` (an intact original that was only upgraded
  is dropped once the copy is verified to hold every one of its messages);
- ``metadata.yaml`` is rebuilt from the files (missing, damaged, binary or of the
  wrong YAML types: the old one is kept as ``metadata.yaml.damaged``);
- the report says what could not be rescued: each damaged chunk (with the message
  count its message index gives, when that survived), unreadable byte ranges, the
  cut tail, messages whose channel definition was lost.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from sslfr_common.timeconv import to_sec

from .mcapfile import McapFile, TopicEntry
from .metadata import (METADATA_FILENAME, BagError, BagMetadata, FileInfo, MetadataError,
                       TopicInfo, decode_text, parse_metadata, parse_serialized, write_metadata)
from .qos import load_profiles
from .scan import FileScan, iter_chunk_messages, mcap_files, scan_file, topic_from_channel

__all__ = ['FileReport', 'RecoveryReport', 'mcap_files', 'recover_bag', 'reader_count']


@dataclass
class FileReport:
    """What recovery found and did in one file."""

    path: str
    status: str  # ok | rebuilt | upgraded | unreadable | damaged (dry run) | kept | cannot repair
    messages: int = 0          # messages in the file after recovery (or rescuable, dry run)
    readable_before: int = 0   # messages a reader got from the original
    chunks_kept: int = 0
    chunks_bad: int = 0
    truncated_bytes: int = 0
    lost: list[str] = field(default_factory=list)  # what could not be rescued
    detail: str = ''
    backup: str = ''
    cannot: list[str] = field(default_factory=list)   # what rosbag2 would still refuse, and why


@dataclass
class RecoveryReport:
    """Result of :func:`recover_bag`."""

    metadata: BagMetadata
    files: list[FileReport] = field(default_factory=list)
    schemas: dict[str, str] = field(default_factory=dict)
    metadata_note: str = ''
    wrote: bool = True

    def text(self) -> str:
        """Human-readable summary: one line per file, then what was lost, then the bag."""
        lines = []
        for f in self.files:
            extra = []
            if f.chunks_bad:
                extra.append(f'{f.chunks_bad} damaged chunk(s) left out')
            if f.truncated_bytes:
                extra.append(f'{f.truncated_bytes} trailing byte(s) of an unfinished record dropped')
            if f.detail:
                extra.append(f.detail)
            if f.backup:
                extra.append(f'original kept as {f.backup}')
            lines.append(f'{f.path}: {f.status}, {f.messages} messages'
                         + (f' (a reader got {f.readable_before} before)'
                            if f.status in ('rebuilt', 'damaged', 'kept') else '')
                         + (f' ({"; ".join(extra)})' if extra else ''))
            lines += [f'  not rescued: {item}' for item in f.lost]
        if self.metadata_note:
            lines.append(self.metadata_note)
        m = self.metadata
        lines.append(f'bag: {m.message_count} messages in {len(m.files)} file(s), '
                     f'{to_sec(m.duration_ns):.1f} s, '
                     + ('metadata.yaml rewritten' if self.wrote else 'nothing changed (dry run)'))
        return '\n'.join(lines)


def reader_count(path: Path) -> int:
    """Messages our reader (CRC-checked, log-time order) gets from one file before failing."""
    from .reader import BagReader  # local: the reader imports this package's scan module
    count = 0
    try:
        for _ in BagReader(path).messages():
            count += 1
    except BagError:
        pass
    return count


def _needs_upgrade(scan: FileScan) -> str:
    """Why an intact file differs from what rosbag2 Jazzy writes ('' when it does not)."""
    for ch in scan.channels.values():
        text = ch.metadata.get('offered_qos_profiles')
        if text is None:
            return f'channel {ch.topic} has no offered_qos_profiles'
        try:
            load_profiles(text)
        except ValueError:
            return f'channel {ch.topic}: offered_qos_profiles is not a QoS sequence'
        if not ch.metadata.get('topic_type_hash', '').startswith('RIHS01_'):
            return f'channel {ch.topic} has no RIHS01 topic_type_hash'
    records = [r for _, r in scan.metadata if r.name == 'rosbag2']
    if not records:
        return 'no rosbag2 metadata record'
    try:
        parse_serialized(records[-1].metadata.get('serialized_metadata', ''), 'rosbag2 record')
    except MetadataError:
        return 'its rosbag2 metadata record does not decode as rosbag2 Jazzy reads it'
    return ''


def _schema_repairs(scan: FileScan) -> tuple[dict[str, tuple[str, str]], list[str]]:
    """Schemas of the file that rosbag2 would refuse (rules F09/F10): {type: (the text
    rebuilt from the installed message definitions, its RIHS01 hash)} for those that can
    be rebuilt, and one line saying why for each that cannot (its type is not a message
    type, or its definition is not installed here)."""
    from .conformance import _check_schema      # local: conformance imports this package's scan
    from .schema import DefinitionCache, DefinitionNotFoundError, normalize_type
    used = {ch.schema_id for ch in scan.channels.values()}
    repairs: dict[str, tuple[str, str]] = {}
    cannot: list[str] = []
    cache = None
    for sid, schema in sorted(scan.schemas.items()):
        if sid not in used:
            continue
        findings = _check_schema('', schema)
        if not findings:
            continue
        why = findings[0].message
        try:
            name = normalize_type(schema.name)
        except ValueError:
            cannot.append(f'schema {schema.name!r} is damaged ({why}) and its name is not a message type: '
                          'its definition cannot be rebuilt')
            continue
        cache = cache or DefinitionCache()
        try:
            repairs[schema.name] = (cache.full_text(name), cache.type_hash(name))
        except (DefinitionNotFoundError, RecursionError, OSError, ValueError) as exc:
            cannot.append(f'schema {schema.name} is damaged ({why}) and cannot be rebuilt: {exc}')
    return repairs, cannot


def _lost(scan: FileScan) -> list[str]:
    out = []
    for c in scan.bad_chunks:
        n = f'{c.indexed_count} messages per its message index' if c.indexed_count is not None \
            else 'message count unknown'
        out.append(f'chunk at byte {c.offset} ({c.length} bytes, {n}): {c.error}')
    for off, length, why in scan.unrescued_damage():
        out.append(f'bytes {off}..{off + length - 1} unreadable: {why}')
    if scan.truncated_at is not None:
        out.append(f'bytes {scan.truncated_at}..{scan.size - 1}: an unfinished record (the '
                   'recording was cut there)')
    orphans = {cid: k for cid, k in scan.per_channel().items() if cid not in scan.channels}
    if orphans:
        out.append(f'{sum(orphans.values())} messages on channel id(s) '
                   f'{", ".join(map(str, sorted(orphans)))} whose channel definition was lost')
    return out


def _rebuild(path: Path, scan: FileScan, topics: dict[int, TopicInfo], schema_texts: dict[str, str],
             meta: BagMetadata) -> tuple[Path, int]:
    """Write the rescued content of ``path`` into ``<path>.recovering``; return it and its count."""
    tmp = path.with_name(path.name + '.recovering')
    if tmp.exists():
        tmp.unlink()
    out = McapFile(tmp, chunk_size=1024 * 1024, compression='zstd', fsync=True,
                   monotonic=lambda: 0.0, library=(scan.library or 'sslfr_bringup') + ' (recovered)')
    written = 0
    try:
        for info in topics.values():
            out.add_topic(TopicEntry(info, schema_texts.get(info.type, '')))
        by_id = {cid: info.name for cid, info in topics.items()}
        loose = []
        scan_loose = scan.loose_messages
        if scan_loose:
            def keep(_facts, records):
                if _facts is None:
                    loose.extend(records)
            scan_file(path, on_records=keep)
        for m in list(iter_chunk_messages(path, scan.good_chunks)) + loose:
            topic = by_id.get(m.channel_id)
            if topic is None:
                continue
            out.write(out.channels[topic], m.data, m.log_time, m.publish_time, m.sequence)
            written += 1
        out.finish(meta)
    except BaseException:
        out.abort()
        tmp.unlink(missing_ok=True)
        raise
    return tmp, written


def _old_custom_data(directory: Path) -> dict[str, str]:
    """custom_data of a metadata.yaml rosbag2 would refuse, read leniently (best effort)."""
    try:
        doc = yaml.safe_load((directory / METADATA_FILENAME).read_text(encoding='utf-8'))
        data = doc['rosbag2_bagfile_information'].get('custom_data') or {}
        return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}
    except Exception:  # noqa: BLE001 - any damage: nothing to carry over
        return {}


def recover_bag(directory: str | os.PathLike, *, verify: bool = True,
                write: bool = True) -> RecoveryReport:
    """Make every file of a bag readable and rebuild ``metadata.yaml`` (see the module doc).

    Parameters
    ----------
    directory : path
        The bag directory.
    verify : bool
        Scan every file. False trusts files whose summary can be read (fast).
    write : bool
        Rewrite files and metadata.yaml (False: report only).

    Raises
    ------
    BagError
        When the path is not a directory or holds no ``.mcap`` file at all.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise BagError(f'{directory} is not a bag directory')
    files = mcap_files(directory)
    if not files:
        raise BagError(f'{directory} holds no .mcap file')
    meta = BagMetadata()
    report = RecoveryReport(metadata=meta, wrote=write)
    meta_path = directory / METADATA_FILENAME
    meta_broken = ''
    if meta_path.exists():
        try:
            old = parse_metadata(decode_text(meta_path.read_bytes(), str(meta_path)), str(meta_path))
            meta.custom_data = dict(old.custom_data)
        except (MetadataError, OSError) as exc:
            meta_broken = str(exc)
            meta.custom_data = _old_custom_data(directory)
    scans: list[tuple[Path, FileScan | None, str]] = []
    for path in files:
        if not verify:
            from .scan import _summary
            summary, _ = _summary(path)
            if summary is not None and summary.statistics is not None:
                scans.append((path, None, ''))
                continue
        try:
            scans.append((path, scan_file(path), ''))
        except OSError as exc:
            scans.append((path, None, f'cannot read: {exc.strerror or exc}'))

    topics: dict[str, TopicInfo] = {}
    plans = []
    for path, scan, error in scans:
        if scan is None and error:
            report.files.append(FileReport(path.name, 'unreadable', detail=error))
            continue
        if scan is None:  # trusted summary (verify=False)
            from .reader import BagReader
            r = BagReader(path)
            for name, info in r.topics.items():
                t = topics.setdefault(name, TopicInfo(info.name, info.type, info.serialization_format,
                                                      info.offered_qos_profiles,
                                                      info.type_description_hash))
                t.message_count += info.message_count
            report.schemas.update({k: v for k, v in r.schemas.items() if k not in report.schemas})
            meta.files.append(r.meta.files[0])
            report.files.append(FileReport(path.name, 'ok', r.message_count, r.message_count))
            continue
        if not scan.magic_ok and not scan.chunks:
            report.files.append(FileReport(path.name, 'unreadable', detail='not an MCAP file'))
            continue
        file_topics: dict[int, TopicInfo] = {}
        counts = scan.per_channel()
        for cid, ch in scan.channels.items():
            schema = scan.schemas.get(ch.schema_id)
            info = topic_from_channel(ch, schema, counts.get(cid, 0))
            file_topics[cid] = info
            t = topics.setdefault(info.name, TopicInfo(info.name, info.type,
                                                       info.serialization_format,
                                                       info.offered_qos_profiles,
                                                       info.type_description_hash))
            t.message_count += info.message_count
            if schema is not None:
                report.schemas.setdefault(schema.name, schema.data.decode('utf-8', 'replace'))
        rescued = sum(k for cid, k in counts.items() if cid in scan.channels)
        span = scan.time_range() if rescued else None
        info = FileInfo(path.name, span[0] if span else 0, (span[1] - span[0]) if span else 0, rescued)
        meta.files.append(info)
        repairs, cannot = _schema_repairs(scan)
        for name, (text, hash_) in repairs.items():
            report.schemas[name] = text
            for info in file_topics.values():
                if info.type == name:
                    info.type_description_hash = topics[info.name].type_description_hash = hash_
        upgrade = '' if not scan.intact else _needs_upgrade(scan)
        if repairs:
            upgrade = '; '.join(filter(None, [upgrade, 'damaged schema text of ' + ', '.join(sorted(repairs))
                                              + ' rebuilt from the installed message definitions']))
        status = 'ok' if scan.intact and not upgrade else ('upgraded' if scan.intact else 'rebuilt')
        if cannot:
            upgrade = '; '.join(filter(None, [upgrade, *cannot]))
            if status == 'ok':
                status = 'cannot repair'
        rep = FileReport(path.name, status, rescued, chunks_kept=len(scan.good_chunks),
                         chunks_bad=len(scan.bad_chunks), lost=_lost(scan),
                         truncated_bytes=(scan.size - scan.truncated_at)
                         if scan.truncated_at is not None else 0,
                         detail=upgrade, cannot=cannot)
        if status != 'ok':
            rep.readable_before = reader_count(path)
            if not write:
                rep.status = 'damaged' if status == 'rebuilt' else 'needs upgrade'
        else:
            rep.readable_before = rescued
        report.files.append(rep)
        plans.append((path, scan, file_topics, rep, rescued))

    if not any(f.status not in ('unreadable',) for f in report.files):
        raise BagError(f'no readable .mcap file in {directory}: '
                       + '; '.join(f'{f.path}: {f.detail}' for f in report.files))
    keep = {f.path for f in report.files if f.status != 'unreadable'}
    meta.files = [f for f in meta.files if f.path in keep]
    meta.topics = topics
    if write:
        for path, scan, file_topics, rep, rescued in plans:
            if rep.status not in ('rebuilt', 'upgraded'):
                continue
            _replace(path, scan, file_topics, report.schemas, meta, rep, rescued)
        # files that could not be replaced keep their original content: count that
        for f in meta.files:
            rep = next(r for r in report.files if r.path == f.path)
            if rep.status == 'kept':
                f.message_count = rep.messages = rep.readable_before
        if meta_path.exists() and meta_broken:
            backup = directory / (METADATA_FILENAME + '.damaged')
            os.replace(meta_path, backup)
            report.metadata_note = (f'metadata.yaml: rosbag2 could not read it ({meta_broken}); '
                                    f'rebuilt from the files, the old one kept as {backup.name}')
        elif not meta_path.exists():
            report.metadata_note = 'metadata.yaml: missing, rebuilt from the files'
        write_metadata(directory, meta)
    elif meta_broken:
        report.metadata_note = f'metadata.yaml: rosbag2 could not read it ({meta_broken}); ' \
                               'recover would rebuild it'
    return report


def _replace(path: Path, scan: FileScan, file_topics: dict[int, TopicInfo],
             schema_texts: dict[str, str], meta: BagMetadata, rep: FileReport,
             planned: int) -> None:
    """Rebuild one file, verify the copy, swap it in only if it is not worse."""
    tmp, written = _rebuild(path, scan, file_topics, schema_texts, meta)
    check = scan_file(tmp)
    verified = check.intact and check.message_count == written == planned
    if not verified or written < rep.readable_before:
        why = 'the rebuilt copy did not verify' if not verified else \
            f'the rebuilt copy holds {written} messages, fewer than the {rep.readable_before} ' \
            'a reader gets from the original'
        tmp.unlink(missing_ok=True)
        rep.status, rep.detail = 'kept', f'left unchanged: {why}'
        return
    if rep.status == 'upgraded' and written == scan.message_count and not rep.lost:
        os.replace(tmp, path)  # lossless copy of an intact file
    else:
        backup = path.with_name(path.name + '.damaged')
        n = 1
        while backup.exists():
            backup = path.with_name(f'{path.name}.damaged.{n}')
            n += 1
        try:
            os.link(path, backup)  # the original stays in place until the copy replaces it
        except OSError:
            os.replace(path, backup)  # no hard links here (e.g. FAT): move it aside
        os.replace(tmp, path)
        rep.backup = backup.name
    rep.messages = written
    _fsync_dir(path.parent)


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
