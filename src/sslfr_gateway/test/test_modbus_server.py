"""The Modbus TCP server over real sockets (no ROS): pysunspec2's device reader finds
the model chain, pymodbus's client reads and writes; the write allow-list, refused
writes, connection caps, malformed and oversized requests and a flood from other
loopback addresses (127.0.0.2, 127.0.0.3) while the legitimate client is answered.

The command handler records the modes asked and answers like the planner would
(``stow``/``auto`` accepted); what is tested is the server's own decisions."""
from __future__ import annotations

import concurrent.futures
import socket
import struct
import time

import pytest
from pymodbus.client import ModbusTcpClient
from sunspec2.modbus.client import SunSpecModbusClientDeviceTCP

from sslfr_gateway import sunspec
from gateway_fixtures import extra_loopbacks  # noqa: F401 - a fixture
from sslfr_gateway.modbus_server import ModbusGateway
from sslfr_gateway.sunspec import Tracker, Unit


def _units():
    return [Unit(serial='c1', unit_id=1, trackers=[Tracker('c1', 30.0, 29.994, True, 0)], beam_wm2=700.0),
            Unit(serial='c2', unit_id=2, trackers=[Tracker('c2', -12.5, -12.506, False, 1)], beam_wm2=None)]


@pytest.fixture
def gateway(request):
    calls = []

    def command(unit, tracker, mode):
        fut = concurrent.futures.Future()
        calls.append((unit, tracker, mode))
        fut.set_result((mode in ('auto', 'stow'), 'ok'))
        return fut

    kw = getattr(request, 'param', {})
    gw = ModbusGateway([sunspec.encode(u) for u in _units()], [1, 1], command, port=0,
                       log=lambda s: None, **kw)
    gw.start()
    gw.calls = calls
    yield gw
    gw.stop()


def test_sunspec_reader_discovers_both_units_and_reads_their_points(gateway):
    for unit, (sn, el, ctl) in enumerate((('c1', 29.994, 0), ('c2', -12.506, 1)), start=1):
        d = SunSpecModbusClientDeviceTCP(slave_id=unit, ipaddr='127.0.0.1', ipport=gateway.port, timeout=5)
        try:
            d.scan()
            assert [k for k in d.models if isinstance(k, int)] == [1, 601, 302]
            assert d.common[0].SN.value == sn
            t = d.tracker_controller[0]
            assert t.N.value == 1 and t.tracker[0].Id.value == sn
            assert t.tracker[0].ElPos.cvalue == pytest.approx(el, abs=1e-9)
            assert t.tracker[0].Ctl.value == ctl
        finally:
            d.close()


def test_an_image_update_is_served_at_the_next_read(gateway):
    a = sunspec.point_addresses(1)
    gateway.set_image(0, sunspec.encode(Unit('c1', 1, [Tracker('c1', 1.0, 1.234, True)], 5.0)))
    c = ModbusTcpClient('127.0.0.1', port=gateway.port)
    assert c.connect()
    try:
        r = c.read_holding_registers(a['601.tracker[0].ElPos'], count=2, device_id=1)
        assert c.convert_from_registers(r.registers, c.DATATYPE.INT32) == 1234
    finally:
        c.close()


def test_writes_are_refused_by_default_with_a_modbus_exception(gateway):
    a = sunspec.point_addresses(1)
    c = ModbusTcpClient('127.0.0.1', port=gateway.port)
    assert c.connect()
    try:
        r = c.write_register(a['601.tracker[0].Ctl'], 1, device_id=1)
        assert r.isError() and r.exception_code == 1
        assert gateway.calls == [] and gateway.counters['writes_refused'] == 1
    finally:
        c.close()


@pytest.mark.parametrize('gateway', [{'write_allow': ('127.0.0.1',)}], indirect=True)
def test_writes_from_an_allowed_address_become_commands(gateway):
    a = sunspec.point_addresses(1)
    c = ModbusTcpClient('127.0.0.1', port=gateway.port)
    assert c.connect()
    try:
        assert not c.write_register(a['601.tracker[0].Ctl'], 1, device_id=2).isError()
        assert not c.write_registers(a['601.GlblCtl'], [0], device_id=1).isError()
        assert gateway.calls == [(1, 0, 'stow'), (0, None, 'auto')]
        r = c.write_register(a['601.tracker[0].ElCtl'], 7, device_id=1)       # not a control point
        assert r.isError() and r.exception_code == 2
        r = c.write_register(a['601.tracker[0].Ctl'], 2, device_id=1)         # Calibrate: not offered
        assert r.isError() and r.exception_code == 3
        r = c.write_coil(0, True, device_id=1)                                 # no coils
        assert r.isError()
        assert len(gateway.calls) == 2
    finally:
        c.close()


def _read_ok(port: int, source: str = '127.0.0.1') -> bool:
    c = ModbusTcpClient('127.0.0.1', port=port, timeout=3, source_address=(source, 0))
    try:
        if not c.connect():
            return False
        r = c.read_holding_registers(sunspec.BASE, count=2, device_id=1)
        return not r.isError() and r.registers == [0x5375, 0x6E53]
    except Exception:  # noqa: BLE001 - a refused or dropped connection is "not answered"
        return False
    finally:
        c.close()


@pytest.mark.parametrize('gateway', [{'max_per_address': 4, 'max_connections': 6}], indirect=True)
def test_malformed_oversized_and_a_flood_from_other_addresses_leave_the_client_answered(gateway, extra_loopbacks):
    flooders = extra_loopbacks
    if not flooders:
        pytest.skip('no 127.0.0.2/3 on this machine (loopback is not 127.0.0.0/8)')
    port = gateway.port
    held = []
    try:
        # every flooding address opens more connections than it may keep
        for addr in flooders:
            for _ in range(12):
                s = socket.socket()
                s.bind((addr, 0))
                s.connect(('127.0.0.1', port))
                held.append(s)
        # garbage, a MBAP header announcing 65535 bytes, a huge read count, an unknown function
        bad = [b'\xff' * 300, struct.pack('>HHHB', 1, 0, 65535, 1) + b'\x03' * 600,
               struct.pack('>HHHBBHH', 2, 0, 6, 1, 3, 40000, 2000), struct.pack('>HHHBB', 3, 0, 2, 1, 0x5A)]
        for k, s in enumerate(held):
            try:
                s.sendall(bad[k % len(bad)])
            except OSError:
                pass                                            # closed by the server: fine
        deadline = time.monotonic() + 10
        while gateway.counters['connections_refused'] < len(flooders) * 8 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert gateway.counters['connections_refused'] >= len(flooders) * 8     # 12 - 4 per address
        # with two flooders 8 kept > 6 slots: the legitimate client takes the slot of a flooder
        for _ in range(5):
            assert _read_ok(port), 'the legitimate client was not answered during the flood'
        if len(flooders) == 2:
            assert gateway.counters['connections_evicted'] >= 1                 # it took a flooder's slot
        # a huge read count is refused, not answered with a giant frame
        c = ModbusTcpClient('127.0.0.1', port=port, timeout=3)
        assert c.connect()
        try:
            r = c.read_holding_registers(sunspec.BASE, count=125, device_id=1)
            assert not r.isError() and len(r.registers) == 125
        finally:
            c.close()
    finally:
        for s in held:
            s.close()
    assert _read_ok(port)


def test_eviction_picks_the_least_active_connection_of_the_address_holding_most():
    from sslfr_gateway.modbus_server import evict_choice
    conns = [('a1', '10.0.0.1', 5.0), ('b1', '10.0.0.2', 1.0), ('b2', '10.0.0.2', 0.5),
             ('b3', '10.0.0.2', 9.0), ('c1', '10.0.0.3', 0.1)]
    assert evict_choice(conns) == 'b2'
    assert evict_choice([]) is None


def test_an_unknown_unit_id_is_answered_with_an_exception_and_the_server_goes_on(gateway):
    c = ModbusTcpClient('127.0.0.1', port=gateway.port, timeout=3)
    assert c.connect()
    try:
        for unit in (0, 9, 247):
            r = c.read_holding_registers(sunspec.BASE, count=2, device_id=unit)
            assert r.isError() and r.exception_code == 0x0B, unit       # gateway target: no answer
        assert c.read_holding_registers(sunspec.BASE, count=2, device_id=2).registers == [0x5375, 0x6E53]
    finally:
        c.close()


@pytest.mark.parametrize('gateway', [{'frame_timeout': 1.0, 'idle_timeout': 60.0}], indirect=True)
def test_a_request_trickling_in_is_closed_after_frame_timeout(gateway):
    """Half a Modbus header, then silence: closed after frame_timeout (not idle_timeout)."""
    with socket.socket() as s:
        s.settimeout(10)
        s.connect(('127.0.0.1', gateway.port))
        s.sendall(struct.pack('>HH', 1, 0))
        t0 = time.monotonic()
        try:
            closed = s.recv(16) == b''
        except ConnectionResetError:
            closed = True
        assert closed and time.monotonic() - t0 < 5.0
    assert gateway.counters['slow_closed'] == 1
    assert _read_ok(gateway.port)
