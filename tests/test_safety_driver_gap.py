"""Issue 21: the safety supervisor through an axis driver's SIGKILL and restart, with
the REAL processes: ``safety``, ``axis_driver`` for the mobile structure and its
simulated board (sim runner on a pty, as tests/test_axis_driver.py's Rig).

The driver is started the way ``ros2 launch`` (re)spawns it: a process that is not
told to configure (``autostart`` false), so it sits ``unconfigured`` and publishes its
status heartbeats -- the case where the supervisor used to go back to OK. After 3 s of
that the test drives the lifecycle itself (``configure``, ``activate``), unless the
driver has meanwhile activated by itself. This is done at start-up, and again after
the driver is killed with SIGKILL and started anew.

What is asserted, from the streams received here (``safety/state`` and the axis
status, ordered by their header stamps: ROS time = wall time of this machine):

- while the driver is unconfigured, safety/state is STOW with the reason
  ``mobile_structure axis not ready: its driver is unconfigured, not active`` (and
  no watchdog reason: its heartbeats arrive);
- after the kill the supervisor leaves OK within the driver's watchdog timeout (2 s,
  + 1 s for a loaded machine): heartbeats are how a SIGKILL can be seen at all, so
  until then the last good status stands;
- from its first non-OK state on it says STOW, never OK, every state naming the axis,
  until the driver has reported active, link up and its axis referenced (``homed``);
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
from sslfr_common.contract import AXIS_STATUS, SAFETY_STATE

pytestmark = pytest.mark.timeout(180)

AXIS = 'mobile_structure'
NODE = f'{AXIS}_driver'
WATCHDOG = 2.0                       # [s] the driver's heartbeat watchdog in this test
IDLE = {'unconfigured', 'inactive', 'finalized'}


def _ready(status) -> bool:
    from sslfr_interfaces.msg import AxisStatus
    return status.state not in IDLE and status.link_state == AxisStatus.LINK_UP and status.homed


@pytest.fixture
def board(ros_env, tmp_path):
    d = tempfile.mkdtemp(prefix='sdg')              # short: UNIX socket path limit
    port, ctl = os.path.join(d, 'board'), os.path.join(d, 'ctl')
    argv = [sys.executable, '-m', 'sslfr_sim.runner', '--kind', 'axis', '--axis', AXIS,
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

    from sslfr_common.node import to_sec
    from sslfr_interfaces.msg import AxisStatus, SafetyState

    states: list = []                         # (arrival [steady s], SafetyState)
    ros.node.create_subscription(SafetyState, SAFETY_STATE.name, lambda m: states.append((time.monotonic(), m)), 10)
    statuses = ros.collect(AxisStatus, AXIS_STATUS.of(AXIS))
    safety = launch('sslfr_safety', 'safety', params={
        'require_site_and_time': False, 'watchdog.nodes': [NODE], 'watchdog.timeouts': [WATCHDOG],
        'watchdog.actions': ['STOW'], 'watchdog.startup_grace': 30.0})
    assert ros.spin_until(lambda: states, 30.0), safety.output()
    params = {'axis': AXIS, 'port': board, 'retry_period': 0.5, 'max_speed': 0.5, 'home_speed': 0.5,
              'autostart': False}
    procs = {'driver': launch('sslfr_drivers', 'axis_driver', params=params, name=NODE)}

    def logs() -> str:
        return f'--- safety\n{safety.output()[-3000:]}\n--- driver\n{procs["driver"].output()[-3000:]}'

    def level():
        return states[-1][1].level if states else None

    def bring_up(since: float) -> float:
        """Watch the driver started at wall time ``since`` sit unconfigured for 3 s, then
        configure and activate it (unless it did by itself); return the header stamp of
        its first status that says active, link up and homed."""
        new = lambda: [m for m in statuses if to_sec(m.header.stamp) > since]  # noqa: E731
        assert ros.spin_until(lambda: new(), 30.0), 'the driver never published\n' + logs()
        ros.spin_for(3.0)
        idle = all(m.state == 'unconfigured' for m in new())
        print(f'driver after 3 s: {new()[-1].state}' + (' (the test configures and activates it)' if idle else ''))
        if idle:
            assert level() == SafetyState.STOW, (list(states[-1][1].reasons), logs())
            # the safety node judges the driver from its own subscription (its discovery
            # of the new driver may lag the test's): wait for the reason, not a sample
            reason = f'{AXIS} axis not ready: its driver is unconfigured, not active'
            assert ros.spin_until(lambda: reason in states[-1][1].reasons, 10.0), (list(states[-1][1].reasons), logs())
            assert not any('heartbeat watchdog' in r for r in states[-1][1].reasons), 'heard'
            for transition in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
                res = ros.call(ChangeState, f'{NODE}/change_state',
                               ChangeState.Request(transition=Transition(id=transition)), timeout=20.0)
                assert res.success, (transition, logs())
        assert ros.spin_until(lambda: any(_ready(m) for m in new()) and level() == SafetyState.OK, 40.0), \
            (list(states[-1][1].reasons), logs())
        return min(to_sec(m.header.stamp) for m in new() if _ready(m))

    def stowed_until(t0: float, t_ready: float) -> list:
        """The states from the first non-OK one after steady ``t0``: STOW naming the axis
        until ``t_ready`` (header stamps), OK only after it; returns the gap's states."""
        after = [(t, m) for t, m in states if t > t0]
        first = next(i for i, (_, m) in enumerate(after) if m.level != SafetyState.OK)
        gap = [m for _, m in after[first:] if to_sec(m.header.stamp) < t_ready]
        assert gap and all(m.level == SafetyState.STOW for m in gap), [(m.level, list(m.reasons)) for m in gap]
        assert all(any(AXIS in r for r in m.reasons) for m in gap), [list(m.reasons) for m in gap]
        oks = [m for _, m in after[first:] if m.level == SafetyState.OK]
        assert oks and all(to_sec(m.header.stamp) > t_ready for m in oks)
        return [t for t, _ in after[first:first + 1]] + gap

    # start-up: the driver's unconfigured heartbeats stow the tracker until it is active and homed
    t_start = time.monotonic()
    stowed_until(t_start, bring_up(time.time() - 1.0))
    ros.spin_for(1.0)
    assert level() == SafetyState.OK

    # SIGKILL, then a respawn that is not told to configure (as ros2 launch respawns it)
    procs['driver'].signal(signal.SIGKILL)
    t_kill, wall_kill = time.monotonic(), time.time()
    assert ros.spin_until(lambda: not procs['driver'].running(), 5.0)
    procs['driver'] = launch('sslfr_drivers', 'axis_driver', params=params, name=NODE)
    t_ready = bring_up(wall_kill + 0.5)
    t_first, *gap = stowed_until(t_kill, t_ready)
    delay = t_first - t_kill
    print(f'driver SIGKILL -> safety STOW after {delay:.2f} s; STOW held over {len(gap)} states '
          f'({t_ready - wall_kill:.1f} s) until the restarted driver was active and homed')
    assert delay <= WATCHDOG + 1.0, delay
