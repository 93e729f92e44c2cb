"""Issue 21: the safety supervisor through an axis driver's SIGKILL and restart, with
the REAL processes: ``safety``, ``axis_driver`` for the mobile structure and its
simulated board (sim runner on a pty, as tests/test_axis_driver.py's Rig).

The driver is killed with SIGKILL and started again the way ``ros2 launch`` respawns
it: a fresh process that is not told to configure (``autostart`` false), so it sits
``unconfigured`` and publishes its status heartbeats -- the case where the supervisor
used to go back to OK. After 3 s of that the test drives the lifecycle itself
(``configure``, ``activate``), unless the driver has meanwhile activated by itself.

What is asserted, from the streams received here (``safety/state`` and the axis
status, ordered by their header stamps: ROS time = wall time of this machine):

- the supervisor leaves OK after the kill within the driver's watchdog timeout
  (2 s, + 1 s for a loaded machine): heartbeats are how a SIGKILL can be seen at all,
  so until then the last good status stands;
- from then on it says STOW, never OK, until the restarted driver has reported active,
  link up and its axis referenced, every state naming the axis; while the restarted
  driver is unconfigured the reason says so;
- then it returns to OK by itself.
"""
from __future__ import annotations

import os
import shutil
import signal
import sys
import tempfile
import time

import pytest

from conftest import NodeProcess

pytestmark = pytest.mark.timeout(180)

AXIS = 'mobile_structure'
NODE = f'{AXIS}_driver'
WATCHDOG = 2.0                       # [s] the driver's heartbeat watchdog in this test
IDLE = {'unconfigured', 'inactive', 'finalized'}


def _sec(t) -> float:
    return t.sec + t.nanosec * 1e-9


def _ready(status) -> bool:
    from sslfr_interfaces.msg import AxisStatus
    return status.state not in IDLE and status.link_state == AxisStatus.LINK_UP and status.homed


@pytest.fixture
def board(ros_env, tmp_path):
    d = tempfile.mkdtemp(prefix='sdg')              # short: UNIX socket path limit
    port, ctl = os.path.join(d, 'board'), os.path.join(d, 'ctl')
    argv = [sys.executable, '-m', 'sslfr_drivers.sim.runner', '--kind', 'axis', '--axis', AXIS,
            '--link', port, '--control', ctl, '--seed', '5', '--opt', 'initial_angle_deg=20.0']
    sim = NodeProcess(argv, ros_env, tmp_path / 'sim.log')
    deadline = time.monotonic() + 20
    while not (os.path.exists(ctl) and os.path.lexists(port)):
        assert sim.running() and time.monotonic() < deadline, sim.output()
        time.sleep(0.05)
    yield port
    sim.stop()
    shutil.rmtree(d, ignore_errors=True)


def test_killed_and_restarted_driver_keeps_safety_stowed_until_active_and_homed(board, launch, ros):
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    from sslfr_interfaces.msg import AxisStatus, SafetyState

    states: list = []                         # (arrival [steady s], SafetyState)
    ros.node.create_subscription(SafetyState, 'safety/state', lambda m: states.append((time.monotonic(), m)), 10)
    statuses = ros.collect(AxisStatus, f'axes/{AXIS}/status')
    safety = launch('sslfr_drivers', 'safety', params={
        'require_site_and_time': False, 'watchdog.nodes': [NODE], 'watchdog.timeouts': [WATCHDOG],
        'watchdog.actions': ['STOW'], 'watchdog.startup_grace': 30.0})
    params = {'axis': AXIS, 'port': board, 'retry_period': 0.5, 'max_speed': 0.5, 'home_speed': 0.5}
    driver = launch('sslfr_drivers', 'axis_driver', params={**params, 'autostart': True}, name=NODE)

    def logs() -> str:
        return f'--- safety\n{safety.output()[-3000:]}\n--- driver\n{driver.output()[-3000:]}'

    def level():
        return states[-1][1].level if states else None

    # start-up: STOW naming the axis while the driver configures and homes, then OK
    assert ros.spin_until(lambda: statuses and _ready(statuses[-1]) and level() == SafetyState.OK, 60.0), logs()
    startup = [m for _, m in states if any(r.startswith(f'{AXIS} axis not ready') for r in m.reasons)]
    assert startup and all(m.level == SafetyState.STOW for m in startup), 'the unconfigured driver stowed'
    ros.spin_for(1.0)
    assert level() == SafetyState.OK

    # SIGKILL, then a respawn that is not told to configure
    driver.signal(signal.SIGKILL)
    t_kill, wall_kill = time.monotonic(), time.time()
    assert ros.spin_until(lambda: not driver.running(), 5.0)
    driver = launch('sslfr_drivers', 'axis_driver', params={**params, 'autostart': False}, name=NODE)
    new = lambda: [m for m in statuses if _sec(m.header.stamp) > wall_kill + 0.5]  # noqa: E731
    assert ros.spin_until(lambda: new(), 30.0), 'the restarted driver never published'
    ros.spin_for(3.0)
    idle = all(m.state == 'unconfigured' for m in new())
    print(f'restarted driver after 3 s: {new()[-1].state}' + (' (the test configures and activates it)' if idle else ''))
    if idle:
        unconfigured = [m for _, m in states if f'{AXIS} axis not ready: its driver is unconfigured, not active'
                        in m.reasons]
        assert unconfigured and states[-1][1].level == SafetyState.STOW, (list(states[-1][1].reasons), logs())
        assert not any('heartbeat watchdog' in r for r in states[-1][1].reasons), 'heard again'
        for transition in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
            res = ros.call(ChangeState, f'{NODE}/change_state',
                           ChangeState.Request(transition=Transition(id=transition)), timeout=20.0)
            assert res.success, (transition, logs())
    assert ros.spin_until(lambda: any(_ready(m) for m in new()) and level() == SafetyState.OK, 40.0), \
        (list(states[-1][1].reasons), logs())
    t_ready = min(_sec(m.header.stamp) for m in new() if _ready(m))

    # the whole gap, from the supervisor's first non-OK state after the kill
    after = [(t, m) for t, m in states if t > t_kill]
    first = next(i for i, (_, m) in enumerate(after) if m.level != SafetyState.OK)
    delay = after[first][0] - t_kill
    gap = [m for _, m in after[first:] if _sec(m.header.stamp) < t_ready]
    print(f'driver SIGKILL -> safety STOW after {delay:.2f} s; STOW held over {len(gap)} states '
          f'({t_ready - wall_kill:.1f} s) until the restarted driver was active and homed')
    assert delay <= WATCHDOG + 1.0, delay
    assert gap and all(m.level == SafetyState.STOW for m in gap), [(m.level, list(m.reasons)) for m in gap]
    assert all(any(AXIS in r for r in m.reasons) for m in gap), [list(m.reasons) for m in gap]
    oks = [m for _, m in after[first:] if m.level == SafetyState.OK]
    assert oks and all(_sec(m.header.stamp) > t_ready for m in oks)
