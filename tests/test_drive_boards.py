"""Topic-level: the REAL ``axis_driver`` executable against the boards of the drives
without switches, each its own process on a real pty (issue 34 item 3), on both board
backends: the Python simulators (``sim_board``) and the boards' firmware in simavr
(``fw_board``, the same command line: ``./sslfr sim --boards firmware``).

* Linear actuator closed on an inclinometer (seed 004, ``--kind actuator``): the driver
  (``drive: linear_actuator_inclinometer``, the description's deadband) references the
  board from its inclinometer by itself and tracks a short ramp within the deadband.
* Switchless stepper (seed 003, ``--kind axis_noswitch``): the driver never moves the
  axis until the operator calls ``axes/mirrors/home`` ("it is at the reference angle
  now"), then tracks; a board reset loses the reference again.

The test plays the planner (``tracker/trajectory``) and the safety supervisor
(``safety/state`` at 10 Hz). ROS time is wall time; the boards run in real time. The
ramp is 5 deg/min, ~600 x the sun's rate of seed 004's lines (0.5 x 15 deg/h), so the
test lasts seconds; the deadband and the inclinometer noise are not scaled.
"""
from __future__ import annotations

import math
import os
import shutil
import sys
import tempfile
import time

import pytest

from conftest import NodeProcess
from sslfr_planner.description import load
from sslfr_sim.actuator import shipped_description

pytestmark = pytest.mark.timeout(120)
R = math.radians
#: board backend -> the module run as the board process (same arguments)
BACKENDS = {'sim': 'sslfr_sim.runner', 'firmware': 'sslfr_sim.fw_board'}


@pytest.fixture(params=sorted(BACKENDS))
def backend(request):
    if request.param == 'firmware':
        from fw_support import require
        require('firmware', 'sim')
    return request.param


class DriveRig:
    """A simulated board process + an axis_driver process + the test's publishers."""

    def __init__(self, launch, ros, ros_env, tmp_path, kind: str, sim_opts: dict, params: dict,
                 backend: str = 'sim'):
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from sslfr_interfaces.msg import AxisStatus, SafetyState
        from trajectory_msgs.msg import JointTrajectory

        from sslfr_sim.runner import SimControl
        self.ros = ros
        self.dir = tempfile.mkdtemp(prefix='axdr')
        self.port = os.path.join(self.dir, 'board')
        ctl = os.path.join(self.dir, 'ctl')
        argv = [sys.executable, '-m', BACKENDS[backend], '--kind', kind, '--axis', 'mirrors',
                '--link', self.port, '--control', ctl, '--seed', '7']
        for k, v in sim_opts.items():
            argv += ['--opt', f'{k}={v}']
        self.sim_proc = NodeProcess(argv, ros_env, tmp_path / 'sim.log')
        deadline = time.monotonic() + 15
        while not (os.path.exists(ctl) and os.path.lexists(self.port)):
            assert self.sim_proc.running() and time.monotonic() < deadline, self.sim_proc.output()
            time.sleep(0.05)
        self.sim = SimControl(ctl)
        p = {'axis': 'mirrors', 'port': self.port, 'autostart': True, 'retry_period': 0.5, **params}
        self.driver = launch('sslfr_drivers', 'axis_driver', params=p, name='mirrors_driver')
        tl1 = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_traj = ros.node.create_publisher(JointTrajectory, 'tracker/trajectory', tl1)
        self.pub_safety = ros.node.create_publisher(SafetyState, 'safety/state', 10)
        self.status = ros.collect(AxisStatus, 'axes/mirrors/status')
        self._SafetyState, self._seq = SafetyState, 0
        ros.node.create_timer(0.1, self._beat)

    def _beat(self):
        self._seq += 1
        self.pub_safety.publish(self._SafetyState(level=0, stow_required=False, stopped_axes=[],
                                                  sequence=self._seq))

    def close(self):
        self.sim_proc.stop()
        shutil.rmtree(self.dir, ignore_errors=True)

    def board(self) -> dict:
        return self.sim.cmd('status')['boards'][0]

    def publish(self, t0: float, times, positions):
        """Mirror positions [rad] at ROS times ``t0 + times`` [s]."""
        from builtin_interfaces.msg import Duration
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
        msg = JointTrajectory()
        msg.header.stamp.sec = int(t0)
        msg.header.stamp.nanosec = int(round((t0 - int(t0)) * 1e9)) % 1_000_000_000
        msg.joint_names = ['mirrors']
        for t, p in zip(times, positions):
            pt = JointTrajectoryPoint()
            pt.positions = [float(p)]
            pt.time_from_start = Duration(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)) % 1_000_000_000)
            msg.points.append(pt)
        self.pub_traj.publish(msg)

    def wait_state(self, states, timeout: float) -> bool:
        return self.ros.spin_until(lambda: bool(self.status) and self.status[-1].state in states, timeout)


@pytest.fixture
def drive_rig(launch, ros, ros_env, tmp_path, backend):
    rigs = []

    def make(**kw):
        r = DriveRig(launch, ros, ros_env, tmp_path, backend=backend, **kw)
        rigs.append(r)
        return r
    yield make
    for r in rigs:
        r.close()


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def test_actuator_board_tracks_a_ramp_within_the_deadband(drive_rig, ros):
    mv = shipped_description('florianopolis_lepten').movement('mirrors')
    r = drive_rig(kind='actuator', sim_opts={'initial_angle_deg': -20.0},
                  params={'drive': mv.drive, 'deadband': mv.deadband, 'lower_limit': mv.range[0],
                          'upper_limit': mv.range[1], 'stow_position': mv.stow, 'host_loss_stow_position': mv.stow,
                          'home_position': mv.stow,
                          'max_speed': 0.03})
    assert r.wait_state(('holding',), 20), r.driver.output()        # referenced from the inclinometer
    assert r.board()['homed'] and r.board()['kind'] == 'AXIS_ACTUATOR'
    t0 = time.time() + 0.5
    ramp = lambda t: R(-20.0) + R(5.0) * min(max(t - t0, 0.0), 12.0) / 60.0    # noqa: E731
    r.publish(t0, [0.5 * k for k in range(25)], [ramp(t0 + 0.5 * k) for k in range(25)])
    ros.spin_for(t0 + 12.0 - time.time())
    during = [s for s in r.status if t0 + 2.0 <= _stamp(s) <= t0 + 12.0]
    assert during and {s.state for s in during} == {'following'}, {s.state for s in during}
    # the board rests anywhere within the deadband; the ramp adds its travel during one
    # settling (<= 0.5 s at 5 deg/min = 0.04 deg) and one status period of age
    bound = mv.deadband + R(5.0) / 60.0 * 0.7
    worst = max(abs(s.measured - ramp(_stamp(s))) for s in during)
    assert worst <= bound, (math.degrees(worst), math.degrees(bound))
    assert ros.spin_until(lambda: r.status[-1].state == 'holding', 5)
    truth = r.board()
    assert abs(truth['angle'] - R(-19.0)) <= mv.deadband + R(0.01), math.degrees(truth['angle'])
    print(f'\nactuator ramp: worst |measured - ramp| {math.degrees(worst):.4f} deg '
          f'(deadband {math.degrees(mv.deadband):.3f} deg, bound {math.degrees(bound):.3f} deg)')


def test_switchless_board_waits_for_the_operator_reference(drive_rig, ros, tmp_path):
    from sslfr_common.drives import ReferenceStore
    from std_srvs.srv import Trigger
    mv = load(shipped_description('bucaramanga_single_axis').path).movement('mirrors')
    r = drive_rig(kind='axis_noswitch', sim_opts={'initial_angle_deg': 0.0, 'max_speed': 2000, 'accel': 8000},
                  params={'drive': mv.drive, 'step_angle': mv.step, 'lower_limit': R(-45.0),
                          'upper_limit': mv.range[1], 'stow_position': mv.stow, 'host_loss_stow_position': mv.stow,
                          'home_position': mv.reference,
                          'use_sensor': False, 'auto_home': False, 'max_speed': 0.2,
                          'state_dir': str(tmp_path / 'state')})
    store = ReferenceStore(tmp_path / 'state', 'mirrors')
    assert r.wait_state(('fault',), 20), r.driver.output()
    assert not r.status[-1].homed and math.isnan(r.status[-1].measured)
    t0 = time.time()
    r.publish(t0, [0.0, 60.0], [R(10.0), R(10.0)])
    ros.spin_for(1.5)
    assert r.board()['angle'] == 0.0 and not r.board()['homed']     # never moved by itself
    client = ros.node.create_client(Trigger, 'axes/mirrors/home')
    assert client.wait_for_service(timeout_sec=5)
    fut = client.call_async(Trigger.Request())
    assert ros.spin_until(fut.done, 5) and fut.result().success, fut.result()
    assert 'referenced at 0.0000 rad' in fut.result().message
    assert ros.spin_until(lambda: abs(r.board()['angle'] - R(10.0)) <= mv.step and
                          r.status[-1].state == 'following', 10), r.board()
    ref = store.load()                                                # kept with the board's boot
    assert ref.angle == mv.reference and not ref.lost and ref.boot_count >= 1
    r.sim.cmd('reset')                                                # the reference is lost
    t_reset = time.time()
    assert ros.spin_until(lambda: _stamp(r.status[-1]) > t_reset and r.status[-1].state == 'fault'
                          and not r.status[-1].homed, 5)
    ros.spin_for(1.0)
    assert not r.board()['homed'] and r.board()['speed'] == 0.0
    assert ros.spin_until(lambda: store.load().lost, 5), store.load()
    assert 'is lost: board reset' in r.driver.output()
