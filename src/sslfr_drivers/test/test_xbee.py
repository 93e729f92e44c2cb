"""XBee API mode (AP=2): digi-xbee (host) against the simulated coordinator (sim)."""
import os
import random
import subprocess
import sys
import time

import pytest
from digi.xbee.models.address import XBee64BitAddress
from digi.xbee.models.mode import OperatingMode
from digi.xbee.packets.base import XBeePacket
from digi.xbee.packets.factory import build_frame
from digi.xbee.packets.raw import RX64Packet, TX64Packet, TXStatusPacket
from hypothesis import given, settings
from hypothesis import strategies as st

from sslfr_drivers.link.board_link import BoardLink, BoardLinkState
from sslfr_sim.axis import AxisConfig, AxisSim
from sslfr_sim.base import FaultInjector
from sslfr_sim.runner import SimControl, SimThread
from sslfr_sim.xbee import ApiParser, XBeeSimCoordinator, api_frame
from sslfr_drivers.link.transport import make_transport

from drivers_testutil import wait_for

# addresses containing bytes that must be escaped (0x7E, 0x7D, 0x11, 0x13)
ADDR_A = '0013A2007E7D1113'
ADDR_B = '0013A20040000002'


@settings(deadline=None)
@given(st.binary(min_size=8, max_size=8), st.binary(max_size=100), st.integers(1, 255))
def test_api_codec_matches_digi_xbee(addr, data, frame_id):
    """Our escaped API codec and digi-xbee's packet classes agree both ways."""
    tx = TX64Packet(frame_id, XBee64BitAddress(addr), 0, data,
                    op_mode=OperatingMode.ESCAPED_API_MODE)
    raw = tx.output(escaped=True)
    frames = ApiParser().feed(raw)
    assert frames == [bytes((0x00, frame_id)) + addr + b'\x00' + data]
    ours = api_frame(bytes((0x80,)) + addr + bytes((0x28, 0)) + data)
    # digi-xbee's reader unescapes a packet before building it (reader.py)
    pkt = build_frame(XBeePacket.unescape_data(bytearray(ours)), OperatingMode.ESCAPED_API_MODE)
    assert isinstance(pkt, RX64Packet)
    assert bytes(pkt.x64bit_source_addr.address) == addr
    assert bytes(pkt.rf_data or b'') == data
    status = build_frame(XBeePacket.unescape_data(bytearray(api_frame(bytes((0x89, frame_id, 1))))),
                         OperatingMode.ESCAPED_API_MODE)
    assert isinstance(status, TXStatusPacket) and status.frame_id == frame_id


def test_api_parser_rejects_bad_checksum():
    good = api_frame(b'\x89\x01\x00')
    p = ApiParser()
    assert p.feed(good[:-1] + bytes((good[-1] ^ 0xFF,)) + good) == [b'\x89\x01\x00']
    assert p.bad_checksums == 1


@pytest.fixture
def xbee_sim():
    host = XBeeSimCoordinator()
    host.add_board(bytes.fromhex(ADDR_A), AxisSim(AxisConfig.for_axis('mirrors'), board_id=11,
                                                  rng=random.Random(1)),
                   FaultInjector(rng=random.Random(2)))
    host.add_board(bytes.fromhex(ADDR_B),
                   AxisSim(AxisConfig.for_axis('mobile_structure'), board_id=12,
                           rng=random.Random(3)),
                   FaultInjector(rng=random.Random(4)))
    with SimThread(host) as sim:
        yield sim


def test_two_boards_behind_one_coordinator(xbee_sim):
    la = BoardLink(make_transport(f'xbee:{xbee_sim.path}?addr={ADDR_A}'), heartbeat=0.25)
    lb = BoardLink(make_transport(f'xbee:{xbee_sim.path}?addr={ADDR_B}'), heartbeat=0.25)
    try:
        la.start()
        lb.start()
        assert la.wait_up(5) and lb.wait_up(5)
        coord = la.transport.coordinator
        assert coord is lb.transport.coordinator            # one UART owner
        assert coord._dev.operating_mode == OperatingMode.ESCAPED_API_MODE
        assert coord.local_address == '0013A20040000000'
        assert (la.info.board_id, lb.info.board_id) == (11, 12)
        lb.set_zero(0)
        lb.move_to(500, 3000)
        assert wait_for(lambda: not lb.get_status().moving, 2)
        assert lb.get_status().position == 500
        assert xbee_sim.host.boards[0][1].counter == 0      # A untouched
        # cut B's radio: its transmissions fail (TX status != 0) and are counted,
        # A is unaffected; B recovers afterwards
        xbee_sim.command(f'disconnect 0.6 @{ADDR_B.lower()}')
        time.sleep(0.7)
        assert lb.transport.tx_failures > 0 and lb.tx_failures == lb.transport.tx_failures
        assert la.transport.tx_failures == 0 and la.state == BoardLinkState.UP
        assert wait_for(lambda: lb.state == BoardLinkState.UP, 3)
        assert lb.get_status().position == 500
        assert coord.tx_failures == lb.transport.tx_failures
    finally:
        la.stop()
        lb.stop()
    assert not coord.is_open                                 # last board closed the UART


def test_runner_xbee_process(tmp_path):
    ctl = str(tmp_path / 'ctl')
    proc = subprocess.Popen(
        [sys.executable, '-m', 'sslfr_sim.runner', '--xbee',
         '--board', f'axis:mirrors@{ADDR_A}', '--board', f'axis:secondary_reflector@{ADDR_B}',
         '--control', ctl, '--seed', '1'], stdout=subprocess.PIPE, text=True)
    try:
        path = proc.stdout.readline().split()[1]
        link = BoardLink(make_transport(f'xbee:{path}?addr={ADDR_B}')).start()
        try:
            assert link.wait_up(5)
            assert wait_for(lambda: os.path.exists(ctl), 2)
            SimControl(ctl).cmd(f'reset @{ADDR_B.lower()}')
            # (protocol 2: the power-up BOOT is of no session and proves nothing; the
            # reset is seen in the authenticated boot count of the next session)
            assert wait_for(lambda: link.resets >= 1, 3)
            # the reset ends the session (requests meanwhile end with NoSession, by
            # contract): ask once the link is UP again in a new session
            assert link.wait_up(5), link.state
            assert not link.get_status().homed
            boards = SimControl(ctl).cmd('status')['boards']
            assert [b['resets'] for b in boards] == [0, 1]
        finally:
            link.stop()
    finally:
        proc.terminate()
        assert proc.wait(5) == 0


def test_hub_gives_each_remote_board_a_pty(xbee_sim, tmp_path):
    """xbee_hub: one process owns the coordinator UART, drivers open plain ptys."""
    from sslfr_drivers.link.transport import SerialTransport
    from sslfr_drivers.link.xbee_hub import XBeeHub
    import threading
    paths = {ADDR_A: str(tmp_path / 'a'), ADDR_B: str(tmp_path / 'b')}
    hub = XBeeHub(xbee_sim.path, paths, control=str(tmp_path / 'hub.sock'))
    t = threading.Thread(target=hub.serve, daemon=True)
    t.start()
    links = [BoardLink(SerialTransport(paths[a]), heartbeat=0.25).start() for a in (ADDR_A, ADDR_B)]
    try:
        assert all(lk.wait_up(5) for lk in links)
        assert [lk.info.board_id for lk in links] == [11, 12]
        links[1].set_zero(0)
        links[1].move_to(-300, 3000)
        assert wait_for(lambda: links[1].get_status().position == -300, 2)
        xbee_sim.command(f'disconnect 0.5 @{ADDR_A.lower()}')
        time.sleep(0.6)
        st = SimControl(str(tmp_path / 'hub.sock')).cmd('status')
        assert st['boards'][0]['tx_failures'] > 0 and st['boards'][1]['tx_failures'] == 0
        assert wait_for(lambda: links[0].state == BoardLinkState.UP, 3)
    finally:
        for lk in links:
            lk.stop()
        hub.running = False
        t.join(2)
        hub.close()


def test_coordinator_port_lost_and_reopened(tmp_path, caplog):
    """The coordinator's port vanishes: the link goes DOWN, the port is reopened with
    back-off, the link comes back; digi-xbee's reader does not spin on the dead port
    (it used to retry forever, one 'Serial exception while reading' warning each)."""
    import logging
    caplog.set_level(logging.WARNING)
    host = XBeeSimCoordinator()
    host.add_board(bytes.fromhex(ADDR_B), AxisSim(AxisConfig.for_axis('mirrors'),
                                                  rng=random.Random(1)), FaultInjector())
    port = str(tmp_path / 'xbee')
    with SimThread(host, link=port) as sim:
        lk = BoardLink(make_transport(f'xbee:{port}?addr={ADDR_B}'), heartbeat=0.25,
                       backoff_max=0.5).start()
        try:
            assert lk.wait_up(5)
            lk.set_zero(0)
            sim.command('unplug 1.0')                 # the coordinator's USB adapter vanishes
            assert wait_for(lambda: lk.state == BoardLinkState.DOWN, 3)
            assert wait_for(lambda: lk.state == BoardLinkState.UP, 6)
            assert lk.reconnects == 1 and lk.get_status().homed
        finally:
            lk.stop()
    spins = [r for r in caplog.records if 'Serial exception while reading' in r.getMessage()]
    assert len(spins) <= 2, f'{len(spins)} retries of a dead port'
    # the library's records reach people as one line on our logger, without traceback
    # (pytest's capture also sees digi's own record: its handlers sit on every logger)
    ours = [r for r in caplog.records if r.name.startswith('sslfr_drivers') and 'XBee library' in r.getMessage()]
    assert any('lost' in r.getMessage() for r in ours), [r.getMessage() for r in caplog.records]
    assert not [r for r in ours if r.exc_info]
    assert logging.getLogger('digi').propagate is False
