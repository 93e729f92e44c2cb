"""fw_board, the firmware boards as a drop-in replacement of sim_board: the same command
line, control socket and fault commands, in both wirings: plain (USB serial, the
harness owns the pty) and the XBee API hub with several boards behind one coordinator
(sim/xbee.py coordinator, xbee_hub on the host side)."""
from __future__ import annotations

import math
import os
import subprocess
import sys
import threading
import time

import pytest

from fw_support import require, wait_for

from sslfr_drivers.link import messages as m
from sslfr_drivers.link import sensor_messages as ms
from sslfr_drivers.link.board_link import BoardLink, LinkState
from sslfr_sim.runner import SimControl
from sslfr_drivers.link.transport import SerialTransport

pytestmark = pytest.mark.timeout(180)
ADDR = {'mirrors': '0013A20040000001', 'absorber': '0013A20040000002', 'gps': '0013A20040000003'}


@pytest.fixture(scope='module', autouse=True)
def _built():
    require('firmware', 'sim')


def _fw_board(tmp_path, *args):
    ctl = str(tmp_path / 'ctl')
    proc = subprocess.Popen([sys.executable, '-m', 'sslfr_sim.fw_board', '--control', ctl, '--seed', '2', *args],
                            stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.startswith('SIM_PTY '), line
    assert wait_for(lambda: os.path.exists(ctl), 10)
    return proc, line.split()[1], SimControl(ctl)


def test_plain_wiring_faults_through_the_control_socket(tmp_path):
    link_path = str(tmp_path / 'mirrors')
    proc, pty, ctl = _fw_board(tmp_path, '--kind', 'axis', '--axis', 'mirrors', '--link', link_path,
                               '--opt', 'initial_angle_deg=30')
    link = BoardLink(SerialTransport(link_path), heartbeat=0.25).start()
    try:
        assert link.wait_up(5) and link.info.name_str == 'sslfr-axis'
        board = ctl.cmd('status')['boards'][0]
        assert board['kind'] == 'AXIS_STEPPER' and abs(board['angle'] - math.radians(30)) < 1e-9
        link.request(m.SetZero(5000))
        link.request(m.MoveTo(4000, 3000.0))
        assert wait_for(lambda: ctl.cmd('status')['boards'][0]['counter'] == 4000, 3)
        assert abs(ctl.cmd('status')['boards'][0]['angle'] - math.radians(30 - 6)) < 1e-6
        ctl.cmd('stall on')                                   # steps counted, joint still
        link.request(m.MoveTo(3000, 3000.0))
        assert wait_for(lambda: ctl.cmd('status')['boards'][0]['counter'] == 3000, 3)
        st = ctl.cmd('status')['boards'][0]
        assert st['stalled'] and abs(st['angle'] - math.radians(24)) < 1e-6
        ctl.cmd('stall off')
        ctl.cmd('set_angle 10')
        assert abs(ctl.cmd('status')['boards'][0]['angle'] - math.radians(10)) < 1e-9
        ctl.cmd('disconnect 1.5')                             # radio cut: the board's watchdog trips
        assert wait_for(lambda: link.state != LinkState.UP, 3)
        assert wait_for(lambda: link.state == LinkState.UP, 5)
        assert ctl.cmd('status')['boards'][0]['watchdog_trips'] >= 1
        resets = link.resets
        ctl.cmd('reset')
        assert wait_for(lambda: link.resets > resets and link.state == LinkState.UP, 5)
        assert not link.request(m.GetStatus()).homed
        ctl.cmd('unplug 1.0')                                 # the port disappears, then a new pty
        assert wait_for(lambda: not os.path.lexists(link_path), 2)
        assert wait_for(lambda: os.path.lexists(link_path), 4)
        assert wait_for(lambda: link.state == LinkState.UP, 8)
        ctl.cmd('corrupt_frames 0.3')
        for _ in range(30):
            try:
                link.request(m.GetStatus())
            except Exception:   # noqa: BLE001 - some answers are corrupted: retried / timed out
                pass
        ctl.cmd('corrupt_frames 0')
        fw = ctl.cmd('status')['boards'][0]
        assert fw['frames_corrupted'] > 0 and link.counters()['crc_errors'] > 0
    finally:
        link.stop()
        ctl.cmd('quit')
        assert proc.wait(10) == 0


def test_xbee_hub_with_several_firmware_boards(tmp_path):
    from sslfr_drivers.link.xbee_hub import XBeeHub
    proc, pty, ctl = _fw_board(tmp_path, '--xbee', '--board', f'axis:mirrors@{ADDR["mirrors"]}',
                               '--board', f'absorber@{ADDR["absorber"]}', '--board', f'gps@{ADDR["gps"]}',
                               '--opt', 'start_utc=2026-06-21T10:00:00Z', '--opt', 'speed=1')
    paths = {ADDR[k]: str(tmp_path / k) for k in ADDR}
    hub = XBeeHub(pty, paths, control=str(tmp_path / 'hub.sock'))
    t = threading.Thread(target=hub.serve, daemon=True)
    t.start()
    samples = {k: [] for k in ADDR}
    links = {}
    try:
        for k in ADDR:
            links[k] = BoardLink(SerialTransport(paths[ADDR[k]]), heartbeat=0.25)
            links[k].add_listener(lambda msg, f, k=k: samples[k].append(msg))
            links[k].start()
        assert all(lk.wait_up(20) for lk in links.values()), {k: lk.last_error for k, lk in links.items()}
        assert {k: lk.info.name_str for k, lk in links.items()} == \
            {'mirrors': 'sslfr-axis', 'absorber': 'sslfr-absorber', 'gps': 'sslfr-gps'}
        links['mirrors'].request(m.SetZero(15000))
        links['mirrors'].request(m.MoveTo(14000, 3000.0))
        assert wait_for(lambda: links['mirrors'].request(m.GetStatus()).position == 14000, 4)
        assert wait_for(lambda: any(isinstance(s, ms.ThermocoupleSample) for s in samples['absorber']), 3)
        assert wait_for(lambda: b'$GPRMC' in b''.join(s.data for s in samples['gps']
                                                      if isinstance(s, ms.NmeaChunk)), 5)
        status = ctl.cmd('status')['boards']
        assert [b['name'] for b in status] == ['sslfr-axis', 'sslfr-absorber', 'sslfr-gps']
        before = {k: lk.resets for k, lk in links.items()}
        ctl.cmd(f'reset @{ADDR["absorber"].lower()}')         # one board only
        assert wait_for(lambda: links['absorber'].resets > before['absorber'], 4)
        assert links['mirrors'].resets == before['mirrors'] and links['mirrors'].request(m.GetStatus()).homed
        ctl.cmd(f'disconnect 1.5 @{ADDR["gps"].lower()}')      # radio cut: TX status no ACK
        assert wait_for(lambda: hub.status()['boards'][2]['tx_failures'] > 0, 4), hub.status()
        assert wait_for(lambda: links['gps'].state == LinkState.UP, 6)
        ctl.cmd('{"cmd": "fault", "kind": "overtemp", "active": true, "value": 180, "board": "%s"}'
                % ADDR['absorber'].lower())
        from sslfr_drivers.sensors import max6675
        assert wait_for(lambda: any(isinstance(s, ms.ThermocoupleSample)
                                    and abs(max6675.decode(s.outlet).temperature - 180) < 2
                                    for s in samples['absorber'][-4:]), 4)
    finally:
        for lk in links.values():
            lk.stop()
        hub.running = False
        t.join(3)
        hub.close()
        ctl.cmd('quit')
        assert proc.wait(10) == 0


def test_actuator_board_through_the_control_socket(tmp_path):
    """``--kind actuator`` (seed 004's board, its drive from the shipped description):
    the line where ``initial_angle_deg`` puts it, a MOVE_TO followed within the deadband
    (the truth in ``status``), ``stall on`` jams the bar (fault STALL), ``reset``
    reboots it unreferenced; the lines are not moved by hand (``set_angle`` refused, as
    by the Python board)."""
    from sslfr_sim.actuator import ActuatorConfig, shipped_description
    cfg = ActuatorConfig.from_description(shipped_description())
    step, band = cfg.step_rad, cfg.deadband + math.radians(0.03)
    link_path = str(tmp_path / 'mirrors')
    proc, pty, ctl = _fw_board(tmp_path, '--kind', 'actuator', '--axis', 'mirrors', '--link', link_path,
                               '--opt', 'initial_angle_deg=-10')
    link = BoardLink(SerialTransport(link_path), heartbeat=0.25).start()

    def board():
        return ctl.cmd('status')['boards'][0]
    try:
        assert link.wait_up(5) and link.info.name_str == 'sslfr-actuator'
        st = board()
        assert st['kind'] == 'AXIS_ACTUATOR' and abs(st['angle'] - math.radians(-10)) < 1e-6
        assert not st['homed'] and st['target'] is None and st['faults'] & m.FaultBits.RESET
        with pytest.raises(RuntimeError, match='set_angle'):
            ctl.cmd('set_angle 5')
        link.request(m.SetZero(round(math.radians(-10) / step)))
        link.request(m.MoveTo(round(math.radians(-8) / step), 3000.0))
        assert wait_for(lambda: board()['target'] is not None, 2)
        assert abs(board()['target'] - math.radians(-8)) < band
        assert wait_for(lambda: not link.request(m.GetStatus()).moving, 10)
        assert abs(board()['angle'] - math.radians(-8)) < band and board()['homed']
        ctl.cmd('stall on')                                   # the bar jammed: the line stays
        link.request(m.MoveTo(round(math.radians(-4) / step), 3000.0))
        assert wait_for(lambda: link.request(m.GetStatus()).fault_bits & m.FaultBits.STALL, 6)
        st = board()
        assert st['stalled'] and abs(st['angle'] - math.radians(-8)) < band
        ctl.cmd('stall off')
        resets = link.resets
        ctl.cmd('reset')
        assert wait_for(lambda: link.resets > resets and link.state == LinkState.UP, 5)
        assert not link.request(m.GetStatus()).homed and not board()['homed']
    finally:
        link.stop()
        ctl.cmd('quit')
        assert proc.wait(10) == 0


def test_switchless_board_behind_the_xbee_hub(tmp_path):
    """``axis_noswitch`` behind the XBee coordinator: the switchless build, the shipped
    seed-003 description's step (0.1125 deg) on the joint, a board reset (one board
    selected) loses the reference."""
    from sslfr_drivers.link.xbee_hub import XBeeHub
    addr = ADDR['mirrors']
    proc, pty, ctl = _fw_board(tmp_path, '--xbee', '--board', f'axis_noswitch:mirrors@{addr}',
                               '--opt', 'initial_angle_deg=5')
    path = str(tmp_path / 'mirrors')
    hub = XBeeHub(pty, {addr: path}, control=str(tmp_path / 'hub.sock'))
    t = threading.Thread(target=hub.serve, daemon=True)
    t.start()
    link = BoardLink(SerialTransport(path), heartbeat=0.25)
    try:
        link.start()
        assert link.wait_up(20) and link.info.name_str == 'sslfr-axis-nosw'
        st = ctl.cmd('status')['boards'][0]
        assert st['name'] == 'sslfr-axis-nosw' and abs(st['angle'] - math.radians(5)) < 1e-9
        step = math.radians(0.1125)
        ref = round(math.radians(5) / step)
        link.request(m.SetZero(ref))
        link.request(m.MoveTo(ref + 100, 2000.0))
        assert wait_for(lambda: ctl.cmd('status')['boards'][0]['counter'] == ref + 100, 4)
        st = ctl.cmd('status')['boards'][0]
        assert abs(st['angle'] - (math.radians(5) + 100 * step)) < 1e-6 and st['homed']
        resets = link.resets
        ctl.cmd(f'reset @{addr.lower()}')
        assert wait_for(lambda: link.resets > resets and link.state == LinkState.UP, 5)
        assert not link.request(m.GetStatus()).homed
    finally:
        link.stop()
        hub.running = False
        t.join(3)
        hub.close()
        ctl.cmd('quit')
        assert proc.wait(10) == 0
