"""rosbag2 Jazzy conformance of our bags, type hashes, the metadata loader, and recovery.

References that are not our own code: the generated ``.json`` type descriptions of
every installed message type (rosidl's hashes), rosbags' v9 writer (a control bag
written by another writer), and the rules of :mod:`sslfr_recording.bag.rules` taken
from rosbag2 Jazzy's source. Recovery is checked on a corpus of damaged copies
against the message count our reader gets before recovery and against the ground
truth of which chunks the damage hit.
"""
from __future__ import annotations

import json
import os
import shutil
import struct
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st
from mcap.reader import make_reader
from mcap.writer import IndexType, Writer
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Temperature
from sslfr_interfaces.msg import AxisStatus, TrackerPhase

from sslfr_recording.bag import BagReader, BagWriter, SplitPolicy, WriterOptions, profile
from sslfr_recording.bag.conformance import check_bag
from sslfr_recording.bag.metadata import BagMetadata, MetadataError, parse_metadata, read_metadata
from sslfr_recording.bag.recover import reader_count, recover_bag
from sslfr_recording.bag.rules import RULES, SOURCES
from sslfr_recording.bag.schema import DefinitionCache
from sslfr_recording.bag.typehash import schema_type_hash, type_hash

T0 = 1_782_000_000 * 10**9


def _write(directory: Path, n: int = 300, options: WriterOptions | None = None) -> list[tuple]:
    """A small bag of three topics (one latched, one without QoS); returns what was written."""
    w = BagWriter(directory, options or WriterOptions(fsync=False, chunk_size=4096))
    w.add_topic('/absorber/outlet_temperature', 'sensor_msgs/msg/Temperature', [profile()])
    w.add_topic('/axes/mirrors/status', 'sslfr_interfaces/msg/AxisStatus',
                [profile(reliability='best_effort'), profile()])
    w.add_topic('/tracker/phase', 'sslfr_interfaces/msg/TrackerPhase', [])
    out = []
    for k in range(n):
        t = T0 + k * 20_000_000
        items = [('/absorber/outlet_temperature', Temperature(temperature=20.0 + k)),
                 ('/axes/mirrors/status', AxisStatus(axis='mirrors', steps=k, board_info='b' * (k % 9)))]
        if k % 25 == 0:
            items.append(('/tracker/phase', TrackerPhase(phase=2, reason=f'step {k}')))
        for i, (topic, msg) in enumerate(items):
            data = bytes(serialize_message(msg))
            w.write(topic, data, t + i)
            out.append((topic, t + i, data))
    w.close()
    return out


def _messages(bag: Path) -> list[tuple]:
    return [(m.topic, m.log_time, m.data) for m in BagReader(bag).messages()]


def _rules(report) -> set[str]:
    return {f.rule for f in report.findings}


# -- type hashes ----------------------------------------------------------------------------
def test_type_hash_computed_from_msg_equals_generated_json_for_every_installed_type():
    defs = DefinitionCache()
    checked = 0
    for prefix in os.environ['AMENT_PREFIX_PATH'].split(os.pathsep):
        for js in sorted(Path(prefix).glob('share/*/msg/*.json')):
            data = json.loads(js.read_text())
            name = data['type_description_msg']['type_description']['type_name']
            want = data['type_hashes'][0]['hash_string']
            assert type_hash(name, defs.text) == want, name
            assert schema_type_hash(defs.full_text(name), name) == want, name
            checked += 1
    assert checked >= 150  # std/sensor/diagnostic/geometry/... and sslfr_interfaces


def test_type_hash_without_json_is_computed(tmp_path):
    # a copy of the index without any .json: the writer still fills RIHS01 hashes
    share = tmp_path / 'share'
    for prefix in os.environ['AMENT_PREFIX_PATH'].split(os.pathsep):
        for pkg in ('std_msgs', 'builtin_interfaces', 'sslfr_interfaces'):
            src = Path(prefix) / 'share' / pkg / 'msg'
            if src.is_dir() and not (share / pkg / 'msg').exists():
                (share / pkg / 'msg').mkdir(parents=True)
                for f in src.glob('*.msg'):
                    shutil.copy(f, share / pkg / 'msg' / f.name)
    defs = DefinitionCache(prefixes=[tmp_path])
    expect = json.loads((Path(DefinitionCache().share_dir('sslfr_interfaces')) / 'msg' /
                         'AxisStatus.json').read_text())['type_hashes'][0]['hash_string']
    assert not list(share.rglob('*.json'))
    assert defs.type_hash('sslfr_interfaces/msg/AxisStatus') == expect


# -- metadata.yaml as rosbag2 writes it ---------------------------------------------------
def test_metadata_yaml_has_qos_as_a_sequence_of_maps(tmp_path):
    _write(tmp_path / 'b', 30)
    doc = yaml.safe_load((tmp_path / 'b' / 'metadata.yaml').read_text())
    info = doc['rosbag2_bagfile_information']
    assert info['version'] == 9 and info['custom_data'] is None
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    qos = topics['/axes/mirrors/status']['topic_metadata']['offered_qos_profiles']
    assert isinstance(qos, list) and qos[0]['reliability'] == 'best_effort'
    assert qos[0]['deadline'] == {'sec': 0, 'nsec': 0}
    assert set(qos[0]) == {'history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan',
                           'liveliness', 'liveliness_lease_duration', 'avoid_ros_namespace_conventions'}
    assert topics['/tracker/phase']['topic_metadata']['offered_qos_profiles'] == []
    for t in topics.values():
        assert t['topic_metadata']['type_description_hash'].startswith('RIHS01_')
    # the rosbag2 record of the .mcap holds the same mapping; channels hold the QoS YAML text
    (f,) = (tmp_path / 'b').glob('*.mcap')
    with open(f, 'rb') as fh:
        r = make_reader(fh)
        recs = [m for m in r.iter_metadata() if m.name == 'rosbag2']
        channels = {c.topic: c for c in r.get_summary().channels.values()}
    assert set(recs[-1].metadata) == {'serialized_metadata'}
    inner = yaml.safe_load(recs[-1].metadata['serialized_metadata'])
    assert inner['topics_with_message_count'][1]['topic_metadata']['offered_qos_profiles'][1][
        'reliability'] == 'reliable'
    assert channels['/tracker/phase'].metadata['offered_qos_profiles'] == '[]'
    assert yaml.safe_load(channels['/axes/mirrors/status'].metadata['offered_qos_profiles']) == qos


def _valid_text(tmp_path) -> str:
    _write(tmp_path / 'v', 10)
    return (tmp_path / 'v' / 'metadata.yaml').read_text()


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=400))
def test_metadata_loader_random_bytes_never_crashes(data):
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError:
        return
    try:
        meta = parse_metadata(text)
    except MetadataError as exc:
        assert exc.rule in RULES and str(exc)
    else:
        assert isinstance(meta, BagMetadata)


_yaml_values = st.recursive(
    st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.text(max_size=12)
    | st.floats(allow_nan=True),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
    max_leaves=8)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(path_pick=st.integers(0, 10**6), value=_yaml_values, data=st.data())
def test_metadata_loader_random_yaml_values_refused_with_key_and_line(tmp_path_factory, path_pick,
                                                                     value, data):
    base = yaml.safe_load(_VALID[0])
    # pick one node of the document and replace it (or delete its key) with random YAML
    nodes = []

    def walk(node, trail):
        if isinstance(node, dict):
            for k, v in node.items():
                nodes.append((node, k, trail + [k]))
                walk(v, trail + [k])
        elif isinstance(node, list):
            for i, v in enumerate(node):
                nodes.append((node, i, trail + [i]))
                walk(v, trail + [i])
    walk(base, [])
    parent, key, trail = nodes[path_pick % len(nodes)]
    if data.draw(st.booleans()) and isinstance(parent, dict):
        del parent[key]
    else:
        parent[key] = value
    text = yaml.safe_dump(base, sort_keys=False)
    try:
        meta = parse_metadata(text)
    except MetadataError as exc:
        assert exc.rule in RULES
        assert exc.key  # names the key path
        assert exc.line >= 0
    else:
        assert isinstance(meta, BagMetadata)


_VALID: list[str] = []


@pytest.fixture(autouse=True, scope='module')
def _valid_metadata(tmp_path_factory):
    _VALID.append(_valid_text(tmp_path_factory.mktemp('valid')))


def test_metadata_loader_refusals_name_key_and_line():
    text = _VALID[0]
    cases = {
        'QoS as a string (what the old writer wrote)': (
            text.replace('offered_qos_profiles:\n', 'offered_qos_profiles: "- history: keep_last"\n'
                         '        unused_key:\n', 1), 'M09'),
        'missing ros_distro': ('\n'.join(l for l in text.splitlines() if 'ros_distro' not in l), 'M17'),
        'files is a string': (text.replace('  files:\n', '  files: nope\n  old_files:\n'), 'M15'),
        'message_count negative': (text.replace('  message_count: ', '  message_count: -', 1), 'M06'),
        'binary-ish': ('\x00\x01rosbag2', 'M01'),
        'depth not an int': (text.replace('depth: 10', 'depth: ten', 1), 'M10'),
    }
    for what, (bad, rule) in cases.items():
        with pytest.raises(MetadataError) as info:
            parse_metadata(bad)
        assert info.value.rule == rule, what
        assert info.value.key, what


# -- conformance --------------------------------------------------------------------------------
def test_rules_cite_their_sources_and_docs_list_them():
    assert len(RULES) >= 35
    for r in RULES.values():
        assert r.cites
        for src, lines in r.cites:
            assert src in SOURCES and lines.replace('-', '').isdigit()
    docs = (Path(__file__).resolve().parents[3] / 'docs' / 'bags.md').read_text()
    for r in RULES.values():  # docs/bags.md's table is the rule list, row for row
        assert f'| {r.id} | {r.severity} | {r.text} | {r.citation()} |' in docs, r.id


def test_our_bags_conform_plain_split_and_recovered(tmp_path):
    _write(tmp_path / 'plain', 200)
    assert check_bag(tmp_path / 'plain').findings == []
    _write(tmp_path / 'split', 600, WriterOptions(fsync=False, chunk_size=4096,
                                                   split=SplitPolicy(max_bytes=15_000)))
    assert len(read_metadata(tmp_path / 'split').files) >= 3
    assert check_bag(tmp_path / 'split').findings == []
    for f in (tmp_path / 'split').glob('*.mcap'):  # `ros2 bag info FILE.mcap` too
        assert check_bag(f).findings == [], f


def test_rosbags_v9_control_bag_conforms(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer as RosbagsWriter
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    T = store.types['sensor_msgs/msg/Temperature']
    H = store.types['std_msgs/msg/Header']
    Tm = store.types['builtin_interfaces/msg/Time']
    with RosbagsWriter(tmp_path / 'rb', version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection('/t', 'sensor_msgs/msg/Temperature', typestore=store)
        for k in range(50):
            m = T(header=H(stamp=Tm(sec=k, nanosec=0), frame_id='x'), temperature=float(k), variance=0.0)
            w.write(c, T0 + k, store.serialize_cdr(m, 'sensor_msgs/msg/Temperature'))
    report = check_bag(tmp_path / 'rb')
    assert report.findings == [], report.text()
    assert report.metadata.ros_distro == 'rosbags'


def _rewrite_mcap(src: Path, dst: Path, *, profile_name='ros2', message_index=True,
                  qos_text=None, record_text=None):
    """Copy an MCAP record by record with one thing changed (for the broken copies)."""
    with open(src, 'rb') as fh:
        r = make_reader(fh)
        header = r.get_header()
        summary = r.get_summary()
        msgs = list(r.iter_messages(log_time_order=False))
        metas = list(r.iter_metadata())
    idx = IndexType.ALL if message_index else IndexType.ALL & ~IndexType.MESSAGE
    with open(dst, 'wb') as out:
        w = Writer(out, index_types=idx)
        w.start(profile=profile_name, library=header.library)
        sids = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        cids = {}
        for cid, c in summary.channels.items():
            md = dict(c.metadata)
            if qos_text is not None:
                md['offered_qos_profiles'] = qos_text
            cids[cid] = w.register_channel(c.topic, c.message_encoding, sids[c.schema_id], md)
        for _, ch, m in msgs:
            w.add_message(cids[ch.id], m.log_time, m.data, m.publish_time, m.sequence)
        for m in metas:
            md = dict(m.metadata)
            if record_text is not None:
                md['serialized_metadata'] = record_text
            w.add_metadata(m.name, md)
        w.finish()


def test_broken_copies_fail_the_check(tmp_path):
    _write(tmp_path / 'good', 200)
    (src,) = (tmp_path / 'good').glob('*.mcap')
    meta_text = (tmp_path / 'good' / 'metadata.yaml').read_text()

    def copy(name: str) -> Path:
        d = tmp_path / name
        shutil.copytree(tmp_path / 'good', d)
        return d

    cases = {}
    d = copy('qos_string')  # v9 metadata with the QoS as a quoted string (the old bug)
    doc = yaml.safe_load(meta_text)
    for t in doc['rosbag2_bagfile_information']['topics_with_message_count']:
        t['topic_metadata']['offered_qos_profiles'] = yaml.safe_dump(
            t['topic_metadata']['offered_qos_profiles'])
    (d / 'metadata.yaml').write_text(yaml.safe_dump(doc, sort_keys=False))
    cases[d] = 'M09'
    d = copy('missing_key')
    (d / 'metadata.yaml').write_text(meta_text.replace('  relative_file_paths:', '  relative_file_pathz:'))
    cases[d] = 'M13'
    d = copy('wrong_profile')
    _rewrite_mcap(src, d / src.name, profile_name='ros1')
    cases[d] = 'F04'
    d = copy('missing_index')
    _rewrite_mcap(src, d / src.name, message_index=False)
    cases[d] = 'F12'
    d = copy('channel_qos_garbage')
    _rewrite_mcap(src, d / src.name, qos_text='history: [')
    cases[d] = 'F07'
    d = copy('record_v9_qos_string')
    inner = yaml.safe_load(meta_text)['rosbag2_bagfile_information']
    for t in inner['topics_with_message_count']:
        t['topic_metadata']['offered_qos_profiles'] = 'x'
    _rewrite_mcap(src, d / src.name, record_text=yaml.safe_dump(inner))
    cases[d] = 'M09'
    d = copy('count_mismatch')
    (d / 'metadata.yaml').write_text(meta_text.replace('  message_count: ', '  message_count: 1', 1))
    cases[d] = 'B05'
    chunks, _ = _chunks(src)
    d = copy('damaged_chunk')
    data = bytearray((d / src.name).read_bytes())
    off, length, _ = chunks[len(chunks) // 2]
    data[off + length // 2] ^= 0xFF
    (d / src.name).write_bytes(bytes(data))
    cases[d] = 'F14'
    d = copy('damaged_message_index')  # right after that chunk: its first index entry's time
    data = bytearray((d / src.name).read_bytes())
    data[off + length + 9 + 6 + 2] ^= 0x01
    (d / src.name).write_bytes(bytes(data))
    cases[d] = 'F12'
    d = copy('no_metadata')
    (d / 'metadata.yaml').unlink()
    cases[d] = 'B01'
    d = copy('unknown_policy')
    (d / 'metadata.yaml').write_text(meta_text.replace('reliability: reliable', 'reliability: sure', 1))
    cases[d] = 'M11'
    for d, rule in cases.items():
        report = check_bag(d)
        assert rule in _rules(report), (d.name, report.text())
        assert all(f.where and f.key for f in report.findings)
    # the line of a metadata refusal is the line of the offending key
    f = next(f for f in check_bag(tmp_path / 'qos_string').findings if f.rule == 'M09')
    lines = (tmp_path / 'qos_string' / 'metadata.yaml').read_text().splitlines()
    assert 'offered_qos_profiles' in lines[f.line - 1]


def test_recover_upgrades_an_old_format_bag_losslessly(tmp_path):
    _write(tmp_path / 'good', 120)
    (src,) = (tmp_path / 'good').glob('*.mcap')
    want = _messages(tmp_path / 'good')
    d = tmp_path / 'old'
    shutil.copytree(tmp_path / 'good', d)
    inner = yaml.safe_load((d / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    for t in inner['topics_with_message_count']:
        t['topic_metadata']['offered_qos_profiles'] = yaml.safe_dump(t['topic_metadata']['offered_qos_profiles'])
    _rewrite_mcap(src, d / src.name, qos_text='', record_text=yaml.safe_dump(inner))
    (d / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': inner}))
    assert check_bag(d).findings
    rep = recover_bag(d)
    assert rep.files[0].status == 'upgraded' and not rep.files[0].backup
    assert check_bag(d).findings == []
    assert _messages(d) == want
    assert (d / 'metadata.yaml.damaged').exists()  # the refused metadata.yaml is kept


# -- recovery corpus ---------------------------------------------------------------------------
def _chunks(path: Path):
    """(offset, length, [(topic, log_time, data)]) of each chunk of an intact file."""
    from sslfr_recording.bag.scan import chunk_records
    with open(path, 'rb') as fh:
        r = make_reader(fh)
        summary = r.get_summary()
    data = path.read_bytes()
    topics = {cid: c.topic for cid, c in summary.channels.items()}
    out = []
    for ci in summary.chunk_indexes:
        body = data[ci.chunk_start_offset + 9:ci.chunk_start_offset + ci.chunk_length]
        msgs = [(topics[m.channel_id], m.log_time, m.data) for m in chunk_records(body)[1]
                if hasattr(m, 'channel_id')]
        out.append((ci.chunk_start_offset, ci.chunk_length, msgs))
    return out, summary


def _intact_chunk(record: bytes) -> bool:
    """Independent check of one zstd Chunk record: decompresses, right size, CRC-32 matches."""
    import zlib

    import zstandard
    start, end, usize, crc, clen = struct.unpack_from('<QQQII', record, 9)
    off = 9 + 32 + clen
    (rlen,) = struct.unpack_from('<Q', record, off)
    try:
        payload = zstandard.ZstdDecompressor().decompress(record[off + 8:off + 8 + rlen],
                                                          max_output_size=usize)
    except zstandard.ZstdError:
        return False
    return len(payload) == usize and zlib.crc32(payload) == crc


def _recover_case(base: Path, name: str, data: bytes, mcap_name: str, meta_bytes: bytes | None,
                  expected: list, stats: dict) -> None:
    d = base / name
    d.mkdir()
    (d / mcap_name).write_bytes(data)
    if meta_bytes is not None:
        (d / 'metadata.yaml').write_bytes(meta_bytes)
    before = reader_count(d / mcap_name)
    try:
        rep = recover_bag(d)
    except Exception as exc:  # noqa: BLE001 - recorded as a failure of the case
        stats['failures'].append(f'{name}: {type(exc).__name__}: {exc}')
        return
    got = _messages(d)
    want = sorted(expected, key=lambda m: m[1])
    if got != want or len(got) < before:
        stats['failures'].append(f'{name}: {len(got)} messages after recovery, expected '
                                 f'{len(want)}, a reader got {before} before')
        return
    if rep.files[0].status not in ('ok',) and data != (d / mcap_name).read_bytes():
        backup = d / (mcap_name + '.damaged')
        if not backup.exists() or backup.read_bytes() != data:
            stats['failures'].append(f'{name}: the damaged original was not kept')
            return
    report = check_bag(d)
    if report.findings:
        stats['failures'].append(f'{name}: recovered bag does not conform: {report.text()}')
        return
    stats['cases'] += 1
    stats['rescued'] += len(got)
    stats['before'] += before


def test_recover_corpus_never_loses_a_readable_message(tmp_path):
    _write(tmp_path / 'src', 240)
    (src,) = (tmp_path / 'src').glob('*.mcap')
    data = src.read_bytes()
    meta = (tmp_path / 'src' / 'metadata.yaml').read_bytes()
    chunks, _ = _chunks(src)
    assert len(chunks) >= 10
    everything = [m for _, _, msgs in chunks for m in msgs]
    assert len(everything) == len(_messages(tmp_path / 'src'))
    (hdr_len,) = struct.unpack_from('<Q', data, 9)
    header_end = 8 + 9 + hdr_len
    stats = {'cases': 0, 'failures': [], 'rescued': 0, 'before': 0}
    base = tmp_path / 'corpus'
    base.mkdir()
    name = src.name
    # every byte of the magic and the header record, flipped
    for off in range(header_end):
        bad = bytearray(data)
        bad[off] ^= 0xFF
        _recover_case(base, f'hdr{off}', bytes(bad), name, meta, everything, stats)
    # the case: the header's length field set to 0xcd
    bad = bytearray(data)
    bad[10] = 0xCD
    _recover_case(base, 'hdr_len_cd', bytes(bad), name, meta, everything, stats)
    # one byte in the middle of each chunk: only that chunk is lost
    for i, (off, length, msgs) in enumerate(chunks):
        bad = bytearray(data)
        bad[off + length // 2] ^= 0x5A
        # lost unless the flip left the data intact (decompresses to bytes with its CRC)
        lost = set() if _intact_chunk(bytes(bad[off:off + length])) else set(map(id, msgs))
        _recover_case(base, f'chunk{i}', bytes(bad), name, meta,
                      [m for m in everything if id(m) not in lost], stats)
        # and the chunk's length field: the walk resynchronises after it, the chunk itself
        # is found through the summary's chunk index (its data and CRC are intact)
        bad = bytearray(data)
        bad[off + 5] ^= 0x40
        _recover_case(base, f'chunklen{i}', bytes(bad), name, meta, everything, stats)
        # its first message index entry (a log time): nothing lost, indexes rewritten
        bad = bytearray(data)
        bad[off + length + 9 + 6 + 2] ^= 0x01
        _recover_case(base, f'msgindex{i}', bytes(bad), name, meta, everything, stats)
    # bytes of the summary section and footer: nothing is lost
    summary_at = struct.unpack_from('<Q', data, len(data) - 8 - 20)[0]
    for k, off in enumerate(range(summary_at, len(data), max(1, (len(data) - summary_at) // 12))):
        bad = bytearray(data)
        bad[off] ^= 0xFF
        _recover_case(base, f'summary{k}', bytes(bad), name, meta, everything, stats)
    # truncations: every complete chunk before the cut survives
    cuts = sorted({header_end + (len(data) - header_end) * k // 60 for k in range(1, 60)})
    for cut in cuts:
        expected = [m for off, length, msgs in chunks if off + length <= cut for m in msgs]
        _recover_case(base, f'cut{cut}', data[:cut], name, None, expected, stats)
    # metadata.yaml missing, binary (a PNG), of the wrong YAML types
    _recover_case(base, 'meta_missing', data, name, None, everything, stats)
    _recover_case(base, 'meta_png', data, name, b'\x89PNG\r\n\x1a\n' + bytes(range(256)),
                  everything, stats)
    _recover_case(base, 'meta_types', data, name,
                  b'rosbag2_bagfile_information:\n  version: 9\n  topics_with_message_count: 5\n',
                  everything, stats)
    total = stats['cases'] + len(stats['failures'])
    print(f'recover corpus: {total} damaged copies, {stats["cases"]} recovered as expected, '
          f'{stats["rescued"]} messages rescued vs {stats["before"]} readable before')
    assert not stats['failures'], '\n'.join(stats['failures'][:10])
    assert total >= 150
    assert stats['rescued'] > stats['before']  # recovery rescues more than a reader got
