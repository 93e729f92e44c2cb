"""The plant gateway against a running simulated collector (`./sslfr sim`, one
namespace-less node set in the test's domain):

- `modbus_gateway`: pysunspec2's device reader finds the SunSpec chain (SunS, 1, 601,
  302) and pymodbus's client reads the tracker; the mirrors' ElPos equals the
  collector's `joint_states` within one motor step (contract STEP_ANGLE); a control
  write is refused by default and, from an allowed address, reaches `planner/set_mode`
  (the planner's mode becomes `stow`);
- `foxglove_bridge`: a WebSocket client speaking the Foxglove protocol subscribes to
  `joint_states` and decodes one message from its CDR payload.
"""
from __future__ import annotations

import asyncio
import json
import math
import re
import struct
import subprocess
import time

import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile

from conftest import ROOT

pytestmark = pytest.mark.timeout(240)
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
NODES = 'planner,safety,absorber_board,irradiance,mirrors_driver'


@pytest.fixture
def collector(ros_env, tmp_path):
    """A simulated collector at real speed around noon; stopped at teardown."""
    log = open(tmp_path / 'sim.log', 'wb')  # noqa: SIM115 - closed at teardown
    proc = subprocess.Popen([str(ROOT / 'sslfr'), 'sim', '--date', '2026-06-21', '--start', '11:00',
                             '--end', '11:30', '--speed', '1', '--no-report',
                             '--only', NODES, '--out', str(tmp_path / 'out')],
                            env=ros_env, stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)
    proc.log_path = tmp_path / 'sim.log'
    yield proc
    if proc.poll() is None:
        import os
        import signal
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(5)
    log.close()


def _sim_tail(collector) -> str:
    return 'collector not running; sslfr sim said:\n' + collector.log_path.read_text(errors='replace')[-3000:]


def _address(proc, pattern: str) -> tuple[str, int]:
    assert proc.wait_for_output(pattern.split('(')[0].split(' at')[0], 60), proc.output()
    m = re.search(pattern, proc.output())
    assert m, proc.output()
    return m.group(1), int(m.group(2))


def _mirrors(msgs):
    for m in reversed(msgs):
        if 'mirrors' in m.name:
            return m.position[m.name.index('mirrors')]
    return None


def _read_elpos(client, addrs) -> float:
    r = client.read_holding_registers(addrs['601.tracker[0].ElPos'], count=2, device_id=1)
    assert not r.isError(), r
    return client.convert_from_registers(r.registers, client.DATATYPE.INT32) * 1e-3


def test_sunspec_positions_follow_joint_states_and_writes_obey_the_allow_list(collector, launch, ros):
    from pymodbus.client import ModbusTcpClient
    from sensor_msgs.msg import JointState
    from sslfr_common.contract import STEP_ANGLE
    from sslfr_interfaces.msg import TrackerPhase
    from sunspec2.modbus.client import SunSpecModbusClientDeviceTCP

    from sslfr_gateway import sunspec

    joints = ros.collect(JointState, 'joint_states')
    phases = ros.collect(TrackerPhase, 'tracker/phase', LATCHED)
    ro = launch('sslfr_gateway', 'modbus_gateway', name='gw_ro',
                params={'port': 0, 'collectors': [''], 'collector_ids': ['sslfr-a']})
    rw = launch('sslfr_gateway', 'modbus_gateway', name='gw_rw',
                params={'port': 0, 'collectors': [''], 'collector_ids': ['sslfr-a'],
                        'write_allow': ['127.0.0.1']})
    _, port_ro = _address(ro, r'SunSpec Modbus TCP at (\S+):(\d+)')
    _, port_rw = _address(rw, r'SunSpec Modbus TCP at (\S+):(\d+)')
    assert ros.spin_until(lambda: _mirrors(joints) is not None and phases, 90), _sim_tail(collector)

    d = SunSpecModbusClientDeviceTCP(slave_id=1, ipaddr='127.0.0.1', ipport=port_ro, timeout=5)
    try:
        d.scan()
        assert [k for k in d.models if isinstance(k, int)] == [1, 601, 302]
        assert d.common[0].SN.value == 'sslfr-a'
        assert d.tracker_controller[0].tracker[0].Id.value == 'sslfr-a'
    finally:
        d.close()

    addrs = sunspec.point_addresses(1)
    c = ModbusTcpClient('127.0.0.1', port=port_ro, timeout=5)
    assert c.connect()
    try:
        # the register equals the latest joint_states (the gateway's image is refreshed at
        # 10 Hz, the mirrors publish at 5 Hz): compare with the value published just before
        matched = []
        deadline = time.monotonic() + 30
        while len(matched) < 5 and time.monotonic() < deadline:
            ros.spin_for(0.3)
            before = _mirrors(joints)
            el = _read_elpos(c, addrs)
            ros.spin_for(0.25)
            after = _mirrors(joints)
            best = min(abs(math.radians(el) - v) for v in (before, after))
            if best <= STEP_ANGLE:
                matched.append(best)
        assert len(matched) >= 5, f'ElPos did not follow joint_states ({matched})'
        r = c.write_register(addrs['601.tracker[0].Ctl'], 1, device_id=1)
        assert r.isError() and r.exception_code == 1                    # read-only by default
    finally:
        c.close()
    assert ros.spin_until(lambda: phases and phases[-1].mode == 'auto', 10)

    c = ModbusTcpClient('127.0.0.1', port=port_rw, timeout=15)
    assert c.connect()
    try:
        r = c.write_register(addrs['601.tracker[0].Ctl'], 1, device_id=1)
        assert not r.isError(), r
        assert ros.spin_until(lambda: phases[-1].mode == 'stow', 10), [p.mode for p in phases[-3:]]
        assert ros.spin_until(lambda: c.read_holding_registers(addrs['601.tracker[0].Ctl'], count=1,
                                                               device_id=1).registers == [1], 5)
    finally:
        c.close()
    assert 'refused: not in write_allow' in ro.output()


async def _foxglove_one(url: str, topic: str, accept=lambda payload: True) -> bytes:
    """The CDR payload of the first message on ``topic`` that ``accept`` takes."""
    import aiohttp
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(url, protocols=('foxglove.sdk.v1', 'foxglove.websocket.v1'),
                                      timeout=aiohttp.ClientWSTimeout(ws_close=5)) as ws:
            channel = None
            async for msg in ws:
                if msg.type == aiohttp.WSMsgType.TEXT:
                    body = json.loads(msg.data)
                    if body.get('op') == 'advertise' and channel is None:
                        for ch in body['channels']:
                            if ch['topic'] == topic:
                                channel = ch
                                assert ch['encoding'] == 'cdr' and ch['schemaEncoding'] == 'ros2msg'
                                assert ch['schemaName'] == 'sensor_msgs/msg/JointState'
                                await ws.send_str(json.dumps({'op': 'subscribe', 'subscriptions': [
                                    {'id': 7, 'channelId': ch['id']}]}))
                elif msg.type == aiohttp.WSMsgType.BINARY and channel is not None:
                    opcode, sub_id, _stamp = struct.unpack_from('<BIQ', msg.data)
                    if opcode == 1 and sub_id == 7 and accept(bytes(msg.data[13:])):
                        return bytes(msg.data[13:])
                elif msg.type in (aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                    break
    raise AssertionError('no joint_states message over the Foxglove WebSocket')


def test_foxglove_client_decodes_joint_states_and_other_addresses_are_refused(collector, launch, ros):
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    joints = ros.collect(JointState, 'joint_states')
    fox = launch('sslfr_gateway', 'foxglove_bridge', params={'port': 0, 'discovery_period': 0.5})
    host, port = _address(fox, r'Foxglove WebSocket at ws://(\S+):(\d+)')
    assert ros.spin_until(lambda: _mirrors(joints) is not None, 90), _sim_tail(collector)
    try:
        payload = asyncio.run(asyncio.wait_for(_foxglove_one(f'ws://{host}:{port}', '/joint_states'), 60))
    except TimeoutError:
        raise AssertionError('no joint_states over the WebSocket in 60 s; bridge said:\n'
                             + fox.output()[-2000:] + '\n' + _sim_tail(collector)) from None
    msg = deserialize_message(payload, JointState)
    assert msg.name and msg.name[0] in ('mirrors', 'mobile_structure', 'secondary_reflector')
    assert all(math.isfinite(p) for p in msg.position)
    # a client from an address not in `allow` (127.0.0.2) is closed before any byte
    import socket
    s = socket.socket()
    try:
        s.bind(('127.0.0.2', 0))
    except OSError:
        s.close()
        return
    try:
        s.settimeout(5)
        s.connect((host, port))
        try:
            s.sendall(b'GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n\r\n')
            answer = s.recv(100)
        except ConnectionResetError:
            answer = b''                                   # closed while the request was in flight
        assert answer == b''
    finally:
        s.close()
    assert fox.wait_for_output('refused: address not in allow', 5), fox.output()


def test_foxglove_client_keeps_receiving_when_the_publisher_returns_with_another_qos(launch, ros):
    """The bridge's subscription follows its publishers: a client subscribed to a topic
    whose publisher goes and comes back with a weaker QoS (a driver restarted by the
    supervisor, or a publisher that was gone when the client subscribed: rosbag2's rule
    then asks reliable + transient local, which a volatile publisher never matches)
    receives the new publisher's messages; diagnostics count the forwarded ones."""
    import aiohttp
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import ReliabilityPolicy
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState

    pub = ros.node.create_publisher(JointState, 'probe_states', QoSProfile(depth=10))
    diags = ros.collect(DiagnosticArray, '/diagnostics', QoSProfile(depth=50))
    fox = launch('sslfr_gateway', 'foxglove_bridge',
                 params={'port': 0, 'discovery_period': 0.5, 'topics': ['probe_states']})
    host, port = _address(fox, r'Foxglove WebSocket at ws://(\S+):(\d+)')

    async def received(ws, name: str, publisher, within: float) -> bool:
        deadline = time.monotonic() + within
        while time.monotonic() < deadline:
            publisher.publish(JointState(name=[name], position=[0.5]))
            try:
                msg = await asyncio.wait_for(ws.receive(), 0.2)
            except asyncio.TimeoutError:
                continue
            if msg.type == aiohttp.WSMsgType.BINARY and msg.data[0] == 1:
                if deserialize_message(bytes(msg.data[13:]), JointState).name == [name]:
                    return True
            elif msg.type != aiohttp.WSMsgType.TEXT:
                raise AssertionError(f'connection ended: {msg}')
        return False

    async def scenario():
        nonlocal pub
        async with aiohttp.ClientSession() as session:
            async with session.ws_connect(f'ws://{host}:{port}', protocols=('foxglove.sdk.v1',)) as ws:
                channel = None
                while channel is None:
                    body = json.loads((await asyncio.wait_for(ws.receive(), 30)).data)
                    if body.get('op') == 'advertise':
                        channel = next((c['id'] for c in body['channels'] if c['topic'] == '/probe_states'), None)
                # the publisher leaves before the client subscribes: the bridge waits for one
                ros.node.destroy_publisher(pub)
                await ws.send_str(json.dumps({'op': 'subscribe', 'subscriptions': [{'id': 7, 'channelId': channel}]}))
                assert not ros.spin_until(lambda: ros.node.count_subscribers('probe_states') > 0, 2.0), \
                    ros.node.get_subscriptions_info_by_topic('probe_states')
                pub = ros.node.create_publisher(JointState, 'probe_states', QoSProfile(depth=10))
                assert await received(ws, 'first', pub, 30), 'no message from the first publisher'
                ros.node.destroy_publisher(pub)
                pub = ros.node.create_publisher(
                    JointState, 'probe_states', QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
                assert await received(ws, 'second', pub, 30), 'no message from the returned publisher'
    asyncio.run(scenario())
    assert ros.spin_until(lambda: any(
        kv.key == 'forwarded' and int(kv.value) >= 2 for d in diags for s in d.status
        if 'foxglove' in s.name for kv in s.values), 10), fox.output()


def test_two_namespaced_collectors_are_two_units(launch, ros):
    """collectors ['/c1', '/c2']: unit 1 serves /c1's topics, unit 2 /c2's (published here)."""
    from pymodbus.client import ModbusTcpClient
    from sensor_msgs.msg import JointState
    from sslfr_interfaces.msg import Irradiance

    from sslfr_gateway import sunspec

    gw = launch('sslfr_gateway', 'modbus_gateway',
                params={'port': 0, 'collectors': ['/c1', '/c2'], 'collector_ids': ['north', 'south'],
                        'stale_after': 1.0})
    _, port = _address(gw, r'SunSpec Modbus TCP at (\S+):(\d+)')
    pubs = {ns: ros.node.create_publisher(JointState, f'{ns}/joint_states', 10) for ns in ('/c1', '/c2')}
    beam = ros.node.create_publisher(Irradiance, '/c2/irradiance/beam', 10)
    assert ros.spin_until(lambda: all(ros.node.count_subscribers(f'{ns}/joint_states') for ns in pubs), 20)
    addrs = sunspec.point_addresses(1)
    c = ModbusTcpClient('127.0.0.1', port=port, timeout=5)
    assert c.connect()
    try:
        def served():
            pubs['/c1'].publish(JointState(name=['mirrors'], position=[0.25]))
            pubs['/c2'].publish(JointState(name=['mirrors'], position=[-0.5]))
            beam.publish(Irradiance(beam=640.2))
            ros.spin_for(0.2)
            return (_read_elpos(c, addrs) == pytest.approx(math.degrees(0.25), abs=1e-3)
                    and c.read_holding_registers(addrs['601.tracker[0].ElPos'], count=2, device_id=2).registers
                    == c.convert_to_registers(round(math.degrees(-0.5) * 1000), c.DATATYPE.INT32)
                    and c.read_holding_registers(addrs['302.repeating[0].DNI'], count=1,
                                                 device_id=2).registers == [640])
        assert ros.spin_until(served, 15)
        sn = c.read_holding_registers(addrs['1.SN'], count=8, device_id=2).registers
        assert b''.join(r.to_bytes(2, 'big') for r in sn).rstrip(b'\0') == b'south'
        # /c2 falls silent, /c1 goes on: /c2's position reads unknown within stale_after (+ margin)
        def c2_unknown():
            pubs['/c1'].publish(JointState(name=['mirrors'], position=[0.25]))
            ros.spin_for(0.2)
            return c.read_holding_registers(addrs['601.tracker[0].ElPos'], count=2,
                                            device_id=2).registers == [0x8000, 0]
        t0 = time.monotonic()
        assert ros.spin_until(c2_unknown, 10)
        assert time.monotonic() - t0 < 5.0
        assert _read_elpos(c, addrs) == pytest.approx(math.degrees(0.25), abs=1e-3)
    finally:
        c.close()


@pytest.mark.parametrize('params, reason', [
    ({'collectors': ['/c1', '/c2'], 'collector_ids': ['a']}, 'differ in length'),
    ({'collectors': ['c1']}, 'is not a namespace'),
    ({'bind_address': 'localhost'}, 'is not an IP address'),
    ({'write_allow': ['10.0.0.300']}, 'is not an IP address'),
])
def test_bad_parameters_are_refused_at_start(launch, params, reason):
    gw = launch('sslfr_gateway', 'modbus_gateway', params={'port': 0, **params})
    assert gw.proc.wait(30) == 2
    assert reason in gw.output(), gw.output()


@pytest.mark.parametrize('exe, text', [('modbus_gateway', 'cannot serve Modbus'),
                                       ('foxglove_bridge', 'cannot listen on')])
def test_a_port_in_use_is_refused_at_start(launch, exe, text):
    import socket
    with socket.socket() as busy:
        busy.bind(('127.0.0.1', 0))
        busy.listen(1)
        node = launch('sslfr_gateway', exe, params={'port': busy.getsockname()[1]})
        assert node.proc.wait(30) == 2
    assert text in node.output(), node.output()
