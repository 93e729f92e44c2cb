"""Topic-level tests of the recorder, replay and recovery (issue 8).

Messages are created in the test process with existing types (sensor_msgs,
sslfr_interfaces, ...) and published as serialized bytes, so the bytes in the bag can
be compared exactly. Readers used for checking: rosbags (independent rosbag2 reader)
and mcap + mcap_ros2 (decoding through the recorded schemas).
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rcl_interfaces.msg import Log
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import Temperature
from sslfr_interfaces.msg import AxisStatus, TrackerPhase
from sslfr_common.contract import ABSORBER_TEMPERATURE, AXIS_STATUS, DIAGNOSTICS, TRACKER_PHASE
from sslfr_common.node import qos

ROOT = Path(__file__).resolve().parents[1]

from sslfr_recording.bag import BagReader, BagWriter, WriterOptions, profile  # noqa: E402
from sslfr_recording.bag.conformance import check_bag  # noqa: E402

TL1 = qos(TRACKER_PHASE)


def dds_padded(data: bytes) -> bytes:
    """What a subscriber receives for published CDR bytes: the DDS layer pads the
    serialized payload with zeros to a multiple of 4 bytes (rosbag2 records the same)."""
    return data + b'\0' * (-len(data) % 4)


def _bag_dirs(root: Path) -> list[Path]:
    return sorted(p for p in root.iterdir() if p.is_dir()) if root.exists() else []


def _read_rosbags(bag: Path) -> list[tuple[str, int, bytes, object]]:
    store = get_typestore(Stores.EMPTY)
    out = []
    with RosbagsReader(bag) as r:
        for c in r.connections:
            store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        for c, t, raw in r.messages():
            out.append((c.topic, t, bytes(raw), store.deserialize_cdr(raw, c.msgtype)))
    return out


def _read_mcap_ros2(bag: Path) -> list[tuple[str, int, bytes, object]]:
    out = []
    for f in sorted(bag.glob('*.mcap')):
        with open(f, 'rb') as fh:
            for schema, ch, msg, dec in make_reader(fh, decoder_factories=[DecoderFactory()]) \
                    .iter_decoded_messages(log_time_order=True):
                out.append((ch.topic, msg.log_time, msg.data, dec))
    return out


def _wait_matched(ros, pubs, timeout=15.0):
    assert ros.spin_until(lambda: all(p.get_subscription_count() > 0 for p in pubs), timeout), \
        'recorder did not subscribe'


def _publish(ros, pub, value: float, n: int) -> None:
    for _ in range(n):
        pub.publish(Temperature(temperature=value))
        ros.spin_for(0.05)


def _diag_error(diags, text: str):
    """Predicate: some diagnostics status is ERROR with ``text`` in its message."""
    from diagnostic_msgs.msg import DiagnosticStatus
    return lambda: any(s.level == DiagnosticStatus.ERROR and text in s.message
                       for d in diags for s in d.status)


def _sslfr(args, env, timeout=60):
    return subprocess.run([str(ROOT / 'sslfr'), *args], env=env, capture_output=True, text=True,
                          timeout=timeout)


def test_recorder_bag_read_back_by_two_readers(launch, ros, tmp_path):
    rec = launch('sslfr_recording', 'recorder', params={
        'output_dir': str(tmp_path / 'bags'), 'chunk_duration': 0.5, 'fsync': False,
        'discovery_period': 0.2, 'exclude': ['/diagnostics']})
    node = ros.node
    p_temp = node.create_publisher(Temperature, ABSORBER_TEMPERATURE.of('outlet'), 10)
    p_axis = node.create_publisher(AxisStatus, AXIS_STATUS.of('mirrors'), 10)
    p_phase = node.create_publisher(TrackerPhase, TRACKER_PHASE.name, TL1)
    _wait_matched(ros, [p_temp, p_axis, p_phase])
    sent = {'/absorber/outlet_temperature': [], '/axes/mirrors/status': [], '/tracker/phase': []}
    for i in range(60):  # 20 Hz for 3 s
        t = Temperature(temperature=100.0 + i, variance=0.25)
        t.header.stamp = node.get_clock().now().to_msg()
        a = AxisStatus(axis='mirrors', state='active', setpoint=0.01 * i, measured=0.01 * i + 1e-4,
                       error=1e-4, steps=i, link_state=2, board_info='axis 1.0')
        for pub, topic, m in ((p_temp, '/absorber/outlet_temperature', t),
                              (p_axis, '/axes/mirrors/status', a)):
            data = bytes(serialize_message(m))
            pub.publish(data)
            sent[topic].append((data, m))
        if i % 10 == 0:
            ph = TrackerPhase(phase=2, phase_name='TRACKING', mode='auto', reason=f'step {i}')
            data = bytes(serialize_message(ph))
            p_phase.publish(data)
            sent['/tracker/phase'].append((data, ph))
        ros.spin_for(0.05)
    node.get_logger().warning('a line for the bag')      # /rosout: the nodes' log lines
    ros.spin_for(1.0)
    assert rec.stop() == 0
    (bag,) = _bag_dirs(tmp_path / 'bags')
    assert (bag / 'metadata.yaml').exists()
    lines = [(dec.level, dec.name, dec.msg) for tp, _, _, dec in _read_rosbags(bag) if tp == '/rosout']
    assert (30, node.get_name(), 'a line for the bag') in lines, lines
    assert any(name == 'recorder' and 'recording /rosout' in msg for _, name, msg in lines), lines
    for reader in (_read_rosbags, _read_mcap_ros2):
        got = reader(bag)
        for topic, items in sent.items():
            mine = [(raw, dec) for tp, _, raw, dec in got if tp == topic]
            assert len(mine) == len(items), (reader.__name__, topic)
            for (raw, _), (d, _) in zip(mine, items):
                assert raw == dds_padded(d), (reader.__name__, topic)
            for (_, dec), (_, m) in zip(mine, items):
                if topic == '/absorber/outlet_temperature':
                    assert dec.temperature == m.temperature and dec.header.stamp.sec == m.header.stamp.sec
                elif topic == '/axes/mirrors/status':
                    assert (dec.axis, dec.steps, dec.measured, dec.board_info) == \
                        (m.axis, m.steps, m.measured, m.board_info)
                else:
                    assert dec.reason == m.reason
    info = BagReader(bag).topics
    assert info['/tracker/phase'].offered_qos_profiles[0]['durability'] == 'transient_local'
    # rosbag2 Jazzy's reading rules (metadata v9, QoS maps, ros2 profile, hashes, indexes)
    report = check_bag(bag)
    assert report.findings == [], report.text()
    assert all(t.type_description_hash.startswith('RIHS01_') for t in report.metadata.topics.values())


def test_record_replay_round_trip_lossless(launch, ros, ros_env, tmp_path):
    # bag 1, written directly: 3 topics, 4 s, known bytes and times (bytes padded as a
    # recorder receives them from DDS)
    t0 = 1_782_043_200 * 10**9  # 2026-06-21 12:00 UTC
    w = BagWriter(tmp_path / 'one', WriterOptions(fsync=False))
    w.add_topic('/absorber/inlet_temperature', 'sensor_msgs/msg/Temperature', [profile()])
    w.add_topic('/axes/mirrors/status', 'sslfr_interfaces/msg/AxisStatus', [profile()])
    w.add_topic('/tracker/phase', 'sslfr_interfaces/msg/TrackerPhase',
                [profile(durability='transient_local', depth=1)])
    w.add_topic('/rosout', 'rcl_interfaces/msg/Log', [profile(durability='transient_local', depth=1000)])
    for k in range(80):  # 20 Hz
        tk = t0 + k * 50_000_000
        m = Temperature(temperature=50.0 + k)
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(tk, 10**9)
        w.write('/absorber/inlet_temperature', dds_padded(serialize_message(m)), tk)
        w.write('/axes/mirrors/status',
                dds_padded(serialize_message(AxisStatus(axis='mirrors', steps=k))), tk + 1_000_000)
        if k % 20 == 0:
            w.write('/tracker/phase',
                    dds_padded(serialize_message(TrackerPhase(phase=2, reason=str(k)))), tk + 2_000_000)
        if k % 30 == 10:   # the day's log lines: replayed on /rosout, as ros2 bag play does
            w.write('/rosout', dds_padded(serialize_message(Log(level=30, name='day_node', msg=f'line {k}'))),
                    tk + 3_000_000)
    w.close()
    rec = launch('sslfr_recording', 'recorder', params={
        'output_dir': str(tmp_path / 'two'), 'chunk_duration': 0.5, 'fsync': False,
        'discovery_period': 0.2, 'use_sim_time': True,
        'topics': ['/absorber/inlet_temperature', '/axes/mirrors/status', '/tracker/phase', '/rosout']})
    diags = ros.collect(DiagnosticArray, DIAGNOSTICS.name)
    out = _sslfr(['replay', str(tmp_path / 'one'), '--rate', '1', '--no-progress',
                  '--wait-subscribers', '15'], ros_env)
    assert out.returncode == 0, out.stderr
    assert 'replayed 167 messages' in out.stdout

    def written():   # the recorder's own count (diagnostics, 1 Hz)
        for arr in reversed(diags):
            for st in arr.status:
                if st.name.endswith(': recording'):
                    return int({kv.key: kv.value for kv in st.values}.get('written', 0))
        return 0
    assert ros.spin_until(lambda: written() >= 167, 15), written()
    assert rec.stop() == 0
    (bag2,) = _bag_dirs(tmp_path / 'two')
    assert bag2.name == 'sslfr_2026-06-21'          # sim time: the recorded day
    a = list(BagReader(tmp_path / 'one').messages())
    # the second recorder's /rosout also holds the live nodes' own lines (recorder, replay)
    b = [m for m in BagReader(bag2).messages()
         if m.topic != '/rosout' or deserialize_message(m.data, Log).name == 'day_node']
    assert len(b) == len(a)
    for topic in {m.topic for m in a}:
        ma = [m for m in a if m.topic == topic]
        mb = [m for m in b if m.topic == topic]
        assert [m.data for m in mb] == [m.data for m in ma], topic   # same bytes, same order
        # log times: the second recorder stamps with /clock (sim time) at reception; the
        # replay publishes /clock before each message, so the difference is delivery
        # latency, bounded generously for a loaded 2-core machine (a stall of ~0.3 s)
        err = max(abs(x.log_time - y.log_time) for x, y in zip(ma, mb)) / 1e9
        assert err < 0.5, (topic, err)
    assert _read_rosbags(bag2)[0][2] == next(iter(BagReader(bag2).messages())).data


def test_sigkill_then_recover_loses_at_most_5_s(launch, ros, ros_env, tmp_path):
    rec = launch('sslfr_recording', 'recorder', params={
        'output_dir': str(tmp_path / 'bags'), 'discovery_period': 0.2})  # default 2 s chunks
    pub = ros.node.create_publisher(Temperature, ABSORBER_TEMPERATURE.of('outlet'), 10)
    _wait_matched(ros, [pub])
    sent = []
    t_kill = None
    start = time.monotonic()
    i = 0
    while time.monotonic() - start < 7.0:
        m = Temperature(temperature=float(i))
        m.header.stamp = ros.node.get_clock().now().to_msg()
        pub.publish(m)
        sent.append(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9)
        i += 1
        if t_kill is None and time.monotonic() - start > 5.0:
            rec.signal(signal.SIGKILL)        # mid-write, no chance to close anything
            t_kill = time.time()
            last_before_kill = i
        ros.spin_for(0.05)
    rec.stop()
    (bag,) = _bag_dirs(tmp_path / 'bags')
    assert not (bag / 'metadata.yaml').exists()
    out = _sslfr(['bag', 'info', str(bag)], ros_env)
    assert out.returncode == 2 and 'recover' in out.stderr and 'metadata.yaml' in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and 'Traceback' not in out.stderr
    out = _sslfr(['bag', 'recover', str(bag)], ros_env)
    assert out.returncode == 0, out.stderr
    report = check_bag(bag)                       # the recovered bag is one rosbag2 opens
    assert report.findings == [], report.text()
    assert _sslfr(['bag', 'info', str(bag)], ros_env).returncode == 0
    got = [g for g in _read_rosbags(bag) if g[0] == '/absorber/outlet_temperature']
    values = [int(dec.temperature) for _, _, _, dec in got]
    assert values == list(range(values[0], values[0] + len(values)))   # no hole, no damage
    last = max(dec.header.stamp.sec + dec.header.stamp.nanosec * 1e-9 for *_, dec in got)
    lost = t_kill - last
    print(f'SIGKILL: {len(values)} of {last_before_kill} messages kept, last {lost:.2f} s lost')
    assert lost <= 5.0
    assert len(values) >= last_before_kill - 5.0 / 0.05


def test_full_rate_day_replays_over_1000x(ros_env, tmp_path):
    from rclpy.serialization import serialize_message as ser
    from sensor_msgs.msg import JointState
    t0 = 1_782_000_000 * 10**9
    w = BagWriter(tmp_path / 'hour', WriterOptions(fsync=False))
    w.add_topic('/tracker/sun', 'sensor_msgs/msg/Temperature', [profile()])
    w.add_topic('/joint_states', 'sensor_msgs/msg/JointState', [profile()])
    one = bytes(ser(Temperature(temperature=1.0)))
    ten = bytes(ser(JointState(name=['mirrors'], position=[0.5], velocity=[0.0])))
    for s in range(3600):               # one hour of 1 Hz + 10 Hz
        w.write('/tracker/sun', one, t0 + s * 10**9)
        for k in range(10):
            w.write('/joint_states', ten, t0 + s * 10**9 + k * 10**8)
    w.close()
    out = _sslfr(['replay', str(tmp_path / 'hour'), '--rate', '0', '--no-progress'], ros_env)
    assert out.returncode == 0, out.stderr
    m = re.search(r'replayed (\d+) messages in ([\d.]+) s \(x(\d+) real time\)', out.stdout)
    assert m and int(m.group(1)) == 39600
    print(out.stdout.strip())
    assert int(m.group(3)) >= 1000


def test_disk_guard_stops_recording_with_diagnostic(launch, ros, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    rec = launch('sslfr_recording', 'recorder', params={
        'output_dir': str(tmp_path / 'bags'), 'min_free_bytes': 2**60, 'discovery_period': 0.2,
        'disk_check_period': 0.2})
    diags = ros.collect(DiagnosticArray, DIAGNOSTICS.name)
    pub = ros.node.create_publisher(Temperature, ABSORBER_TEMPERATURE.of('outlet'), 10)
    _wait_matched(ros, [pub])
    _publish(ros, pub, 1.0, 20)
    assert ros.spin_until(_diag_error(diags, 'recording stopped'), 10.0)
    assert rec.running()                          # only recording stops
    # invalid parameters are refused at runtime, the node keeps its configuration
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    req = SetParameters.Request(parameters=[Parameter(name='compression', value=ParameterValue(
        type=ParameterType.PARAMETER_STRING, string_value='gzip'))])
    res = ros.call(SetParameters, 'recorder/set_parameters', req)
    assert not res.results[0].successful and 'compression' in res.results[0].reason
    assert not any((tmp_path / 'bags').glob('*/*.mcap'))
    assert rec.stop() == 0


def test_unwritable_output_refused_and_write_errors_are_errors(launch, ros, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    # at start: an output_dir that cannot hold bags stops the node with the reason
    (tmp_path / 'a_file').write_text('x')
    bad = launch('sslfr_recording', 'recorder', params={'output_dir': str(tmp_path / 'a_file')})
    assert bad.proc.wait(20) == 2
    assert 'not a directory' in bad.output()
    rec = launch('sslfr_recording', 'recorder', params={
        'output_dir': str(tmp_path / 'bags'), 'discovery_period': 0.2, 'chunk_duration': 0.2,
        'fsync': False, 'exclude': ['/diagnostics']})
    diags = ros.collect(DiagnosticArray, DIAGNOSTICS.name)

    def set_dir(value):
        req = SetParameters.Request(parameters=[Parameter(name='output_dir', value=ParameterValue(
            type=ParameterType.PARAMETER_STRING, string_value=value))])
        return ros.call(SetParameters, 'recorder/set_parameters', req).results[0]
    # at run time: refused with the reason, the old location is kept
    res = set_dir('/proc/x')
    assert not res.successful and '/proc/x' in res.reason and 'cannot write' in res.reason
    pub = ros.node.create_publisher(Temperature, ABSORBER_TEMPERATURE.of('outlet'), 10)
    _wait_matched(ros, [pub])
    _publish(ros, pub, 1.0, 10)
    assert ros.spin_until(lambda: any((tmp_path / 'bags').glob('*/*.mcap')), 10.0)
    # a write error (the bag directory replaced by a file under the recorder) is an ERROR
    # from the first one on
    assert set_dir(str(tmp_path / 'bags2')).successful
    os.makedirs(tmp_path / 'bags2', exist_ok=True)
    shutil.rmtree(tmp_path / 'bags2')
    (tmp_path / 'bags2').write_text('not a directory')
    _publish(ros, pub, 2.0, 10)
    assert ros.spin_until(_diag_error(diags, 'write error'), 10.0)
    assert rec.running()
    assert rec.stop() == 0


@pytest.mark.skipif(not (ROOT / 'ros_ws/install/sslfr_planner/lib/sslfr_planner/planner').exists()
                    or not (ROOT / 'ros_ws/install/sslfr_safety/lib/sslfr_safety/safety').exists(),
                    reason='planner/safety executables not installed')
def test_whatif_replay_runs_fresh_planner_and_safety(ros_env, tmp_path):
    """Inputs of a recorded stretch go to a fresh planner + safety; their decisions are
    recorded (sim time of the recorded day) and compared with the bag's."""
    from daybag import SUNRISE, write_day
    write_day(tmp_path / 'day', SUNRISE - 60, SUNRISE + 60, traj_period=30)
    out = _sslfr(['replay', str(tmp_path / 'day'), '--what-if', '--rate', '20', '--no-progress',
                  '--out', str(tmp_path / 'wi')], ros_env, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert 'fresh nodes: planner, safety' in out.stdout
    assert re.search(r'tracker/phase: agreement [\d.]+ % of \d+ samples', out.stdout)
    assert re.search(r'safety/state: agreement [\d.]+ % of \d+ samples', out.stdout)
    (bag,) = _bag_dirs(tmp_path / 'wi' / 'decisions')
    decisions = BagReader(bag)
    topics = decisions.topics
    assert topics['/tracker/phase'].message_count > 0 and topics['/safety/state'].message_count > 0
    # Recorded on the bag's day (sim time), from the start of the stretch: playing waits
    # until the recorder listens to the fresh nodes' decisions and every sim-time node's
    # /clock is matched (without: the first 55-66 s of sim time, about 3 s wall, were
    # missing in 3 of 12 loaded runs; the recorder or the planner heard /clock late).
    # Bound: 20 s of sim time = 1 s wall at rate 20 (seen since: 0-7 s, the planner's
    # first plan on a loaded machine).
    for topic in ('/safety/state', '/tracker/phase'):
        first = next(decisions.messages([topic]))
        assert 0 <= first.log_time / 1e9 - (SUNRISE - 60) < 20, topic
    assert (tmp_path / 'wi' / 'whatif.md').exists()


@pytest.mark.parametrize('inherited', ['default', 'ignored'])
def test_replay_ctrl_c_stops_cleanly(inherited, ros_env, tmp_path):
    """Ctrl-C stops a replay. 'ignored': started with SIGINT ignored, as everything started
    in the background by a non-interactive shell is (`cmd &` in a script): Python then
    raises no KeyboardInterrupt, and a replay that relied on one played on to its end."""
    w = BagWriter(tmp_path / 'b', WriterOptions(fsync=False))
    w.add_topic('/absorber/inlet_temperature', 'sensor_msgs/msg/Temperature', [profile()])
    data = bytes(serialize_message(Temperature(temperature=3.0)))
    for k in range(600):                        # 60 s at 10 Hz
        w.write('/absorber/inlet_temperature', data, 1_782_000_000 * 10**9 + k * 10**8)
    w.close()
    def ignore_sigint():                            # in the child, before its exec
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    proc = subprocess.Popen([str(ROOT / 'sslfr'), 'replay', str(tmp_path / 'b'), '--rate', '1'],
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=ignore_sigint if inherited == 'ignored' else None)
    seen = ''
    while '%' not in seen and proc.poll() is None:   # replaying: the progress bar is drawn
        seen += proc.stderr.read(1)
    time.sleep(1.0)                                  # a second into the replay
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=20)
    err = seen + err
    assert proc.returncode == 130, err
    assert 'interrupted' in out and 'Traceback' not in err
    assert '%' in err                               # the progress bar was drawn


def test_sslfr_record_exits_1_when_it_recorded_nothing(ros_env, tmp_path):
    proc = subprocess.Popen([str(ROOT / 'sslfr'), 'record', '-o', str(tmp_path / 'bags'),
                             '--topics', '/nobody/publishes/this'], env=ros_env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = []                        # wait until it records (start-up is slow when loaded)
    for line in proc.stderr:
        first.append(line)
        if 'recording to' in line:
            break
    assert proc.poll() is None, ''.join(first)
    time.sleep(1.0)                   # a little time in which nothing is published
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    err = ''.join(first) + err
    assert proc.returncode == 1, (out, err)
    assert 'recorded 0 message(s)' in err and '/nobody/publishes/this' in err
    assert 'Traceback' not in err


@pytest.mark.parametrize('gap', [0.05, 0.3])
def test_two_sigints_during_the_stop_still_finish_the_bag(launch, ros, tmp_path, gap):
    """A terminal's Ctrl-C and launch's own SIGINT (issue 21): the recorder exits 0 and
    the day's bag is complete (metadata.yaml written atomically, no .tmp left), as
    rosbag2's rules require."""
    from sslfr_recording.bag.conformance import check_bag
    rec = launch('sslfr_recording', 'recorder', params={
        'output_dir': str(tmp_path / 'bags'), 'chunk_duration': 0.5, 'discovery_period': 0.2,
        'exclude': ['/diagnostics']})
    pub = ros.node.create_publisher(Temperature, ABSORBER_TEMPERATURE.of('outlet'), 10)
    _wait_matched(ros, [pub])
    _publish(ros, pub, 80.0, 40)
    rec.signal(signal.SIGINT)
    time.sleep(gap)
    rec.signal(signal.SIGINT)
    assert rec.proc.wait(15) == 0, rec.output()
    out = rec.output()
    assert 'Traceback' not in out and 'publish log message to rosout' not in out, out
    (bag,) = _bag_dirs(tmp_path / 'bags')
    assert (bag / 'metadata.yaml').exists() and not list(bag.glob('*.tmp')), list(bag.iterdir())
    report = check_bag(bag)
    assert report.conforms, report.text()
