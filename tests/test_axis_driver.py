"""Topic-level acceptance of the axis driver (issue 5, "Axis driver node").

Each test runs the REAL ``axis_driver`` executable and the link helper's simulated
axis board as its own process on a real pty (``python -m sslfr_sim.runner``,
the same protocol as the firmware); faults are injected through the simulator's
control socket. The test process plays the planner (``tracker/trajectory``), the
safety supervisor (``safety/state`` at 10 Hz) and, when needed, ``tracker/phase``.
No sim time: ROS time is wall time, the simulated board runs in real time.

What is compressed, honestly: the "10-minute trajectory" is ten minutes of the
real mirror motion (beta_0 = theta_t / 2 for Almeria on the summer solstice from
10:00 solar time, closed-form projected angle of a horizontal N-S axis) replayed
60x faster, i.e. in 10 s of wall time; the mirror speed is then ~0.14 deg/s
(~23 steps/s), far inside the axis' speed limit (the seed's own tracking speed is
0.006 deg/s). The other tests replay sun trajectories 40x faster. The board's step resolution (0.006 deg) and sensor noise
(0.003 deg 1-sigma) are not scaled.
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
from sslfr_common.contract import JOINTS
from sslfr_common.timeconv import to_sec
from sslfr_common.contract import (AXIS_HOME, AXIS_JOG, AXIS_STATUS, DIAGNOSTICS, SAFETY_STATE,
                                   TRACKER_PHASE, TRACKER_TRAJECTORY)

pytestmark = pytest.mark.timeout(120)

STEP = math.radians(0.006)             # [rad] seed 000 step
NOISE = math.radians(0.003)            # [rad] sim sensor noise, 1 sigma
TOL = STEP + 4 * NOISE                 # one step + the sensor noise (4 sigma bound)
SPEEDUP = 60.0                         # sun seconds per wall second in the tracking test


def beta0_almeria(t_solar_h: float) -> float:
    """Mirror angle beta_0 = theta_t / 2 [rad] at solar time ``t_solar_h`` [h].

    Horizontal N-S axis: tan theta_t = sin w cos d / (cos phi cos d cos w + sin phi sin d)
    (seed 000 eq. 9 in projected form), phi = 36.84 deg (Almeria), d = 23.44 deg
    (solstice), w = 15 deg/h (t - 12 h).
    """
    phi, d = math.radians(36.84), math.radians(23.44)
    w = math.radians(15.0 * (t_solar_h - 12.0))
    tt = math.atan2(math.sin(w) * math.cos(d), math.cos(phi) * math.cos(d) * math.cos(w)
                    + math.sin(phi) * math.sin(d))
    return tt / 2


class Rig:
    """Simulated board process + axis_driver process + publishers in the test."""

    def __init__(self, launch, ros, ros_env, tmp_path, axis='mirrors', sim_args=(), params=None):
        from sslfr_common.node import qos
        from diagnostic_msgs.msg import DiagnosticArray
        from sslfr_interfaces.msg import AxisStatus, SafetyState, TrackerPhase
        from trajectory_msgs.msg import JointTrajectory

        from sslfr_sim.runner import SimControl

        self.ros, self.axis = ros, axis
        self.dir = tempfile.mkdtemp(prefix='axd')        # short: UNIX socket path limit
        self.port = os.path.join(self.dir, 'board')
        self.ctl_path = os.path.join(self.dir, 'ctl')
        argv = [sys.executable, '-m', 'sslfr_sim.runner', '--kind', 'axis', '--axis', axis,
                '--link', self.port, '--control', self.ctl_path, '--seed', '7',
                '--opt', 'sensor_noise_deg=0.003', *sim_args]
        self.sim_proc = NodeProcess(argv, ros_env, tmp_path / 'sim.log')
        deadline = time.monotonic() + 15
        while not (os.path.exists(self.ctl_path) and os.path.lexists(self.port)):
            assert self.sim_proc.running() and time.monotonic() < deadline, self.sim_proc.output()
            time.sleep(0.05)
        self.sim = SimControl(self.ctl_path)
        p = {'axis': axis, 'port': self.port, 'autostart': True, 'retry_period': 0.5,
             'max_speed': 0.3, 'home_speed': 0.3}
        p.update(params or {})
        self.driver = launch('sslfr_drivers', 'axis_driver', params=p, name=f'{axis}_driver')

        tl1 = qos(TRACKER_PHASE)
        node = ros.node
        self.pub_traj = node.create_publisher(JointTrajectory, TRACKER_TRAJECTORY.name, tl1)
        self.pub_phase = node.create_publisher(TrackerPhase, TRACKER_PHASE.name, tl1)
        self.pub_safety = node.create_publisher(SafetyState, SAFETY_STATE.name, 10)
        self.status = ros.collect(AxisStatus, AXIS_STATUS.of(axis))
        self.diags = ros.collect(DiagnosticArray, DIAGNOSTICS.name)
        self.safety = {'level': 0, 'stow_required': False, 'stopped_axes': []}
        self.heartbeat = True
        self.last_heartbeat = 0.0
        self._seq = 0
        self._SafetyState = SafetyState
        node.create_timer(0.1, self._beat)

    def close(self):
        self.sim_proc.stop()
        shutil.rmtree(self.dir, ignore_errors=True)

    # -- inputs -------------------------------------------------------------------
    def _beat(self):
        if not self.heartbeat:
            return
        self._seq += 1
        msg = self._SafetyState(level=self.safety['level'], stow_required=self.safety['stow_required'],
                                stopped_axes=list(self.safety['stopped_axes']), sequence=self._seq)
        self.pub_safety.publish(msg)
        self.last_heartbeat = time.monotonic()

    def publish_trajectory(self, t0: float, times, positions, velocities=None):
        """Points at wall/ROS times ``t0 + times`` [s] with ``positions`` [rad]."""
        from builtin_interfaces.msg import Duration
        from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
        msg = JointTrajectory()
        msg.header.stamp.sec = int(t0)
        msg.header.stamp.nanosec = int(round((t0 - int(t0)) * 1e9)) % 1_000_000_000
        msg.joint_names = ['mobile_structure', self.axis] if self.axis == 'mirrors' else ['mirrors', self.axis]
        for k, (t, p) in enumerate(zip(times, positions)):
            pt = JointTrajectoryPoint()
            pt.positions = [0.0, float(p)]
            if velocities is not None:
                pt.velocities = [0.0, float(velocities[k])]
            pt.time_from_start = Duration(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)) % 1_000_000_000)
            msg.points.append(pt)
        self.pub_traj.publish(msg)

    def publish_sun_trajectory(self, t_wall0: float, sun_start_h: float, sun_minutes: float,
                               speedup: float = SPEEDUP, dt_wall: float = 0.25):
        """Sun-driven mirror trajectory, ``sun_minutes`` of sun compressed ``speedup`` x."""
        n = int(round(sun_minutes * 60 / speedup / dt_wall)) + 1
        ts = [k * dt_wall for k in range(n)]
        ps = [self.ideal(t_wall0 + t, t_wall0, sun_start_h, speedup) for t in ts]
        h = 1e-3
        vs = [(self.ideal(t_wall0 + t + h, t_wall0, sun_start_h, speedup)
               - self.ideal(t_wall0 + t - h, t_wall0, sun_start_h, speedup)) / (2 * h) for t in ts]
        self.publish_trajectory(t_wall0, ts, ps, vs)

    @staticmethod
    def ideal(t_wall: float, t_wall0: float, sun_start_h: float, speedup: float = SPEEDUP) -> float:
        return beta0_almeria(sun_start_h + (t_wall - t_wall0) * speedup / 3600.0)

    # -- observations ---------------------------------------------------------------
    def board(self) -> dict:
        return self.sim.cmd('status')['boards'][0]

    def diag(self, after: float = 0.0) -> dict:
        """The axis's newest diagnostics values (of a message stamped >= ``after`` [s])."""
        for arr in reversed(self.diags):
            if to_sec(arr.header.stamp) < after:
                break
            for st in arr.status:
                if self.axis in st.name:
                    return {kv.key: kv.value for kv in st.values}
        return {}

    def wait_state(self, state: str, timeout: float) -> bool:
        return self.ros.spin_until(lambda: bool(self.status) and self.status[-1].state == state, timeout)


@pytest.fixture
def rig(launch, ros, ros_env, tmp_path):
    rigs = []

    def make(**kw):
        r = Rig(launch, ros, ros_env, tmp_path, **kw)
        rigs.append(r)
        return r
    yield make
    for r in rigs:
        r.close()


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def _errors(status, ideal, t_from, t_to):
    return [(s.measured - ideal(_stamp(s)), s) for s in status if t_from <= _stamp(s) <= t_to]


def test_follows_ten_minute_sun_trajectory_within_one_step_plus_noise(rig, ros):
    sun_h = 10.0
    start = beta0_almeria(sun_h)
    r = rig(sim_args=['--opt', f'initial_angle_deg={math.degrees(start) + 0.5}'])
    assert r.wait_state('holding', 20), r.driver.output()          # configured, active, no trajectory
    t0 = time.time() + 1.0
    r.publish_sun_trajectory(t0, sun_h, 10.0)
    t_end = t0 + 600 / SPEEDUP
    ideal = lambda t: Rig.ideal(t, t0, sun_h)     # noqa: E731

    # a refused trajectory in the middle must not disturb tracking
    ros.spin_for(t0 + 5 - time.time())
    now = time.time()
    r.publish_trajectory(now, [0.0, 1.0], [0.1, float('nan')])
    ros.spin_for(0.3)                                           # TL1 keeps only the last message
    r.publish_trajectory(now, [0.0, 1.0], [0.1, 2.0])           # beyond +pi/2
    ros.spin_for(0.3)
    r.publish_trajectory(now - 100, [0.0, 1.0], [0.1, 0.1])     # past only
    ros.spin_for(t_end + 0.5 - time.time())

    errs = _errors(r.status, ideal, t0 + 1.0, t_end)
    assert len(errs) > 0.8 * 5.0 * (t_end - t0 - 1.0), (len(errs), r.driver.output())   # 5 Hz status
    worst = max(abs(e) for e, _ in errs)
    print(f'\n10-min sun trajectory (x{SPEEDUP:.0f}): {len(errs)} samples, max |measured - ideal| '
          f'= {math.degrees(worst) * 3600:.1f} arcsec = {worst / STEP:.2f} steps '
          f'(bound {TOL / STEP:.2f} steps)')
    assert worst <= TOL, [(round(e / STEP, 2), s.state) for e, s in errs if abs(e) > TOL][:10]
    assert all(s.state == 'following' for _, s in errs)
    # the board's step counter (no sensor noise) stays within one step of quantisation
    # plus what the axis moves in one control period (control_rate 20 Hz) and 50 ms of
    # scheduling delay: at 60x the mirrors move ~21 steps/s, so a delay a loaded machine
    # gives is worth steps here (2.46 steps were seen twice against a bound of 2)
    rate = max(abs(ideal(t0 + k + 0.5) - ideal(t0 + k)) / 0.5 for k in range(int(t_end - t0)))
    cmd_bound = STEP + rate * (1 / 20.0 + 0.05)
    cmd_err = max(abs(s.steps * STEP - ideal(_stamp(s))) for _, s in errs)
    assert cmd_err <= cmd_bound, (cmd_err / STEP, 'steps; bound', cmd_bound / STEP)
    ros.spin_until(lambda: r.diag().get('trajectories_rejected') == '3', 3)
    d = r.diag()
    assert d['trajectories_rejected'] == '3' and d['trajectories_accepted'] == '1', d
    out = r.driver.output()
    assert 'non-finite position' in out and 'outside soft limits' in out and 'past-only' in out


def test_link_cut_then_restored_resumes_tracking_and_reset_uses_sensor(rig, ros):
    sun_h = 14.0
    r = rig(sim_args=['--opt', f'initial_angle_deg={math.degrees(beta0_almeria(sun_h))}'])
    assert r.wait_state('holding', 20), r.driver.output()
    t0 = time.time() + 0.5
    r.publish_sun_trajectory(t0, sun_h, 20.0, speedup=40.0)            # 30 s of wall time
    ideal = lambda t: Rig.ideal(t, t0, sun_h, 40.0)  # noqa: E731
    ros.spin_for(3.0)
    assert r.status[-1].state == 'following'

    r.sim.cmd('disconnect 5')
    t_cut = time.time()
    ros.spin_for(5.0)
    during = [s for s in r.status if t_cut + 1.5 < _stamp(s) < t_cut + 5.0]
    assert during and all(s.link_state != 2 for s in during), [s.link_state for s in during]
    assert r.board()['watchdog_trips'] >= 1           # the board stopped by itself

    def tracking_again():
        s = r.status[-1] if r.status else None
        return (s is not None and _stamp(s) > t_cut + 5 and s.link_state == 2
                and s.state == 'following' and abs(s.measured - ideal(_stamp(s))) <= TOL)
    assert ros.spin_until(tracking_again, 10.0), [(s.state, s.link_state) for s in r.status[-5:]]
    resumed = _stamp(r.status[-1]) - (t_cut + 5.0)
    ros.spin_for(1.0)
    after = [s for s in r.status if _stamp(s) > t_cut + 5 + resumed]
    assert max(abs(s.measured - ideal(_stamp(s))) for s in after) <= TOL
    truth = r.board()
    assert truth['homed'] and abs(truth['angle'] - truth['counter'] * STEP) <= STEP, truth
    print(f'\nlink cut 5 s: tracking within one step + noise {resumed:.2f} s after restoration')

    # board reset (sensor present): position re-established from the sensor, no NOT_HOMED move
    r.sim.cmd('reset')
    t_reset = time.time()
    assert ros.spin_until(lambda: _stamp(r.status[-1]) > t_reset + 0.3 and tracking_again(), 5.0)
    back = next(s for s in r.status if _stamp(s) > t_reset and s.homed and s.state == 'following')
    ros.spin_for(1.0)
    b = r.board()
    assert abs(b['angle'] - b['counter'] * STEP) <= STEP + 4 * NOISE, b
    d = r.diag()
    assert d.get('nacks_not_homed') == '0' and int(d['board_resets']) >= 1, d
    assert int(d['set_zero_sent']) >= 2 and b['resets'] == 1, (d, b)   # start-up + after the reset
    print(f'board reset (sensor): re-referenced and following {_stamp(back) - t_reset:.2f} s later')

    # the port disappears for 3 s (USB unplugged): reopened with back-off, tracking again
    reconnects = int(r.diag()['reconnects'])
    r.sim.cmd('unplug 3')
    t_cut = time.time() - 2.0          # tracking_again() looks for statuses after t_cut + 5
    assert ros.spin_until(lambda: r.status[-1].link_state == 0, 3)      # LINK_DOWN seen
    assert ros.spin_until(tracking_again, 10.0)
    print(f'port unplugged 3 s: tracking again {_stamp(r.status[-1]) - (t_cut + 5):.2f} s after it came back')
    assert ros.spin_until(lambda: int(r.diag()['reconnects']) > reconnects, 3)


def test_board_reset_without_sensor_rehomes_before_moving(rig, ros):
    """mobile_structure axis, board without position sensor: after a reset the only
    motion allowed is the homing move toward the SLEEP (rest, 0 rad) switch."""
    r = rig(axis='mobile_structure', sim_args=['--opt', 'no_sensor=1', '--opt', 'initial_angle_deg=-3'])
    assert r.wait_state('holding', 25), r.driver.output()
    t0 = time.time() + 0.5
    r.publish_trajectory(t0, [0.0, 1.5, 60.0], [0.10, 0.12, 0.13])
    assert ros.spin_until(lambda: abs(r.board()['angle'] - 0.12) < 0.001, 8)
    r.sim.cmd('reset')
    samples = []
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        b = r.board()
        samples.append(b)
        if b['homed'] and b['counter'] != 0 and abs(b['angle'] - 0.125) < 0.01:
            break
        ros.spin_for(0.03)
    first_homed = next(i for i, b in enumerate(samples) if b['homed'])
    angles = [b['angle'] for b in samples[:first_homed]]
    # before re-homing the joint only moved toward the rest switch (down), never along
    # the trajectory; the board's HOME ended at that switch (the simulator records the
    # angle where it ended: sampling over the control socket can miss the last 40 ms)
    assert all(a2 <= a1 + 1e-12 for a1, a2 in zip(angles, angles[1:])), angles
    assert angles[0] > 0.1, angles
    width = math.radians(0.2)                   # the simulated SLEEP switch's width
    assert samples[first_homed]['home_angle'] is not None
    assert abs(samples[first_homed]['home_angle']) <= width / 2 + STEP, samples[first_homed]
    assert r.diag().get('nacks_not_homed') == '0', r.diag()
    ros.spin_for(0.5)
    b = r.board()
    # homed on a switch 0.2 deg wide, approached from above: reference within its half width
    assert abs(b['angle'] - b['counter'] * STEP) <= math.radians(0.1) + STEP, b
    s = r.status[-1]
    assert s.homed and s.state == 'following'


def test_corrupted_bytes_no_wrong_move_and_exact_frames_lost(rig, ros):
    sun_h = 9.0
    r = rig(sim_args=['--opt', f'initial_angle_deg={math.degrees(beta0_almeria(sun_h))}'])
    assert r.wait_state('holding', 20), r.driver.output()
    t0 = time.time() + 0.5
    r.publish_sun_trajectory(t0, sun_h, 20.0, speedup=40.0)
    ideal = lambda t: Rig.ideal(t, t0, sun_h, 40.0)  # noqa: E731

    def frozen_counts():
        """Freeze traffic (a radio cut, ended only after both reads) and read both ends'
        counters at rest: the host's from a diagnostics message (1 Hz) stamped at least
        0.5 s into the cut, then the board's. (A fixed 1.6 s cut was not frozen when a
        diagnostics message came late under load: the board's counters, read after the
        cut had ended, held 4 frames more than the host's.)"""
        r.sim.cmd('disconnect 60')
        in_cut = time.time() + 0.5
        assert ros.spin_until(lambda: bool(r.diag(after=in_cut)), 10), 'no diagnostics during the cut'
        d = r.diag(after=in_cut)
        out = r.board()['frames_out']
        r.sim.cmd('disconnect 0')
        return out, int(d['frames_received']) + int(d['frames_lost']), int(d['frames_lost']), int(d['sessions'])

    ros.spin_for(1.0)
    out0, host0, lost0, sess0 = frozen_counts()
    ros.spin_for(1.0)
    r.sim.cmd('corrupt 0.01')
    t_c = time.time()
    truth = []                         # (wall time, true joint angle): no sensor noise
    while time.time() < t_c + 6.0:
        truth.append((time.time(), r.board()['angle']))
        ros.spin_for(0.05)
    lag = max(ideal(t) - a for t, a in truth)
    ahead = max(a - ideal(t) for t, a in truth)
    r.sim.cmd('corrupt 0')
    ros.spin_for(0.5)
    out1, host1, lost1, sess1 = frozen_counts()
    board = r.board()
    lost = lost1 - lost0
    print(f'\n1% byte corruption for 6 s: board sent {out1 - out0} frames, host counted '
          f'{host1 - host0} received+lost, {lost} lost, {board["bytes_corrupted"]} bytes corrupted, '
          f'{sess1 - sess0} new session(s); '
          f'truth lags the ideal by <= {lag / STEP:.1f} steps, ahead by <= {ahead / STEP:.1f} steps')
    assert board['bytes_corrupted'] > 10
    assert lost > 0
    # every board frame is received or counted lost (sequence gaps): exactly, while one
    # session lasts. Frames lost at the end of a session that corruption ended (no valid
    # answer for link_timeout 1 s, then a reconnection: seen in the busy soak; at 4 %
    # corruption 4-10 frames per new session) leave no gap to count. So: the host never
    # counts more than the board sent; with no new session, exactly; per new session at
    # most what the board answers in one link_timeout (20 Hz control + 4 Hz heartbeat)
    # goes uncounted. (The cuts' own reconnections, when they happen, lose nothing.)
    new_sessions = sess1 - sess0
    assert new_sessions >= 0, (sess0, sess1)
    assert 0 <= (out1 - out0) - (host1 - host0) <= 24 * new_sessions, (out1 - out0, host1 - host0, new_sessions)
    assert r.status[-1].frames_lost == lost1
    assert r.status[-1].frames_bad > 0
    # no wrong move: this morning trajectory only rises (~0.1 deg/s): the joint never
    # went down, never got ahead of the ideal by more than the one-period lead + a step;
    # lost frames only make it wait (lag, bounded by a second of trajectory motion, 20
    # steps); a session ended by corruption (or the first cut's, if it reconnects late)
    # adds its link_timeout (1 s) before the new session moves again: 40 steps whenever a
    # new session happened (seen in the busy soak: 21.1 steps with 3 new sessions)
    angles = [a for _, a in truth]
    assert all(a2 >= a1 - 1e-12 for a1, a2 in zip(angles, angles[1:]))
    assert ahead <= 2 * STEP, ahead / STEP
    assert lag <= (40 if new_sessions else 20) * STEP, (lag / STEP, new_sessions)
    assert r.diag()['faults'] == '0'


def test_safety_silence_stops_within_1_2_s_stow_and_jog(rig, ros):
    from sslfr_interfaces.msg import TrackerPhase
    from sslfr_interfaces.srv import Jog
    from std_srvs.srv import Trigger

    # (the fail-safe stow after a longer silence is tested in tests/test_safety_e2e.py)
    r = rig(sim_args=['--opt', 'initial_angle_deg=0'],
            params={'max_speed': 0.02, 'safety_silent_stow_after': 5.0})
    assert r.wait_state('holding', 20), r.driver.output()
    t0 = time.time() + 0.3
    c0 = r.board()['counter']
    r.publish_trajectory(t0, [0.0, 30.0], [0.0, 0.3])             # 0.01 rad/s
    # following: the board's step counter moves (its instantaneous speed may be 0
    # between two moves: the driver sends a move when the setpoint crosses a step)
    seen = []
    assert ros.spin_until(lambda: seen.append(r.board()) or seen[-1]['counter'] != c0, 3), \
        (seen[-3:], list(r.status)[-3:])
    r.heartbeat = False
    t_last = r.last_heartbeat
    track = []                                   # (steady time, step counter) of the board
    while time.monotonic() < t_last + 2.6:
        track.append((time.monotonic(), r.board()['counter']))
        time.sleep(0.01)
    # the last instant the counter still changed = when the motor stopped for good
    last_move = max(t for (t, c), (_, c0) in zip(track[1:], track) if c != c0)
    print(f'\nsafety silent: motor stopped {last_move - t_last:.3f} s after the last heartbeat')
    assert last_move - t_last > 0.8            # it kept following while the heartbeat was fresh
    assert last_move - t_last <= 1.2
    assert track[-1][0] - last_move >= 1.3     # and stayed stopped
    assert r.ros.spin_until(lambda: r.status[-1].state == 'stopped', 2)

    # stow required: mirrors go to the sleeping position
    r.safety.update(level=2, stow_required=True)
    r.heartbeat = True
    assert ros.spin_until(lambda: r.status[-1].state == 'stowing'
                          and abs(r.status[-1].commanded - math.pi / 2) < STEP, 3)
    # ESTOP while moving: STOP sent from the safety callback, motor still within 0.3 s
    assert ros.spin_until(lambda: r.board()['speed'] != 0.0, 2)
    r.safety.update(level=3, stow_required=False)
    r._beat()
    t_estop = time.monotonic()
    while r.board()['speed'] != 0.0 and time.monotonic() < t_estop + 1.0:
        ros.spin_for(0.01)
    print(f'ESTOP: motor still {time.monotonic() - t_estop:.3f} s after the message')
    assert time.monotonic() - t_estop <= 0.3
    held = r.board()['counter']
    assert ros.spin_until(lambda: r.status[-1].state == 'stopped', 2)
    assert r.board()['counter'] == held                          # and it stays stopped
    r.safety.update(level=0, stow_required=False)
    # the operator e-stop (safety/estop: ESTOP listing every axis) while stowing: the
    # same STOP from the safety callback, motor still within 0.3 s
    r.safety.update(level=2, stow_required=True)
    assert ros.spin_until(lambda: r.board()['speed'] != 0.0, 3)
    r.safety.update(level=3, stow_required=True, stopped_axes=list(JOINTS))
    r._beat()
    t_estop = time.monotonic()
    while r.board()['speed'] != 0.0 and time.monotonic() < t_estop + 1.0:
        ros.spin_for(0.01)
    print(f'operator e-stop: motor still {time.monotonic() - t_estop:.3f} s after the message')
    assert time.monotonic() - t_estop <= 0.3
    assert ros.spin_until(lambda: r.status[-1].state == 'stopped', 2)
    r.safety.update(level=0, stow_required=False, stopped_axes=[])

    # jog: refused outside maintenance, accepted in maintenance
    res = ros.call(Jog, AXIS_JOG.of('mirrors'), Jog.Request(delta=0.01, speed=0.0))
    assert not res.success and 'maintenance' in res.message
    r.pub_phase.publish(TrackerPhase(phase=TrackerPhase.MAINTENANCE, phase_name='MAINTENANCE',
                                     mode='maintenance'))
    assert ros.spin_until(lambda: r.status[-1].state in ('holding', 'jogging')
                          and r.status[-1].moving is False, 10)
    here = r.status[-1].measured
    res = ros.call(Jog, AXIS_JOG.of('mirrors'), Jog.Request(delta=-0.01, speed=0.0))
    assert res.success, res.message
    assert ros.spin_until(lambda: abs(r.board()['angle'] - (here - 0.01)) < 2 * STEP + 4 * NOISE, 5)
    res = ros.call(Jog, AXIS_JOG.of('mirrors'), Jog.Request(delta=1.0, speed=0.0))
    assert not res.success and 'max_jog' in res.message
    assert ros.call(Trigger, AXIS_HOME.of('mirrors'), Trigger.Request()).success


def test_lifecycle_transitions_stall_fault_and_old_protocol(rig, ros):
    """Driven by sslfr_drivers.axis.lifecycle_ctl (what bringup uses), no autostart:
    deactivate stops the motor, cleanup closes the link; a stalled joint (steps
    counted, sensor still) latches a fault that stops the axis. A second driver meets
    a board speaking protocol version 0 and must refuse it."""
    from sslfr_drivers.axis.lifecycle_ctl import bring_to, get_state

    r = rig(sim_args=['--opt', 'initial_angle_deg=0'], params={'autostart': False})
    # in parallel: a board speaking an old protocol version is refused with a clear message
    old = rig(axis='mobile_structure', sim_args=['--protocol-version', '0'])
    t_old = time.time()
    name = 'mirrors_driver'
    assert ros.spin_until(lambda: bool(r.status) and r.status[-1].state == 'unconfigured', 15)
    assert get_state(ros.node, name, executor=ros.executor) == 'unconfigured'
    ok, msg = bring_to(ros.node, name, 'active', executor=ros.executor)
    assert ok, msg + r.driver.output()

    # invalid parameters are refused at run time with a reason; the last good ones stay
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    def set_param(pname, value):
        req = SetParameters.Request(parameters=[Parameter(name=pname, value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=value))])
        return ros.call(SetParameters, f'{name}/set_parameters', req).results[0]
    res = set_param('lower_limit', 1.6)                        # above upper_limit
    assert not res.successful and 'soft limits' in res.reason, res.reason
    res = set_param('max_speed', 5.0)                          # outside the declared range
    assert not res.successful
    assert set_param('max_speed', 0.25).successful
    t0 = time.time() + 0.3
    r.publish_trajectory(t0, [0.0, 30.0], [0.0, 0.6])          # 0.02 rad/s
    assert ros.spin_until(lambda: r.status[-1].state == 'following' and r.board()['speed'] != 0, 5)

    ok, msg = bring_to(ros.node, name, 'inactive', executor=ros.executor)
    assert ok, msg
    assert ros.spin_until(lambda: r.board()['speed'] == 0.0, 0.5)
    ros.spin_for(0.5)
    assert r.board()['speed'] == 0.0 and r.status[-1].state == 'inactive'

    ok, msg = bring_to(ros.node, name, 'active', executor=ros.executor)
    assert ok, msg
    assert ros.spin_until(lambda: r.board()['speed'] != 0.0, 3)
    r.sim.cmd('stall on')
    t_stall = time.time()
    assert ros.spin_until(lambda: r.status[-1].state == 'fault', 5), [s.state for s in r.status[-5:]]
    print(f'\nstall injected: fault after {time.time() - t_stall:.2f} s')
    assert ros.spin_until(lambda: r.board()['speed'] == 0.0, 1)
    ros.spin_for(1.2)
    assert r.board()['speed'] == 0.0                          # stays stopped (latched)
    d = r.diag()
    assert int(d['faults']) >= 1 and ('lost steps' in d['reason'] or 'stall' in d['reason']), d

    ok, msg = bring_to(ros.node, name, 'unconfigured', executor=ros.executor)
    assert ok, msg
    assert ros.spin_until(lambda: r.status[-1].state == 'unconfigured' and r.status[-1].link_state == 0, 3)

    out = old.driver.output()
    assert 'configure refused: board speaks protocol version 0, this host speaks version 2' in out, out
    assert out.count('configure refused') == 1          # autostart keeps retrying, logs once
    assert old.driver.running(), out
    # the contract: status at 5 Hz in every lifecycle state, LINK_FAULT included, from the
    # driver's construction on. The driver has run for seconds by now, but on a loaded
    # machine the first messages of a new participant reach this test's subscription
    # only once DDS discovery has matched the two (volatile QoS: what was published
    # before is not resent), so wait for one: 10 s = startup + discovery, loaded
    assert ros.spin_until(lambda: bool(old.status), 10.0), out
    first = _stamp(old.status[0])
    print(f'refused driver: first status received stamped {first - t_old:.2f} s after the rig started it')
    assert old.status[-1].state == 'unconfigured' and old.status[-1].link_state == 3   # LINK_FAULT
    assert old.board()['homed'] is False and old.board()['counter'] == 0    # never driven


# ----------------------------------------------------------------- issue 21: self-activation
def _active(ros, name: str) -> bool:
    from sslfr_drivers.axis.lifecycle_ctl import get_state
    return get_state(ros.node, name, timeout=1.0, executor=ros.executor) == 'active'


def _gaps(status) -> float:
    stamps = [_stamp(s) for s in status]
    return max((b - a for a, b in zip(stamps, stamps[1:])), default=0.0)


def test_driver_started_before_its_board_activates_by_itself_and_after_sigkill(launch, ros, ros_env, tmp_path):
    """The port appears 5 s after the driver started: configure is retried with
    back-off (each failed attempt's reason in diagnostics), then the driver activates
    by itself; SIGKILLed and started again, it becomes active by itself again. The
    status heartbeat runs at 5 Hz throughout, also while no board answers."""
    import signal

    from diagnostic_msgs.msg import DiagnosticArray
    from sslfr_interfaces.msg import AxisStatus

    d = tempfile.mkdtemp(prefix='axd')
    port = os.path.join(d, 'board')
    params = {'axis': 'mirrors', 'port': port, 'retry_period': 0.5, 'retry_period_max': 2.0}
    status = ros.collect(AxisStatus, AXIS_STATUS.of('mirrors'))
    diags = ros.collect(DiagnosticArray, DIAGNOSTICS.name)
    driver = launch('sslfr_drivers', 'axis_driver', params=params, name='mirrors_driver')   # autostart: default
    sim = None
    try:
        assert ros.spin_until(lambda: len(status) >= 3, 30), driver.output()
        t_first = time.monotonic()
        ros.spin_until(lambda: time.monotonic() > t_first + 5.0 or not driver.running(), 6.0)
        early = list(status)
        assert all(s.state == 'unconfigured' and s.link_state == 0 for s in early), [s.state for s in early]
        # 5 Hz while configure attempts come and go (an attempt never holds the heartbeat)
        assert len(early) >= 0.7 * 5 * (_stamp(early[-1]) - _stamp(early[0])) and _gaps(early) < 1.0, _gaps(early)
        sim = NodeProcess([sys.executable, '-m', 'sslfr_sim.runner', '--kind', 'axis', '--axis', 'mirrors',
                           '--link', port, '--seed', '7', '--opt', 'initial_angle_deg=10'],
                          ros_env, tmp_path / 'sim.log')
        t_board = time.monotonic()
        assert ros.spin_until(lambda: _active(ros, 'mirrors_driver'), 30), driver.output()
        print(f'\nboard appeared late: driver active {time.monotonic() - t_board:.1f} s after the port appeared')
        # every failed attempt is in diagnostics with its reason
        failed = {}
        for arr in diags:
            for st in arr.status:
                kv = {k.key: k.value for k in st.values}
                for entry in kv.get('attempts', '').split(' | '):
                    if 'failed:' in entry:
                        failed[entry.split()[0]] = entry
        assert ros.spin_until(lambda: any(k.key == 'lifecycle' and k.value == 'active'
                                          for a in diags[-1:] for s in a.status for k in s.values), 5)
        last = {k.key: k.value for k in diags[-1].status[0].values}
        n_failed = int(last['failed_attempts'])
        assert n_failed >= 3 and len(failed) == n_failed, (n_failed, sorted(failed))
        assert all(f'cannot reach the board on {port}' in e for e in failed.values()), failed
        assert 'ok' in last['attempts'].split(' | ')[-1] and last['lifecycle_goal'] == 'active'
        reasons = {e.split('failed: ', 1)[1] for e in failed.values()}
        assert driver.output().count('configure failed') == len(reasons)   # each reason logged once

        # SIGKILL and start again (what launch's respawn and sslfr up do): active by itself
        driver.signal(signal.SIGKILL)
        driver.proc.wait(5)
        n = len(status)
        again = launch('sslfr_drivers', 'axis_driver', params=params, name='mirrors_driver')
        assert ros.spin_until(lambda: len(status) > n and _active(ros, 'mirrors_driver'), 30), again.output()
        assert 'configured: board' in again.output()
    finally:
        if sim is not None:
            sim.stop()
        shutil.rmtree(d, ignore_errors=True)


# ----------------------------------------------------------------- issue 22: answered refusals
def test_every_lifecycle_request_is_answered_and_bad_inputs_are_refused(rig, ros):
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from sslfr_drivers.axis.lifecycle_ctl import get_state

    r = rig(sim_args=['--opt', 'initial_angle_deg=0'])
    name = 'mirrors_driver'
    assert r.wait_state('holding', 20), r.driver.output()

    def change(tid):
        req = ChangeState.Request()
        req.transition.id = tid
        return ros.call(ChangeState, f'{name}/change_state', req, timeout=10.0).success   # fails on no answer

    for tid in (99, 255, Transition.TRANSITION_CONFIGURE):
        assert change(tid) is False
    out = r.driver.output()
    assert 'lifecycle request refused: transition 99 is not possible from state active' in out
    assert 'transition 255 is not possible' in out and 'transition 1 is not possible from state active' in out
    assert ros.spin_until(lambda: r.diag().get('lifecycle_requests_refused') == '3', 3), r.diag()
    assert get_state(ros.node, name, executor=ros.executor) == 'active'

    # an outside deactivate is respected: the driver does not activate itself again
    assert change(Transition.TRANSITION_DEACTIVATE) is True
    ros.spin_for(2.0)                                     # 4 x retry_period: time to undo it, if it did
    assert get_state(ros.node, name, executor=ros.executor) == 'inactive'
    assert r.status[-1].state == 'inactive' and r.diag().get('lifecycle_goal') == 'inactive'
    assert change(Transition.TRANSITION_ACTIVATE) is True
    assert r.wait_state('holding', 5)

    # a port that cannot be a board is refused at run time with the reason, counted
    req = SetParameters.Request(parameters=[Parameter(name='port', value=ParameterValue(
        type=ParameterType.PARAMETER_STRING, string_value='/dev/null'))])
    res = ros.call(SetParameters, f'{name}/set_parameters', req).results[0]
    assert not res.successful and 'memory device' in res.reason, res.reason
    assert ros.spin_until(lambda: r.diag().get('parameter_changes_refused') == '1', 3), r.diag()
    assert r.diag()['port'] == r.port and 'parameter change refused' in r.driver.output()

    # malformed trajectories: duplicate joint names, a velocities list of the wrong length
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    from builtin_interfaces.msg import Duration
    bad = []
    for names, vel in ((['mirrors', 'mirrors'], [0.0, 0.0]), (['mobile_structure', 'mirrors'], [0.0])):
        msg = JointTrajectory(joint_names=names)
        msg.header.stamp = ros.node.get_clock().now().to_msg()
        msg.points = [JointTrajectoryPoint(positions=[0.0, 0.01], velocities=vel,
                                           time_from_start=Duration(sec=k)) for k in (1, 2)]
        bad.append(msg)
    for k, msg in enumerate(bad):
        r.pub_traj.publish(msg)
        assert ros.spin_until(lambda k=k: r.diag().get('trajectories_rejected') == str(k + 1), 5), r.diag()
    out = r.driver.output()
    assert 'trajectory refused (duplicate joint names: mirrors)' in out
    assert 'trajectory refused (point 0 has 1 velocities for 2 joints)' in out
    assert r.diag()['trajectories_accepted'] == '0' and r.status[-1].state == 'holding'


@pytest.mark.parametrize('signals', [('SIGINT',), ('SIGINT', 'SIGINT'), ('SIGTERM',)])
def test_stop_signals_with_the_link_up_exit_0_and_print_no_error(rig, ros, signals):
    """Issue 21: the axis driver, active with its board link UP (the link's reader and
    its logs running), stopped by SIGINT (a terminal), two SIGINTs 50 ms apart (ros2
    launch without a terminal) or SIGTERM (systemd): exit 0, its on_exit stops the
    board, and nothing is printed as an error (no log forwarded to rosout after the
    context is gone, no traceback)."""
    import signal as sig
    from sslfr_interfaces.msg import AxisStatus
    r = rig()
    assert ros.spin_until(lambda: bool(r.status) and r.status[-1].link_state == AxisStatus.LINK_UP
                          and r.status[-1].state not in ('unconfigured', 'inactive'), 20), \
        r.driver.output()
    for k, name in enumerate(signals):
        if k:
            time.sleep(0.05)
        r.driver.signal(getattr(sig, name))
    try:
        r.driver.proc.wait(10)
    except Exception:  # noqa: BLE001 - reported below with the output
        pass
    out = r.driver.output()
    assert r.driver.proc.returncode == 0, out
    for bad in ('Traceback', 'Failed to publish log message to rosout', 'context is invalid',
                'never retrieved', '[ERROR]'):
        assert bad not in out, out
    assert r.board()['speed'] == 0.0
