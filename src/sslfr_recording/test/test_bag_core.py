"""Unit tests of the pure bag core: schemas, QoS, metadata, writer, readers, recovery,
policies. Independent references: rosbags (pure-Python rosbag2 reader + typestore) and
mcap + mcap-ros2-support decoding through the recorded schemas."""
from __future__ import annotations

import datetime as dt
import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, strategies as st
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from sensor_msgs.msg import JointState, Temperature
from sslfr_interfaces.msg import AxisStatus, SafetyState

from sslfr_recording.bag import (BagError, BagReader, BagWriter, DefinitionCache, DiskGuard,
                               SplitPolicy, WriterOptions, bag_name, dump_profiles,
                               load_profiles, profile, read_metadata, recover_bag)
from sslfr_recording.bag.schema import SEPARATOR, parse_dependencies
from sslfr_recording.bag.session import RecordingSession

sys.path.insert(0, str(Path(__file__).parent))

T0 = 1_782_000_000 * 10**9  # 2026-06-21


def _messages(n=300):
    """(topic, type, msg) triples of several types, with varied content.

    Each message is serialized once (:data:`_SER`): rclpy/Fast-CDR leaves alignment
    padding bytes uninitialised, so two serializations of one message may differ in
    padding; comparisons are against the bytes that were written."""
    out = []
    for i in range(n):
        t = Temperature(temperature=20.0 + i * 0.5, variance=0.01)
        t.header.stamp.sec, t.header.frame_id = 1000 + i, 'absorber_outlet'
        out.append(('/absorber/outlet_temperature', 'sensor_msgs/msg/Temperature', t))
        a = AxisStatus(axis='mirrors', state='active', commanded=0.1 * i, setpoint=0.1 * i,
                       measured=0.1 * i + 1e-3, error=1e-3, steps=i * 7, link_state=2,
                       frames_lost=i // 10, board_info='axis-board 1.2')
        out.append(('/axes/mirrors/status', 'sslfr_interfaces/msg/AxisStatus', a))
        if i % 10 == 0:
            s = SafetyState(level=i % 4, reasons=[f'r{i}', 'x' * (i % 7)], stopped_axes=['mirrors'] * (i % 2),
                            sequence=i)
            out.append(('/safety/state', 'sslfr_interfaces/msg/SafetyState', s))
            j = JointState(name=['mirrors', 'mobile_structure'], position=[0.1 * i, -0.2],
                           velocity=[0.0, 1e-3], effort=[0.5, 0.0])
            out.append(('/joint_states', 'sensor_msgs/msg/JointState', j))
    for _, _, m in out:
        _SER[id(m)] = bytes(serialize_message(m))
    return out


_SER: dict[int, bytes] = {}


def ser(m) -> bytes:
    return _SER[id(m)]


def same(ros_msg, other) -> bool:
    """Field-by-field equality of an rclpy message and a decoded one (any reader)."""
    if hasattr(ros_msg, 'get_fields_and_field_types'):
        return all(same(getattr(ros_msg, f), getattr(other, f))
                   for f in ros_msg.get_fields_and_field_types())
    if isinstance(other, (list, tuple, np.ndarray)) or isinstance(ros_msg, (list, tuple, np.ndarray)):
        a, b = list(ros_msg), list(other)
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return ros_msg == other


def _write(directory, msgs, options=None):
    w = BagWriter(directory, options or WriterOptions(fsync=False))
    for topic, typ, _ in msgs:
        w.add_topic(topic, typ, [profile(durability='transient_local' if 'safety' in topic else 'volatile')])
    for k, (topic, _, m) in enumerate(msgs):
        w.write(topic, ser(m), T0 + k * 10_000_000, T0 + k * 10_000_000 - 5, sequence=k)
    return w.close()


# -- schemas -----------------------------------------------------------------------------
def test_schema_text_is_rosbag2_concatenation():
    text = DefinitionCache().full_text('sslfr_interfaces/msg/AxisStatus')
    share = Path(os.environ['AMENT_PREFIX_PATH'].split(':')[-1]) / 'share'
    own = DefinitionCache().msg_file('sslfr_interfaces/AxisStatus').read_text()
    assert text.startswith(own)
    header = (share / 'std_msgs/msg/Header.msg').read_text()
    time_ = (share / 'builtin_interfaces/msg/Time.msg').read_text()
    assert text == own + '\n' + SEPARATOR + 'MSG: std_msgs/Header\n' + header + '\n' + SEPARATOR + \
        'MSG: builtin_interfaces/Time\n' + time_
    # each dependency once, even when reached twice (LimitSwitches: Header + 5 x Time)
    ls = DefinitionCache().full_text('sslfr_interfaces/msg/LimitSwitches')
    assert ls.count('MSG: builtin_interfaces/Time\n') == 1


def test_parse_dependencies_rule():
    deps = parse_dependencies('uint8 A=1\n# Foo/Bar comment\nHeader h\nstd_msgs/String[] s\n'
                              'float64[3] x\ngeometry_msgs/Point[<=5] p\n', 'pkg')
    assert deps == {'pkg/Header', 'std_msgs/String', 'geometry_msgs/Point'}


@pytest.mark.parametrize('typ', ['sensor_msgs/msg/NavSatFix', 'sensor_msgs/msg/JointState',
                                 'trajectory_msgs/msg/JointTrajectory',
                                 'diagnostic_msgs/msg/DiagnosticArray', 'rosgraph_msgs/msg/Clock'])
def test_schema_parses_like_rosbags_jazzy_store(typ):
    """Our schema text, parsed by rosbags, gives the same field layout as rosbags' own
    Jazzy type store (an independent definition source)."""
    ours = get_types_from_msg(DefinitionCache().full_text(typ), typ)
    ref = get_typestore(Stores.ROS2_JAZZY)
    for name, (consts, fields) in ours.items():
        assert name in ref.fielddefs, name
        ref_fields = ref.fielddefs[name][1]
        assert [f[0] for f in fields] == [f[0] for f in ref_fields], name


# -- QoS ---------------------------------------------------------------------------------
@given(st.lists(st.tuples(st.sampled_from(['reliable', 'best_effort']),
                          st.sampled_from(['volatile', 'transient_local']),
                          st.integers(0, 1000)), max_size=4))
def test_qos_roundtrip(items):
    profs = [profile(r, d, n) for r, d, n in items]
    text = dump_profiles(profs)
    assert load_profiles(text) == profs
    assert (text == '[]') == (not profs)  # rosbag2 writes [] for no profile


def test_qos_v8_integers_are_read():
    text = ('- history: 1\n  depth: 5\n  reliability: 2\n  durability: 1\n  deadline:\n    sec: 0\n'
            '    nsec: 0\n  lifespan:\n    sec: 0\n    nsec: 0\n  liveliness: 1\n'
            '  liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n  avoid_ros_namespace_conventions: false')
    (p,) = load_profiles(text)
    assert (p['history'], p['reliability'], p['durability'], p['depth']) == \
        ('keep_last', 'best_effort', 'transient_local', 5)


# -- writer + two independent readers ----------------------------------------------------
def test_bag_read_back_by_rosbags_and_mcap_ros2(tmp_path):
    msgs = _messages()
    _write(tmp_path / 'bag', msgs)
    meta = read_metadata(tmp_path / 'bag')
    assert meta.version == 9 and meta.message_count == len(msgs)
    # reader 1: rosbags (metadata.yaml + its own MCAP parser + typestore from the msgdefs)
    store = get_typestore(Stores.EMPTY)
    got = []
    with RosbagsReader(tmp_path / 'bag') as r:
        assert r.message_count == len(msgs)
        for c in r.connections:
            store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
            assert c.ext.offered_qos_profiles[0].depth == 10
        for c, t, raw in r.messages():
            got.append((c.topic, t, bytes(raw), store.deserialize_cdr(raw, c.msgtype)))
    assert len(got) == len(msgs)
    for k, ((topic, _, m), (rt, t, raw, dec)) in enumerate(zip(msgs, got)):
        assert rt == topic and t == T0 + k * 10_000_000
        assert raw == ser(m)
        assert same(m, dec), topic
    # reader 2: mcap + mcap_ros2, decoding every message through the recorded schema
    (mcap_file,) = (tmp_path / 'bag').glob('*.mcap')
    with open(mcap_file, 'rb') as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        decoded = list(reader.iter_decoded_messages(log_time_order=True))
    assert len(decoded) == len(msgs)
    for (topic, typ, m), (schema, channel, message, dec) in zip(msgs, decoded):
        assert channel.topic == topic and schema.name == typ and schema.encoding == 'ros2msg'
        assert channel.message_encoding == 'cdr'
        assert 'offered_qos_profiles' in channel.metadata and 'topic_type_hash' in channel.metadata
        assert message.data == ser(m)
        assert same(m, dec), topic


def test_split_by_size_and_duration(tmp_path):
    msgs = _messages(600)
    meta = _write(tmp_path / 'b', msgs, WriterOptions(fsync=False, chunk_size=4096,
                                                      split=SplitPolicy(max_bytes=20_000)))
    assert len(meta.files) >= 3
    assert sum(f.message_count for f in meta.files) == len(msgs)
    with RosbagsReader(tmp_path / 'b') as r:
        assert sum(1 for _ in r.messages()) == len(msgs)
    assert [m.data for m in BagReader(tmp_path / 'b').messages()] == \
        [ser(m) for _, _, m in msgs]
    meta = _write(tmp_path / 'c', msgs, WriterOptions(fsync=False, split=SplitPolicy(max_duration_s=3.0)))
    # 1410 messages 10 ms apart = 14.1 s -> 5 files of <= 3 s
    assert len(meta.files) == 5
    assert all(f.duration_ns < 3e9 for f in meta.files)


def test_chunk_age_bound_and_crash_recovery(tmp_path):
    clock = [0.0]
    w = BagWriter(tmp_path / 'b', WriterOptions(fsync=False, chunk_duration_s=2.0),
                  monotonic=lambda: clock[0])
    w.add_topic('/t', 'sensor_msgs/msg/Temperature', [profile()])
    data = bytes(serialize_message(Temperature(temperature=1.0)))
    for k in range(100):       # 10 Hz for 10 s of monotonic time
        clock[0] = k * 0.1
        w.write('/t', data, T0 + k * 100_000_000)
    clock[0] = 10.05
    w.poll()                   # nothing written for < 2 s stays in memory
    w.abort()                  # SIGKILL-like: no summary, no metadata.yaml
    with pytest.raises(BagError, match='recover'):
        BagReader(tmp_path / 'b')
    rep = recover_bag(tmp_path / 'b')
    kept = rep.metadata.message_count
    assert rep.files[0].status == 'rebuilt'
    assert 80 <= kept < 100    # at most the last 2 s (20 messages) lost
    r = BagReader(tmp_path / 'b')
    times = [m.log_time for m in r.messages()]
    assert times == [T0 + k * 100_000_000 for k in range(kept)]
    with RosbagsReader(tmp_path / 'b') as rr:
        assert rr.message_count == kept


def test_truncation_anywhere_never_crashes_recovery(tmp_path):
    msgs = _messages(200)
    _write(tmp_path / 'src', msgs, WriterOptions(fsync=False, chunk_size=2048))
    (src,) = (tmp_path / 'src').glob('*.mcap')
    data = src.read_bytes()
    counts = []
    for cut in range(20, len(data), max(1, len(data) // 23)):
        d = tmp_path / f'cut{cut}'
        d.mkdir()
        (d / f'cut{cut}_0.mcap').write_bytes(data[:cut])
        try:
            rep = recover_bag(d)
        except BagError as exc:          # only when not even the header survived
            assert 'no readable' in str(exc)
            continue
        n = rep.metadata.message_count
        got = [m.data for m in BagReader(d).messages()]
        assert got == [ser(m) for _, _, m in msgs[:n]]  # a prefix, intact
        counts.append(n)
    assert counts == sorted(counts) and counts[-1] > 0


def test_corrupt_chunk_is_dropped_and_reader_error_is_clear(tmp_path, capsys):
    msgs = _messages(200)
    _write(tmp_path / 'b', msgs, WriterOptions(fsync=False, chunk_size=2048, compression='none'))
    (f,) = (tmp_path / 'b').glob('*.mcap')
    data = bytearray(f.read_bytes())
    mid = len(data) // 3
    data[mid:mid + 16] = b'\xff' * 16        # flip bytes inside a chunk
    f.write_bytes(bytes(data))
    with pytest.raises(BagError, match='recover'):
        list(BagReader(tmp_path / 'b').messages())
    from sslfr_recording import bag_cli
    rep = recover_bag(tmp_path / 'b', verify=True)
    assert rep.files[0].chunks_bad == 1
    kept = [m.data for m in BagReader(tmp_path / 'b').messages()]
    assert 0 < len(kept) < len(msgs)
    # the damaged original is kept beside the rebuilt file, byte for byte
    assert (tmp_path / 'b' / (f.name + '.damaged')).read_bytes() == bytes(data)
    # garbage is a clear error, never a traceback
    (tmp_path / 'g').mkdir()
    (tmp_path / 'g' / 'g_0.mcap').write_bytes(b'not an mcap file at all')
    assert bag_cli.main(['info', str(tmp_path / 'g')]) == 2
    assert bag_cli.main(['recover', str(tmp_path / 'g')]) == 2
    err = capsys.readouterr().err
    assert 'metadata.yaml: missing' in err and 'no readable .mcap file' in err
    (tmp_path / 'm').mkdir()
    (tmp_path / 'm' / 'metadata.yaml').write_text('rosbag2_bagfile_information: [1, 2')
    assert bag_cli.main(['info', str(tmp_path / 'm')]) == 2
    assert 'metadata.yaml:1' in capsys.readouterr().err


# -- policies and session -----------------------------------------------------------------
def test_disk_guard_threshold_and_hysteresis():
    g = DiskGuard(min_free_bytes=100, min_free_fraction=0.1, hysteresis_bytes=10)
    assert g.threshold(500) == 100 and g.threshold(5000) == 500
    assert g.evaluate(600, 5000).ok
    s = g.evaluate(499, 5000)
    assert not s.ok and 'recording stopped' in s.message
    assert not g.evaluate(505, 5000).ok      # hysteresis: needs 510
    assert g.evaluate(510, 5000).ok


def test_session_day_rollover_disk_guard_and_resume(tmp_path):
    free = [10**12]
    guard = DiskGuard(min_free_bytes=10**9, min_free_fraction=0.0, hysteresis_bytes=0)
    clock = [0.0]
    s = RecordingSession(tmp_path, 'sslfr', options=WriterOptions(fsync=False), guard=guard,
                         disk_check_period_s=1.0, monotonic=lambda: clock[0],
                         disk_check=lambda p: guard.evaluate(free[0], 10**13))
    s.add_topic('/t', 'sensor_msgs/msg/Temperature', [profile()])
    data = bytes(serialize_message(Temperature()))
    midnight = int(dt.datetime(2026, 6, 22, tzinfo=dt.timezone.utc).timestamp()) * 10**9
    for k in range(-5, 5):                     # across midnight UTC
        assert s.write('/t', data, midnight + k * 10**9)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['sslfr_2026-06-21', 'sslfr_2026-06-22']
    assert read_metadata(tmp_path / 'sslfr_2026-06-21').message_count == 5
    free[0] = 10**8                            # disk nearly full
    clock[0] = 2.0
    s.poll()
    assert not s.recording
    assert not s.write('/t', data, midnight + 6 * 10**9)
    assert s.stats.dropped_disk == 1
    assert read_metadata(tmp_path / 'sslfr_2026-06-22').message_count == 5  # closed cleanly
    free[0] = 10**12
    clock[0] = 4.0
    s.poll()
    assert s.recording and s.write('/t', data, midnight + 7 * 10**9)
    s.close()
    meta = read_metadata(tmp_path / 'sslfr_2026-06-22')           # same day bag continued
    assert meta.message_count == 6 and len(meta.files) == 2
    assert bag_name('x', midnight - 1) == 'x_2026-06-21'


# -- what-if comparison and report on bags -------------------------------------------------
def test_whatif_comparison_on_bags(tmp_path):
    from daybag import SUNRISE, write_day

    from sslfr_recording.bag.whatif import compare_bags
    start, end = SUNRISE - 900, SUNRISE + 300
    write_day(tmp_path / 'a', start, end, traj_period=60)
    write_day(tmp_path / 'b', start, end, traj_period=60)
    write_day(tmp_path / 'c', start, end, traj_period=60, phase_offset=120.0)
    same = compare_bags(BagReader(tmp_path / 'a'), BagReader(tmp_path / 'b'))
    assert same.phase.agreement == 1.0 and same.safety.agreement == 1.0
    assert same.trajectory['mirrors']['max'] == 0.0
    assert len(same.phase.matched) == 2 and not same.phase.unmatched_recorded
    diff = compare_bags(BagReader(tmp_path / 'a'), BagReader(tmp_path / 'c'))
    assert [round(d) for *_, d in diff.phase.matched] == [120, 120]   # NIGHT->PRE_DAWN->TRACKING
    assert diff.phase.agreement == pytest.approx(1 - 240 / 1200, abs=3e-3)
    assert 'new run +120.0 s' in diff.text()


def test_report_figures_on_a_known_day(tmp_path):
    from daybag import SUNRISE, SUNSET, STOW, expected_H, write_day

    from sslfr_recording import report, report_cli
    start, end = STOW[0] - 1800, STOW[0] + 1800
    write_day(tmp_path / 'd', start, end, err_amp=0.002)
    rep = report.analyse(BagReader(tmp_path / 'd'))
    assert rep.events['sunrise'] == SUNRISE and rep.events['sunset'] == SUNSET
    assert rep.phase_time == {'TRACKING': pytest.approx(3600 - 1, abs=1.5)}
    e = rep.tracking['mirrors']['setpoint']
    assert e.rms == pytest.approx(0.002 / math.sqrt(2), rel=0.01)
    assert e.max == pytest.approx(0.002, rel=1e-3)
    (stow,) = rep.stows
    assert stow['start'] == STOW[0] and stow['duration'] == pytest.approx(600)
    assert 'outlet' in stow['reasons'][0]
    assert rep.temperatures['outlet_temperature']['max'] == pytest.approx(152.0)
    assert rep.irradiance['H_kWh_m2'] == pytest.approx(expected_H(start, end - 1), rel=1e-4)
    assert report_cli.main([str(tmp_path / 'd'), '--out', str(tmp_path / 'r')]) == 0
    md = (tmp_path / 'r' / 'report.md').read_text()
    for png in ('angles', 'tracking_error', 'temperatures', 'irradiance'):
        assert (tmp_path / 'r' / f'{png}.png').stat().st_size > 5000 and f'({png}.png)' in md


def test_report_accuracy_times_and_timeline_of_warnings(tmp_path):
    """A known error profile: 0.1 deg from 10:00, 0.5 deg from 10:30, 0 from 10:40 (the
    mirrors following): by hand, the 60 s RMS passes 0.06 deg at 10:00:22 (sqrt(k/60) 0.1
    > 0.06), 0.36 deg at 10:30:30, falls below 0.8 x 0.36 at 10:40:41 and below
    0.8 x 0.06 at 10:41:00; and /rosout lines listed at their log times beside the phase
    and safety changes, repeats collapsed, INFO left out."""
    from daybag import DAY0, STOW, write_day

    from sslfr_recording import report, report_render
    h10 = DAY0 + 10 * 3600

    def err(t):
        return math.radians(0.1 if h10 <= t < h10 + 1800 else 0.5 if h10 + 1800 <= t < h10 + 2400 else 0.0)
    logs = [(h10 + 22.5, 30, 'mirrors_driver', 'mirrors: tracking error 0.061 deg ...'),
            (h10 + 100.0, 20, 'planner', 'an INFO line'),
            (STOW[0] + 0.2, 40, 'safety', 'STOW: absorber: outlet 152.0 degC > 150 degC'),
            *[(STOW[0] + k, 30, 'mirrors_driver', 'link lost') for k in (1, 2, 3)],
            (STOW[0] + 4, 30, 'safety', 'link lost')]
    write_day(tmp_path / 'd', h10 - 600, STOW[1] + 60, error_of=err, state='following', logs=logs)
    rep = report.analyse(BagReader(tmp_path / 'd'))
    acc = rep.accuracy['mirrors']
    assert acc['warn_s'] == pytest.approx(41 * 60 - 22, abs=2)
    assert acc['error_s'] == pytest.approx(10 * 60 + 41 - 30, abs=2)
    assert math.degrees(acc['peak']) == pytest.approx(0.5, abs=1e-6)
    assert [lvl for _, lvl, _ in acc['changes']] == [1, 2, 1, 0]
    kinds = [(report_render.utc(t), kind, text, n) for t, kind, text, n, _ in rep.timeline]
    assert ('10:00:22', 'WARN', 'mirrors_driver: mirrors: tracking error 0.061 deg ...', 1) in kinds
    assert ('13:00:00', 'safety', 'STOW: absorber: outlet 152.0 degC > 150 degC', 1) in kinds
    assert ('13:00:00', 'ERROR', 'safety: STOW: absorber: outlet 152.0 degC > 150 degC', 1) in kinds
    assert ('13:00:01', 'WARN', 'mirrors_driver: link lost', 3) in kinds      # repeats collapsed
    assert ('13:00:04', 'WARN', 'safety: link lost', 1) in kinds
    assert ('13:10:00', 'safety', 'OK', 1) in kinds
    assert not any('INFO' in k[2] for k in kinds)
    assert [k[0] for k in kinds] == sorted(k[0] for k in kinds)
    assert rep.log_counts == {('WARN', 'mirrors_driver'): 4, ('ERROR', 'safety'): 1, ('WARN', 'safety'): 1}
    text = report_render.render_text(rep)
    assert f'mirrors              {acc["warn_s"]:8.0f} s / {acc["error_s"]:6.0f} s of ' in text, text
    assert '13:00:01  WARN   mirrors_driver: link lost (x3 until 13:00:03)' in text
    assert 'log lines: ERROR 1 (safety 1); WARN 5 (mirrors_driver 4, safety 1)' in text


def test_playback_helpers():
    from sslfr_recording.bag.playback import Timeline, parse_time_spec
    from sslfr_recording.replay import remap_table
    from sslfr_planner.cli_input import CliError
    s = T0
    assert parse_time_spec('90', s) == s + 90 * 10**9
    assert parse_time_spec('-10', s, s + 100 * 10**9) == s + 90 * 10**9
    day = dt.datetime.fromtimestamp(s / 1e9, tz=dt.timezone.utc).replace(hour=12, minute=30)
    assert parse_time_spec('12:30', s) == int(day.replace(second=0, microsecond=0).timestamp()) * 10**9
    assert parse_time_spec('2026-06-21T12:00:00Z', s) == 1782043200 * 10**9
    with pytest.raises(ValueError):
        parse_time_spec('noon', s)
    assert remap_table([('gps/fix', '/other/fix')], ['/gps/fix', '/a']) == {'/gps/fix': '/other/fix'}
    assert remap_table([('gps/fix', 'rel')], ['/gps/fix']) == {'/gps/fix': 'rel'}
    with pytest.raises(CliError, match='no topic /x'):
        remap_table([('x', '/y')], ['/gps/fix'])
    with pytest.raises(CliError, match='both be published on /a'):
        remap_table([('gps/fix', '/a')], ['/gps/fix', '/a'])
    tl = Timeline(s, 100.0, 1000.0)
    assert tl.due(s + 10**12) == pytest.approx(101.0) and tl.bag_time(101.0) == s + 10**12


def test_bag_info_prints_what_ros2_bag_info_prints(tmp_path, monkeypatch, capsys):
    """`sslfr bag info` against the text rosbag2 Jazzy prints (rosbag2_py
    src/rosbag2_py/format_bag_metadata.cpp, ``format_bag_meta_data``: the field names
    padded to 19 columns, ``format_file_size`` with one decimal in KiB, times as
    ``%b %e %Y %H:%M:%S.<ns> (<s>.<ns>)`` in local time, continuation lines indented
    19, then ``Service:`` and ``Service information:``), plus our QoS block."""
    import time as _time
    from sslfr_bringup import cli
    from sslfr_recording.bag.reader import format_size
    from sensor_msgs.msg import Temperature
    from rclpy.serialization import serialize_message

    monkeypatch.setenv('TZ', 'UTC')
    _time.tzset()
    try:
        bag = tmp_path / 'day'
        w = BagWriter(bag, WriterOptions(fsync=False))
        for t in ('/t', '/u2'):
            w.add_topic(t, 'sensor_msgs/msg/Temperature', [profile()])
        for k in range(20):
            for t in ('/t', '/u2'):
                w.write(t, bytes(serialize_message(Temperature(temperature=float(k)))), 10**18 + k * 10**8)
        w.close()
        assert cli.main(['bag', 'info', str(bag)]) == 0
        out = capsys.readouterr().out
    finally:
        monkeypatch.delenv('TZ')
        _time.tzset()
    size = sum(p.stat().st_size for p in bag.rglob('*') if p.is_file())
    assert out.splitlines() == [
        '',
        'Files:             day_0.mcap',
        f'Bag size:          {format_size(size)}',
        'Storage id:        mcap',
        'ROS Distro:        jazzy',
        'Duration:          1.900000000s',
        'Start:             Sep  9 2001 01:46:40.000000000 (1000000000.000000000)',
        'End:               Sep  9 2001 01:46:41.900000000 (1000000001.900000000)',
        'Messages:          40',
        'Topic information: Topic: /t | Type: sensor_msgs/msg/Temperature | Count: 20 | Serialization Format: cdr',
        '                   Topic: /u2 | Type: sensor_msgs/msg/Temperature | Count: 20 | Serialization Format: cdr',
        'Service:           0',
        'Service information: ',
        'Offered QoS:       /t: reliable volatile keep_last 10 (1 publisher(s))',
        '                   /u2: reliable volatile keep_last 10 (1 publisher(s))',
    ]
    assert format_size(size).endswith(' KiB') and format_size(512) == '512 B' and format_size(1536) == '1.5 KiB'


def test_recorder_keeps_rosout_but_not_its_own_history():
    """/rosout is recorded like any topic; lines older than the recorder (a publisher's
    transient-local history re-sent to a restarted recorder) are not."""
    from sslfr_recording.bag import recorder_config as rc
    assert rc.wanted('/rosout', [], ['/clock'])
    assert not rc.wanted('/parameter_events', [], [])
    assert not rc.wanted('/rosout', [], ['/rosout'])          # still excludable
    start = 1_782_000_000 * 10**9
    assert rc.log_line_kept(start + 1, start) and rc.log_line_kept(start, start)
    assert not rc.log_line_kept(start - 5 * 10**9, start)
    assert rc.log_line_kept(0, start)                          # no source timestamp: kept
