"""Boards defocus on their own (issue 35 item 3), with the Python simulator: the REAL
``axis_driver`` configures the simulated mirrors board (its host-loss stow: the stow
position after 2 s, the test's delay; default 60 s), is SIGKILLed, and the board
drives to the stow position by itself within 1 s (its watchdog) + the delay + the
travel; a driver started again reads fault HOST_LOSS in the board's status.
The same on the real firmware in simavr: tests/test_fw_boards.py."""
from __future__ import annotations

import math
import os
import shutil
import signal
import sys
import tempfile
import time

import pytest

from conftest import NodeProcess
from sslfr_common.contract import AXIS_STATUS, MIRRORS, SAFETY_STATE

pytestmark = pytest.mark.timeout(180)

DELAY, SPEED, START = 2.0, 0.5, math.radians(20.0)


def test_killed_driver_leaves_a_board_that_stows_by_itself(launch, ros, ros_env, tmp_path):
    from sslfr_drivers.link import messages as m
    from sslfr_sim.runner import SimControl
    from sslfr_interfaces.msg import AxisStatus
    d = tempfile.mkdtemp(prefix='hls')
    port, ctl = os.path.join(d, 'board'), os.path.join(d, 'ctl')
    sim = NodeProcess([sys.executable, '-m', 'sslfr_sim.runner', '--kind', 'axis', '--axis', 'mirrors',
                       '--link', port, '--control', ctl, '--seed', '3', '--opt', f'initial_angle_deg={20.0}'],
                      ros_env, tmp_path / 'sim.log')
    try:
        deadline = time.monotonic() + 15
        while not (os.path.exists(ctl) and os.path.lexists(port)):
            assert sim.running() and time.monotonic() < deadline, sim.output()
            time.sleep(0.05)
        board = SimControl(ctl)
        status = ros.collect(AxisStatus, AXIS_STATUS.of(MIRRORS))
        from sslfr_interfaces.msg import SafetyState
        pub = ros.node.create_publisher(SafetyState, SAFETY_STATE.name, 10)
        safety = {'on': True, 'seq': 0}

        def beat():                       # the test plays a safety supervisor saying OK
            if safety['on']:
                safety['seq'] += 1
                pub.publish(SafetyState(level=SafetyState.OK, sequence=safety['seq']))
        ros.node.create_timer(0.1, beat)
        params = {'axis': 'mirrors', 'port': port, 'retry_period': 0.5, 'max_speed': SPEED,
                  'host_loss_stow_delay': DELAY}
        driver = launch('sslfr_drivers', 'axis_driver', params=params, name='mirrors_driver')
        # safety OK, no trajectory: the driver references the axis from the sensor and holds
        assert ros.spin_until(lambda: status and status[-1].homed, 30), driver.output()
        assert f'host-loss stow to 1.5708 rad after {DELAY:.0f} s of host silence' in driver.output()
        b = board.cmd('status')['boards'][0]
        assert abs(b['angle'] - START) < math.radians(0.1)
        driver.signal(signal.SIGKILL)
        driver.proc.wait(5)
        t_kill = time.monotonic()
        target = round((math.pi / 2) / m.DEFAULT_STEP_RAD)

        def there():
            s = board.cmd('status')['boards'][0]
            return abs(s['counter'] - target) <= 1 and s['speed'] == 0
        while not there():
            assert time.monotonic() - t_kill < 20, board.cmd('status')
            time.sleep(0.05)
        took = time.monotonic() - t_kill
        # the stow runs at the driver's max_speed, capped by the board's (3000 steps/s), with
        # its acceleration (6000 steps/s^2): cruise + one ramp time
        rate = min(SPEED / m.DEFAULT_STEP_RAD, 3000.0)
        travel = (math.pi / 2 - START) / m.DEFAULT_STEP_RAD / rate + rate / 6000.0
        print(f'driver killed -> board at its host-loss stow: {took:.2f} s (1 s + {DELAY} s + {travel:.2f} s travel)')
        # the watchdog counts from the last request, up to a heartbeat (0.25 s) before the kill
        assert 1.0 + DELAY + travel - 0.35 <= took <= 1.0 + DELAY + travel + 1.0
        b = board.cmd('status')['boards'][0]
        assert abs(b['angle'] - math.pi / 2) < math.radians(0.05) and b['faults'] & m.FaultBits.HOST_LOSS
        # the host comes back (no safety/state: it only STOPs): the board says what it did, stays
        safety['on'] = False
        n = len(status)
        again = launch('sslfr_drivers', 'axis_driver', params=params, name='mirrors_driver')
        assert ros.spin_until(lambda: any(s.fault_bits & m.FaultBits.HOST_LOSS for s in status[n:]), 30), \
            again.output()
        assert 'the board stowed by itself while its host was away' in again.output()
        ros.spin_for(1.0)
        assert abs(board.cmd('status')['boards'][0]['counter'] - target) <= 1
    finally:
        sim.stop()
        shutil.rmtree(d, ignore_errors=True)
