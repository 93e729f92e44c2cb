"""Check a bag against rosbag2 Jazzy's own reading rules and the MCAP ``ros2`` profile.

``ros2 bag`` cannot be installed here, so the rules it applies are restated in
:mod:`.rules` (each with the source file and lines it comes from) and applied here to
a bag directory or a single ``.mcap`` file:

- metadata.yaml and each file's ``rosbag2`` record are decoded with rosbag2's own
  decoding order and yaml-cpp's conversions (:func:`.metadata.parse_metadata`), so
  the first key rosbag2 would throw on is reported with its line;
- each ``.mcap`` is scanned record by record (:mod:`.scan`): header, profile,
  schemas (``ros2msg`` layout, every dependency defined), channels (``cdr``,
  ``offered_qos_profiles``, ``topic_type_hash`` equal to the hash of the schema),
  chunk CRCs, message indexes, summary statistics against the data;
- metadata.yaml's files, counts, times and topics are compared with the data.

A finding has a rule id, a place (file, line or byte offset, key) and a severity
(``refuse``, ``play``, ``differs``; see :mod:`.rules`). A bag conforms when there is
no finding at all.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from .metadata import (METADATA_FILENAME, BagMetadata, MetadataError, decode_text,
                       parse_metadata, parse_serialized)
from .qos import load_profiles, unknown_policies
from .rules import RULES
from .scan import FileScan, mcap_files, scan_file
from .schema import normalize_type
from .typehash import individual_description, schema_type_hash, split_schema

_BLOCKING = ('refuse', 'play')


@dataclass
class Finding:
    """One broken rule at one place."""

    rule: str
    where: str
    key: str
    message: str
    line: int = 0
    severity: str = ''

    def __post_init__(self):
        if not self.severity:
            self.severity = RULES[self.rule].severity

    def text(self) -> str:
        loc = f'{self.where}:{self.line}' if self.line else self.where
        return f'{loc}: {self.key}: {self.message} [rule {self.rule}, {self.severity}]'


@dataclass
class Report:
    """All findings for one bag; ``metadata`` as rosbag2 would read it (None if it cannot)."""

    path: Path
    findings: list[Finding] = field(default_factory=list)
    metadata: BagMetadata | None = None
    scans: dict[str, FileScan] = field(default_factory=dict)

    @property
    def conforms(self) -> bool:
        return not self.findings

    @property
    def blocking(self) -> list[Finding]:
        """Findings that make ``ros2 bag info``/``play`` fail or misbehave."""
        return [f for f in self.findings if f.severity in _BLOCKING]

    def text(self) -> str:
        if not self.findings:
            return f'{self.path}: conforms to every checked rosbag2 Jazzy rule ({len(RULES)} rules)'
        return '\n'.join(f.text() for f in self.findings)


def _metadata_finding(exc: MetadataError, where: str) -> Finding:
    return Finding(exc.rule, where, exc.key, exc.message, exc.line)


def check_metadata_text(text: str, where: str = METADATA_FILENAME) -> tuple[BagMetadata | None, list[Finding]]:
    """Decode metadata.yaml text as rosbag2 does; findings for refusals and M11/M18."""
    try:
        meta = parse_metadata(text, where)
    except MetadataError as exc:
        return None, [_metadata_finding(exc, where)]
    return meta, _metadata_form(meta, where)


def _metadata_form(meta: BagMetadata, where: str) -> list[Finding]:
    out = []
    for t in meta.topics.values():
        bad = unknown_policies(t.offered_qos_profiles)
        if bad:
            out.append(Finding('M11', where, f'{t.name}.offered_qos_profiles',
                               f'policy names rmw does not know: {", ".join(bad)}'))
    if meta.version != 9:
        out.append(Finding('M18', where, 'version', f'rosbag2 Jazzy writes version 9, found {meta.version}'))
    return out


# -- one file -------------------------------------------------------------------------------
def _check_schema(where: str, schema) -> list[Finding]:
    out = []
    key = f'schema {schema.id} ({schema.name})'
    if schema.encoding != 'ros2msg':
        return [Finding('F09', where, key, f'encoding is {schema.encoding!r}, not ros2msg')]
    try:
        normalize_type(schema.name)
    except ValueError:
        return [Finding('F09', where, key, 'name is not a package resource name pkg/msg/Type')]
    try:
        text = schema.data.decode('utf-8')
        parts = split_schema(text, schema.name)
    except (UnicodeDecodeError, ValueError) as exc:
        return [Finding('F10', where, key, f'data is not delimited ros2msg text ({exc})')]
    for name, body in parts.items():
        try:
            desc = individual_description(name, body)
        except ValueError as exc:
            out.append(Finding('F10', where, key, f'definition of {name} cannot be read ({exc})'))
            continue
        for f in desc['fields']:
            dep = f['type']['nested_type_name']
            if dep and dep not in parts:
                out.append(Finding('F10', where, key, f'{name}.{f["name"]} uses {dep}, which the '
                                   'schema does not define'))
    return out


def check_file(path: Path, scan: FileScan | None = None) -> tuple[FileScan, list[Finding]]:
    """Rules F01-F14 on one ``.mcap`` file."""
    scan = scan or scan_file(path)
    where = path.name
    out: list[Finding] = []
    if not scan.magic_ok or not scan.header_ok:
        out.append(Finding('F01', where, 'header', 'bad magic' if not scan.magic_ok
                           else 'the Header record is damaged'))
    for c in scan.bad_chunks:
        out.append(Finding('F14', where, f'chunk at byte {c.offset}', c.error))
    for off, length, why in scan.damaged:
        if not why.startswith('header'):
            out.append(Finding('F14', where, f'bytes {off}..{off + length - 1}', why))
    if scan.truncated_at is not None:
        out.append(Finding('F02', where, f'byte {scan.truncated_at}', 'the file ends inside a '
                           'record (a cut recording): no summary, and rosbag2\'s fallback scan '
                           'fails on the cut record'))
    summary = scan.summary
    if summary is None and scan.truncated_at is None and (scan.damaged or scan.bad_chunks):
        out.append(Finding('F02', where, 'summary', f'cannot be read ({scan.summary_error}) and '
                           'the data section is damaged: rosbag2\'s fallback scan fails'))
    if summary is not None and summary.statistics is None:
        out.append(Finding('F03', where, 'statistics', 'the summary has no Statistics record'))
    if scan.header_ok and scan.profile != 'ros2':
        out.append(Finding('F04', where, 'header.profile', f'is {scan.profile!r}, not ros2'))
    encodings = set()
    for cid, ch in sorted(scan.channels.items()):
        key = f'channel {cid} ({ch.topic})'
        schema = scan.schemas.get(ch.schema_id)
        if schema is None:
            out.append(Finding('F05', where, key, f'schema id {ch.schema_id} is not defined'))
        encodings.add(ch.message_encoding)
        if ch.message_encoding != 'cdr':
            out.append(Finding('F06', where, key, f'message encoding {ch.message_encoding!r}, not cdr'))
        qos = ch.metadata.get('offered_qos_profiles')
        if qos is None:
            out.append(Finding('F07', where, key, 'no offered_qos_profiles metadata (the ros2 '
                               'profile requires it)', severity='differs'))
        else:
            try:
                profiles = load_profiles(qos, f'{key}.offered_qos_profiles')
                bad = unknown_policies(profiles)
                if bad:
                    out.append(Finding('M11', where, f'{key}.offered_qos_profiles',
                                       f'policy names rmw does not know: {", ".join(bad)}'))
                if qos == '':
                    out.append(Finding('F07', where, f'{key}.offered_qos_profiles', 'is empty: '
                                       'rosbag2 writes [] for no profile', severity='differs'))
            except ValueError as exc:
                out.append(Finding('F07', where, f'{key}.offered_qos_profiles', str(exc)))
        th = ch.metadata.get('topic_type_hash')
        if th is None:
            pass  # optional for readers (mcap_storage.cpp 489-492); our writer always sets it
        elif not th.startswith('RIHS01_') or len(th) != 7 + 64:
            out.append(Finding('F08', where, f'{key}.topic_type_hash', f'{th!r} is not a RIHS01 hash'))
        elif schema is not None and schema.encoding == 'ros2msg':
            try:
                want = schema_type_hash(schema.data.decode('utf-8'), schema.name)
            except (KeyError, ValueError, UnicodeDecodeError):
                want = th  # the schema finding says why
            if want != th:
                out.append(Finding('F08', where, f'{key}.topic_type_hash',
                                   f'{th} is not the hash of the schema\'s type description ({want})'))
    if len(encodings) > 1:
        out.append(Finding('F06', where, 'channels', f'mixed message encodings {sorted(encodings)}'))
    for sid, schema in sorted(scan.schemas.items()):
        out += _check_schema(where, schema)
    records = [r for _, r in scan.metadata if r.name == 'rosbag2']
    indexed = summary is not None and any(mi.name == 'rosbag2' for mi in summary.metadata_indexes)
    if summary is not None and not indexed:
        out.append(Finding('F11', where, 'metadata index', 'no rosbag2 metadata record is indexed: '
                           'rosbag2 reads the channels\' QoS as version 8', severity='differs'))
    for rec in records[-1:]:
        text = rec.metadata.get('serialized_metadata')
        if text is None:
            out.append(Finding('F11', where, 'rosbag2 record', 'has no serialized_metadata key',
                               severity='differs'))
            continue
        try:
            parse_serialized(text, f'{where} rosbag2 record')
        except MetadataError as exc:
            out.append(Finding(exc.rule if exc.rule != 'M01' else 'F11', f'{where} rosbag2 record',
                               exc.key, exc.message, exc.line))
    chunk_idx = list(summary.chunk_indexes) if summary is not None else []
    if scan.chunks and (not chunk_idx or all(ci.message_index_length == 0 for ci in chunk_idx)):
        out.append(Finding('F12', where, 'message indexes', 'no chunk has message indexes: '
                           'rosbag2 cannot read in log-time order and plays in file order'))
    if chunk_idx and any(ci.message_index_length for ci in chunk_idx):
        for c in scan.index_mismatches():
            out.append(Finding('F12', where, f'message index of the chunk at byte {c.offset}',
                               'does not list exactly the chunk\'s messages (log time, offset): '
                               'log-time reads go wrong'))
    if summary is not None:
        offsets = {ci.chunk_start_offset for ci in chunk_idx}
        for c in scan.chunks:
            if c.offset not in offsets:
                out.append(Finding('F12', where, f'chunk at byte {c.offset}', 'has no chunk '
                                   'index: indexed readers (rosbag2) never see its messages'))
        st = summary.statistics
        if st is not None and not scan.bad_chunks:
            data = scan.per_channel()
            span = scan.time_range() or (0, 0)
            if st.message_count != scan.message_count:
                out.append(Finding('F13', where, 'statistics.message_count',
                                   f'{st.message_count}, the chunks hold {scan.message_count}'))
            if {k: v for k, v in st.channel_message_counts.items() if v} != \
                    {k: v for k, v in data.items() if v}:
                out.append(Finding('F13', where, 'statistics.channel_message_counts',
                                   'differ from the messages in the chunks'))
            if scan.message_count and (st.message_start_time, st.message_end_time) != span:
                out.append(Finding('F13', where, 'statistics.message_start/end_time',
                                   f'{st.message_start_time}..{st.message_end_time}, the data '
                                   f'spans {span[0]}..{span[1]}'))
    return scan, out


# -- a bag ------------------------------------------------------------------------------------
def check_bag(path: str | os.PathLike) -> Report:
    """Every rule of :mod:`.rules` on a bag directory or a single ``.mcap`` file."""
    path = Path(path)
    report = Report(path)
    if path.is_file():
        scan, found = check_file(path)
        report.scans[path.name] = scan
        report.findings += found
        return report
    meta_path = path / METADATA_FILENAME
    if not meta_path.exists():
        report.findings.append(Finding('B01', path.name, METADATA_FILENAME, 'missing: `ros2 bag '
                                       'info/play` cannot open the directory'))
        files = mcap_files(path)
    else:
        try:
            text = decode_text(meta_path.read_bytes(), METADATA_FILENAME)
            meta, found = check_metadata_text(text, METADATA_FILENAME)
        except MetadataError as exc:
            meta, found = None, [_metadata_finding(exc, METADATA_FILENAME)]
        report.findings += found
        report.metadata = meta
        if meta is None:
            files = mcap_files(path)
        else:
            if meta.storage_identifier != 'mcap':
                report.findings.append(Finding('B03', METADATA_FILENAME, 'storage_identifier',
                                               f'{meta.storage_identifier!r}, not mcap'))
            files = []
            for rel in meta.file_paths():
                p = path / rel
                if not p.is_file():
                    report.findings.append(Finding('B02', METADATA_FILENAME, 'relative_file_paths',
                                                   f'{rel} does not exist'))
                else:
                    files.append(p)
    for p in files:
        scan, found = check_file(p)
        report.scans[p.name] = scan
        report.findings += found
    if report.metadata is not None:
        report.findings += _compare(report.metadata, report.scans)
    return report


def _compare(meta: BagMetadata, scans: dict[str, FileScan]) -> list[Finding]:
    """Rules B04-B07: metadata.yaml against what the files hold."""
    where = METADATA_FILENAME
    out = []
    if meta.file_paths() != [f.path for f in meta.files]:
        out.append(Finding('B04', where, 'relative_file_paths', f'{meta.file_paths()} but files '
                           f'lists {[f.path for f in meta.files]}'))
    topic_counts: dict[str, int] = {}
    topic_info: dict[str, tuple[str, str, str]] = {}
    total, spans = 0, []
    for f in meta.files:
        scan = scans.get(Path(f.path).name)
        if scan is None:
            continue
        count = scan.message_count
        total += count
        span = scan.time_range()
        if span:
            spans.append(span)
        if f.message_count != count:
            out.append(Finding('B05', where, f'files[{f.path}].message_count',
                               f'{f.message_count}, the file holds {count}'))
        if span and (f.starting_time_ns, f.duration_ns) != (span[0], span[1] - span[0]):
            out.append(Finding('B06', where, f'files[{f.path}].starting_time/duration',
                               f'{f.starting_time_ns}+{f.duration_ns}, the file spans '
                               f'{span[0]}+{span[1] - span[0]}'))
        for cid, k in scan.per_channel().items():
            ch = scan.channels.get(cid)
            if ch is not None:
                topic_counts[ch.topic] = topic_counts.get(ch.topic, 0) + k
        for ch in scan.channels.values():
            schema = scan.schemas.get(ch.schema_id)
            topic_info.setdefault(ch.topic, (schema.name if schema else '', ch.message_encoding,
                                             ch.metadata.get('topic_type_hash', '')))
    if len(scans) == len(meta.files):
        count, start, duration = meta.read_totals or (meta.message_count, 0, 0)
        if count != total:
            out.append(Finding('B05', where, 'message_count', f'{count}, the files hold {total}'))
        if sum(t.message_count for t in meta.topics.values()) != count:
            out.append(Finding('B05', where, 'topics_with_message_count', 'the topics\' counts do '
                               f'not add up to message_count {count}'))
        if spans:
            lo, hi = min(s[0] for s in spans), max(s[1] for s in spans)
            if (start, duration) != (lo, hi - lo):
                out.append(Finding('B06', where, 'starting_time/duration', f'{start}+{duration}, '
                                   f'the data spans {lo}+{hi - lo}'))
        for name, t in meta.topics.items():
            if name not in topic_info:
                out.append(Finding('B07', where, f'topics_with_message_count[{name}]',
                                   'no file has a channel for this topic'))
                continue
            typ, fmt, th = topic_info[name]
            if (t.type, t.serialization_format) != (typ, fmt):
                out.append(Finding('B07', where, f'topics_with_message_count[{name}]',
                                   f'{t.type}/{t.serialization_format}, the channel says {typ}/{fmt}'))
            if t.message_count != topic_counts.get(name, 0):
                out.append(Finding('B05', where, f'topics_with_message_count[{name}].message_count',
                                   f'{t.message_count}, the files hold {topic_counts.get(name, 0)}'))
            if not t.type_description_hash.startswith('RIHS01_'):
                out.append(Finding('B07', where, f'topics_with_message_count[{name}].type_description_hash',
                                   f'{t.type_description_hash!r} is not a RIHS01 hash'))
            elif th and th != t.type_description_hash:
                out.append(Finding('B07', where, f'topics_with_message_count[{name}].type_description_hash',
                                   f'{t.type_description_hash}, the channel says {th}'))
        for name in topic_info:
            if name not in meta.topics:
                out.append(Finding('B07', where, 'topics_with_message_count',
                                   f'{name} is recorded in the files but not listed'))
    return out
