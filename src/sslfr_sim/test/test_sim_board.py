"""The simulated axis board as its own process on a real pty (sim_board), driven
through BoardLink exactly as a driver would drive firmware."""
import math
import os
import subprocess
import sys
import time

import pytest

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.board_link import BoardLink, LinkState, NackError
from sslfr_sim.runner import SimControl
from sslfr_drivers.link.transport import SerialTransport

from drivers_testutil import wait_for

STEP = m.DEFAULT_STEP_RAD


@pytest.fixture
def board(tmp_path):
    """sim_board process (mirrors axis, fast motor) + a connected link + control."""
    link_path = str(tmp_path / 'ttyAXIS')
    ctl = str(tmp_path / 'ctl.sock')
    proc = subprocess.Popen(
        [sys.executable, '-m', 'sslfr_sim.runner', '--axis', 'mirrors', '--seed', '7',
         '--link', link_path, '--control', ctl, '--opt', 'max_speed=20000',
         '--opt', 'accel=200000'],
        stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.startswith('SIM_PTY /dev/pts/'), line
    assert os.path.realpath(link_path) == line.split()[1]
    assert wait_for(lambda: os.path.exists(ctl), 5)
    link = BoardLink(SerialTransport(link_path), timeout=0.2, retries=2).start()
    assert link.wait_up(5)
    yield link, SimControl(ctl)
    link.stop()
    proc.terminate()
    assert proc.wait(5) == 0
    assert not os.path.exists(link_path)


def test_process_board_moves_and_reports(board):
    link, ctl = board
    assert link.info.board_kind == m.BoardKind.AXIS_STEPPER and link.info.name_str == 'sim-axis'
    st = link.get_status()
    assert st.limit_bits == m.LimitBits.HIGH | m.LimitBits.SLEEP       # parked at +90 deg
    assert abs(st.sensor_angle - math.pi / 2) < math.radians(0.05)
    link.set_zero(round(math.pi / 2 / STEP))                            # 15000 steps
    link.move_to(5000, 20000)                                           # 30 deg
    assert wait_for(lambda: not link.get_status().moving, 3)
    s = ctl.cmd('status')['boards'][0]
    assert s['counter'] == 5000 and abs(s['angle'] - 5000 * STEP) < 1e-9
    st = link.get_status()
    assert st.position == 5000 and st.limit_bits == 0
    assert abs(st.sensor_angle - math.radians(30)) < math.radians(0.02)   # noise 0.003 deg


def test_watchdog_stops_motor_after_one_second_of_silence(board):
    link, ctl = board
    link.set_zero(15000)
    link.request(m.MoveTo(14000, 5))        # a slow move that would last minutes
    t0 = time.monotonic()
    time.sleep(0.7)
    assert ctl.cmd('status')['boards'][0]['speed'] != 0       # still moving at 0.7 s
    assert wait_for(lambda: ctl.cmd('status')['boards'][0]['speed'] == 0, 1.5)
    stopped_after = time.monotonic() - t0
    assert 0.95 < stopped_after < 1.6
    st = link.get_status()
    assert st.fault_bits & m.FaultBits.WATCHDOG and not st.moving
    link.move_to(14000, 1000)                        # a new MOVE_TO clears the fault
    assert not link.get_status().fault_bits & m.FaultBits.WATCHDOG


def test_heartbeat_keeps_watchdog_quiet(board):
    link, ctl = board
    link.heartbeat = 0.25
    link.set_zero(15000)
    link.move_to(14990, 5)
    time.sleep(1.6)
    assert not link.get_status().fault_bits & m.FaultBits.WATCHDOG
    assert ctl.cmd('status')['boards'][0]['watchdog_trips'] == 0


def test_limit_switch_stops_and_home(board):
    link, ctl = board
    link.set_zero(15000)
    link.move_to(-20000, 20000)                      # beyond the -45 deg end
    assert wait_for(lambda: not link.get_status().moving, 4)
    st = link.get_status()
    assert st.limit_bits & m.LimitBits.LOW and st.fault_bits & m.FaultBits.LIMIT
    assert abs(st.position - (-7500)) <= 30          # -45 deg / 0.006 deg
    with pytest.raises(NackError) as err:
        link.move_to(-8000, 1000)                    # further into the switch
    assert err.value.code == m.ErrorCode.LIMIT_ACTIVE
    link.move_to(-7000, 20000)                       # away from it is fine
    assert wait_for(lambda: not link.get_status().moving, 2)
    link.home(m.Switch.LOW, -5000, position=-7500)   # home on the low switch
    assert wait_for(lambda: link.get_status().homed and not link.get_status().homing, 3)
    s = ctl.cmd('status')['boards'][0]
    assert abs(s['angle'] - math.radians(-45)) < 2 * STEP + 1e-9


def test_reset_loses_position_and_stall(board):
    link, ctl = board
    link.set_zero(15000)
    link.move_to(14000, 20000)
    assert wait_for(lambda: not link.get_status().moving, 2)
    resets = link.resets
    ctl.cmd('reset')
    assert wait_for(lambda: link.resets > resets and link.state == LinkState.UP, 3)
    st = link.get_status()
    assert not st.homed and st.position == 0 and st.fault_bits & m.FaultBits.RESET
    with pytest.raises(NackError) as err:
        link.move_to(100, 1000)
    assert err.value.code == m.ErrorCode.NOT_HOMED
    # the sensor still knows where the joint is: re-establish from it, then stall
    angle = link.get_status().sensor_angle
    link.set_zero(round(angle / STEP))
    ctl.cmd('stall on')
    before = link.get_status().sensor_angle
    link.move_to(round(angle / STEP) - 1000, 20000)
    assert wait_for(lambda: not link.get_status().moving, 2)
    st = link.get_status()
    assert abs(st.position - (round(angle / STEP) - 1000)) <= 1
    assert abs(st.sensor_angle - before) < math.radians(0.02)   # joint did not move


def test_slipping_coupling_turns_the_joint_not_the_counter(board):
    """``slip DEG SECONDS``: the joint (and its sensor) turns DEG away from the motor at a
    steady rate over SECONDS and stays there; the step counter does not see it."""
    link, ctl = board
    link.set_zero(15000)
    before = ctl.cmd('status')['boards'][0]
    assert ctl.cmd('slip -0.5 1.0') == {'ok': True}
    with pytest.raises(RuntimeError, match='could not convert'):     # malformed: refused, board goes on
        ctl.cmd('slip 0.1 oops')
    half = wait_for(lambda: abs(ctl.cmd('status')['boards'][0]['angle'] - before['angle']) > math.radians(0.1), 2)
    assert half
    mid = ctl.cmd('status')['boards'][0]['angle'] - before['angle']
    assert math.radians(-0.5) < mid < 0, 'under way, at a steady rate'
    time.sleep(1.2)
    s = ctl.cmd('status')['boards'][0]
    assert s['angle'] - before['angle'] == pytest.approx(math.radians(-0.5), abs=1e-9)
    assert s['counter'] == before['counter'] == 15000
    st = link.get_status()
    assert st.position == 15000
    assert abs(st.sensor_angle - (math.pi / 2 - math.radians(0.5))) < math.radians(0.02)


def test_cli_help():
    out = subprocess.run([sys.executable, '-m', 'sslfr_sim.runner', '--help'],
                         capture_output=True, text=True, timeout=20)
    assert out.returncode == 0 and '--control' in out.stdout and 'disconnect' in out.stdout


def test_split_frames_survives_garbage_and_a_short_tail():
    """The fault injector cuts the board's output at frame lengths; injected garbage
    ending in fewer than 4 bytes once raised IndexError in the simulator's serve thread."""
    from sslfr_sim.base import _split_frames
    garbage = b'\xa5\x5a\x01\x05garbage-not-a-frame\x00\xff' * 3
    for k in range(len(garbage) + 1):
        pieces = _split_frames(garbage[:k])
        assert b''.join(pieces) == garbage[:k]
