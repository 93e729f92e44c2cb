"""Unit tests of the axis driver's decisions that used to live in the node: the one
trajectory validation (joint extraction included), the parameter table, the port
check, the lifecycle policy (self-activation, answered requests), jog rules, the
ROS/steady time rate, the diagnostics verdict and the command bookkeeping."""
from __future__ import annotations

import math
import os
import stat as stat_mod
from types import SimpleNamespace

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sslfr_common.contract import JOINT_RANGE, JOINTS, STOW_POSITION, Phase
from sslfr_drivers.axis.activation import SelfActivation, check_request
from sslfr_drivers.axis.commands import Action, BoardState
from sslfr_drivers.axis.diagnostics import DIAG_ERROR, DIAG_OK, DIAG_WARN, diagnostic_verdict
from sslfr_drivers.axis.operator_input import operator_mode
from sslfr_drivers.axis.rates import TimeRate
from sslfr_drivers.axis.supervisor import AxisSupervisor, AxisTuning
from sslfr_drivers.axis.joint import Calibration, SoftLimits
from sslfr_drivers.axis.params import PARAMS, cross_check, params_for, port_problem, tuning_from
from sslfr_drivers.axis.trajectory import (
    TrajectoryMsg, TrajectoryPoint, TrajectoryRejected, TrajectoryStore, validate_trajectory,
)

MIRRORS = SoftLimits(*JOINT_RANGE['mirrors'])
NOW = 1_750_000_000.0


# ----------------------------------------------------------------- trajectory
def _msg(names, rows, start=NOW, vel=None, acc=None):
    """``rows``: per point (time_from_start, positions); ``vel``/``acc``: per point lists."""
    pts = tuple(TrajectoryPoint(t, tuple(p), tuple(vel[k]) if vel else (), tuple(acc[k]) if acc else ())
                for k, (t, p) in enumerate(rows))
    return TrajectoryMsg(tuple(names), start, pts)


def test_extracts_its_own_joint_by_name_not_by_position():
    msg = _msg(['mobile_structure', 'mirrors', 'secondary_reflector'],
               [(0.0, [0.5, 0.1, -0.2]), (10.0, [0.6, 0.2, -0.3])], vel=[[9, 0.01, 9], [9, 0.02, 9]])
    traj = validate_trajectory(msg, 'mirrors', NOW, MIRRORS)
    assert list(traj.positions) == [0.1, 0.2] and list(traj.velocities) == [0.01, 0.02]
    assert list(traj.times) == [NOW, NOW + 10.0]
    other = validate_trajectory(msg, 'secondary_reflector', NOW, SoftLimits(-1, 1))
    assert list(other.positions) == [-0.2, -0.3] and list(other.velocities) == [9, 9]


def test_zero_stamp_means_now_and_other_joints_are_ignored():
    traj = validate_trajectory(_msg(['mirrors'], [(1.0, [0.1]), (2.0, [0.2])], start=0.0),
                               'mirrors', NOW, MIRRORS)
    assert traj.start == NOW + 1.0
    store = TrajectoryStore()
    assert store.offer(_msg(['mobile_structure'], [(1.0, [float('nan')])]), 'mirrors', NOW, MIRRORS) is None
    assert store.current is None and store.accepted == store.rejected == 0   # not for us: nothing counted


@pytest.mark.parametrize('msg,word', [
    (_msg(['mirrors', 'mirrors'], [(1.0, [0.1, 0.1])]), 'duplicate joint names: mirrors'),
    (_msg(['mirrors', 'x', 'x'], [(1.0, [0.1, 0.0, 0.0])]), 'duplicate joint names: x'),
    (_msg(['x', 'mirrors'], [(1.0, [0.1, 0.1]), (2.0, [0.1, 0.1])], vel=[[0.0, 0.0], [0.0]]),
     'point 1 has 1 velocities for 2 joints'),
    (_msg(['x', 'mirrors'], [(1.0, [0.1, 0.1])], vel=[[0.0, 0.0, 0.0]]), '3 velocities for 2 joints'),
    (_msg(['x', 'mirrors'], [(1.0, [0.1, 0.1])], acc=[[0.0]]), '1 accelerations for 2 joints'),
    (_msg(['x', 'mirrors'], [(1.0, [0.1])]), 'point 0 has 1 positions for 2 joints'),
    (TrajectoryMsg(('mirrors',), NOW, (TrajectoryPoint(1.0, (0.1,), (0.0,)), TrajectoryPoint(2.0, (0.1,)))),
     'velocities on 1 of 2 points'),
    (_msg(['mirrors'], []), 'no points'),
])
def test_malformed_messages_are_refused_with_the_reason(msg, word):
    with pytest.raises(TrajectoryRejected, match=word):
        validate_trajectory(msg, 'mirrors', NOW, MIRRORS)
    store = TrajectoryStore()
    store.offer(_msg(['mirrors'], [(0.0, [0.0]), (10.0, [0.1])]), 'mirrors', NOW, MIRRORS)
    good = store.current
    assert word in store.offer(msg, 'mirrors', NOW, MIRRORS)
    assert store.current is good and store.rejected == 1 and word in store.last_reason


@given(st.lists(st.sampled_from(['mirrors', 'a', 'b']), min_size=1, max_size=5))
def test_any_duplicate_name_list_is_refused_when_it_names_the_joint(names):
    msg = _msg(names, [(1.0, [0.1] * len(names))])
    dup = len(set(names)) < len(names)
    if 'mirrors' not in names:
        assert validate_trajectory(msg, 'mirrors', NOW, MIRRORS) is None
    elif dup:
        with pytest.raises(TrajectoryRejected, match='duplicate'):
            validate_trajectory(msg, 'mirrors', NOW, MIRRORS)
    else:
        assert validate_trajectory(msg, 'mirrors', NOW, MIRRORS).positions[0] == 0.1


# ----------------------------------------------------------------- parameters
def test_table_per_axis_defaults_come_from_the_contract():
    for axis in JOINTS:
        v = params_for(axis).defaults()
        assert v['axis'] == axis and (v['lower_limit'], v['upper_limit']) == JOINT_RANGE[axis]
        assert v['stow_position'] == v['home_position'] == STOW_POSITION[axis]
        assert params_for(axis).validate(v) == []
    assert PARAMS.defaults()['axis'] == 'mirrors' and PARAMS.by_name['axis'].read_only
    # issue 21: self-activation is on unless a config turns it off
    assert PARAMS.defaults()['autostart'] is True
    with pytest.raises(KeyError):
        params_for('tower')


@pytest.mark.parametrize('change,word', [
    ({'lower_limit': 1.6}, 'soft limits need lower_limit < upper_limit'),
    ({'axis': 'mobile_structure', 'lower_limit': -1.6, 'stow_position': 0.0, 'home_position': 0.0,
      'wind_stow_position': 0.0, 'host_loss_stow_position': 0.0}, 'exceed the kinematic limits'),
    ({'stow_position': -0.5, 'lower_limit': -0.4}, 'stow_position'),
    ({'min_speed': 0.1, 'max_speed': 0.05}, 'min_speed > max_speed'),
    ({'max_speed': 5.0}, 'max_speed: 5.0 rad/s is outside'),
    ({'home_switch': 'middle'}, "home_switch: 'middle' is not one of low, high, sleep"),
    ({'axis': 'tower'}, "axis: 'tower' is not one of"),
])
def test_invalid_sets_are_refused_with_the_reason(change, word):
    errors = PARAMS.validate({**PARAMS.defaults(), **change})
    assert errors and word in '; '.join(errors)


def test_tuning_from_values():
    v = {**params_for('mobile_structure').defaults(), 'control_rate': 40.0, 'invert': True}
    assert cross_check(v) == []
    cfg, stall = tuning_from(v)
    assert isinstance(cfg, AxisTuning) and cfg.lead == pytest.approx(0.025) and cfg.calibration.invert
    assert cfg.limits.lower == -math.pi / 2 and stall.tolerance == v['lost_step_tolerance']


def _chr(major, minor):
    return lambda path: SimpleNamespace(st_mode=stat_mod.S_IFCHR | 0o660, st_rdev=os.makedev(major, minor))


@pytest.mark.parametrize('port,stat,word', [
    ('/dev/null', os.stat, 'memory device'),
    ('/dev/zero', os.stat, 'memory device'),
    ('/dev/ptmx', os.stat, 'pty multiplexer'),
    ('/dev/tty1', _chr(4, 1), 'virtual console'),
    ('/tmp', os.stat, 'not a character device'),
    ('foo://x', os.stat, 'unknown URL scheme'),
    ('xbee:/dev/ttyUSB0', os.stat, 'expected'),
    ('xbee:/dev/null?addr=0013A20012345678', os.stat, 'memory device'),
    ('/dev/ttyUSB0\nExec=x', os.stat, 'control characters'),
])
def test_ports_that_cannot_be_a_board(port, stat, word):
    why = port_problem(port, stat)
    assert why and word in why and port.split('?')[0].replace('xbee:', '')[:8] in why


@pytest.mark.parametrize('port,stat', [
    ('', os.stat), ('loop://', os.stat), ('socket://host:1', os.stat),
    ('/dev/sslfr/not-plugged-yet', os.stat),                          # appears later (issue 21)
    ('/dev/ttyUSB0', _chr(188, 0)), ('/dev/ttyACM0', _chr(166, 0)), ('/dev/ttyS0', _chr(4, 64)),
    ('/dev/pts/3', _chr(136, 3)), ('xbee:/dev/ttyUSB1?addr=0013A20012345678&baud=9600', _chr(188, 1)),
])
def test_ports_that_can_be_a_board(port, stat):
    assert port_problem(port, stat) is None


# ----------------------------------------------------------------- lifecycle policy
UNCONF = [(1, 'configure'), (5, 'shutdown')]
ACTIVE = [(4, 'deactivate'), (7, 'shutdown')]


@pytest.mark.parametrize('state,tid,label,avail,word', [
    ('active', 99, '', ACTIVE, 'transition 99 is not possible from state active'),
    ('unconfigured', 255, '', UNCONF, 'transition 255 is not possible'),
    ('active', 1, '', ACTIVE, 'possible: deactivate [4], shutdown [7]'),
    ('active', 0, 'configure', ACTIVE, "transition 'configure' is not possible"),
])
def test_impossible_requests_are_refused_with_a_reason(state, tid, label, avail, word):
    got, why = check_request(state, tid, label, avail)
    assert got == '' and word in why


def test_possible_requests_by_id_or_label():
    assert check_request('unconfigured', 1, '', UNCONF) == ('configure', '')
    assert check_request('active', 0, 'shutdown', ACTIVE) == ('shutdown', '')
    assert check_request('active', 7, '', ACTIVE) == ('shutdown', '')


def test_configure_retried_with_doubling_back_off_then_activation():
    a = SelfActivation(True, 0.5, 2.0)
    assert a.next_transition('unconfigured', 0.0) == 'configure'
    tries = []
    t = 0.0
    while len(tries) < 6:            # the board is missing: every configure fails
        if a.next_transition('unconfigured', t) == 'configure':
            tries.append(t)
            a.record(t, 'configure', False, f'no INFO ({len(tries)})')
        t = round(t + 0.05, 2)
    assert [round(b - a_, 2) for a_, b in zip(tries, tries[1:])] == [0.5, 1.0, 2.0, 2.0, 2.0]
    assert a.failures == 6 and 'next in' in a.pending('unconfigured', t)
    a.record(t, 'configure', True)
    assert a.next_transition('inactive', t) == 'activate' and a.wait == 0.5
    a.record(t, 'activate', True)
    assert a.next_transition('active', t + 100) is None and a.pending('active', t) == ''
    hist = a.values(t)['attempts'].split(' | ')
    assert len(hist) == 8 and 'failed: no INFO (6)' in hist[-3] and hist[-1].endswith('activate at +%.1f s: ok' % t)


def test_external_requests_set_the_goal_and_are_not_undone():
    a = SelfActivation(True, 0.1, 1.0)
    a.external('deactivate')
    assert a.goal == 'inactive' and a.next_transition('inactive', 10.0) is None
    a.external('configure')                    # does not raise an inactive goal to active
    assert a.goal == 'inactive'
    a.external('cleanup')
    assert a.next_transition('unconfigured', 10.0) is None
    a.external('activate')
    assert a.next_transition('unconfigured', 10.0) == 'configure'
    a.external('configure')                    # keeps the active goal
    assert a.goal == 'active'
    a.external('shutdown')
    assert a.next_transition('finalized', 10.0) is None
    # a node that fell back by itself (ErrorProcessing -> unconfigured) climbs back
    b = SelfActivation(True)
    b.record(0.0, 'configure', True)
    b.record(0.0, 'activate', True)
    assert b.next_transition('unconfigured', 1.0) == 'configure'
    assert SelfActivation(False).next_transition('unconfigured', 1e9) is None
    b.refuse('transition 99 is not possible')
    assert b.values(1.0)['lifecycle_requests_refused'] == '1'


# ----------------------------------------------------------------- node decisions
def _sup():
    cfg = AxisTuning('mirrors', Calibration(), MIRRORS, 0.05, 0.0005, 0.05, math.pi / 2, 'sleep',
                     math.pi / 2, 0.02)
    sup = AxisSupervisor(cfg)
    sup.safety.receive(0.0, 0, False, [], 1)
    return sup


HOMED = BoardState(0, 0, False, True, False, 0.1)


def test_jog_rules_in_order():
    sup = _sup()
    assert 'not in maintenance' in sup.request_jog(0.01, 0.0, HOMED, True, 0.2)[1]
    assert sup.set_mode(operator_mode(Phase.MAINTENANCE, 'auto')) and sup.mode == 'maintenance'
    assert 'not active' in sup.request_jog(0.01, 0.0, HOMED, False, 0.2)[1]
    assert 'board not answering' in sup.request_jog(0.01, 0.0, None, True, 0.2)[1]
    assert 'not homed' in sup.request_jog(0.01, 0.0, BoardState(0, 0, False, False, False, 0.1), True, 0.2)[1]
    for delta in (0.3, float('nan'), float('inf')):
        assert 'max_jog 0.2000' in sup.request_jog(delta, 0.0, HOMED, True, 0.2)[1]
    assert 'speed' in sup.request_jog(0.01, -1.0, HOMED, True, 0.2)[1]
    ok, msg, target = sup.request_jog(0.15, 0.0, HOMED, True, 0.2)
    assert ok and target == pytest.approx(0.25) and sup.jog_target == target
    ok, _, target = sup.request_jog(0.15, 0.0, HOMED, True, 0.2)          # jogs add up
    assert ok and target == pytest.approx(0.40)
    sup2 = _sup()
    sup2.set_mode('maintenance')
    assert 'outside soft limits' in sup2.request_jog(-0.2, 0.0, BoardState(0, 0, False, True, False, -0.7),
                                                     True, 0.2)[1]
    sup.fault = 'stall'
    assert 'fault: stall' in sup.request_jog(0.01, 0.0, HOMED, True, 0.2)[1]
    assert sup.set_mode('auto') and sup.jog_target is None            # leaving maintenance drops the jog


def test_operator_mode_and_home_request():
    assert operator_mode(Phase.MANUAL, 'auto') == 'manual' == operator_mode(Phase.TRACKING, 'manual')
    assert operator_mode(Phase.STOW, 'stow') == 'auto' == operator_mode(Phase.STOWING, 'auto')
    sup = _sup()
    assert sup.request_home(False) == (False, 'driver not active')
    sup.fault = 'lost steps'
    ok, msg = sup.request_home(True)
    assert ok and sup.home_requested and sup.fault is None and 'sleep switch' in msg


def test_time_rate_real_time_sim_time_and_jumps():
    r = TimeRate()
    for k in range(50):
        rate = r.update(1000.0 + 0.05 * k, 0.05 * k)
    assert rate == pytest.approx(1.0)
    for k in range(50, 120):                    # a simulated day at 400 x
        rate = r.update(1002.5 + 20.0 * (k - 49), 0.05 * k)
    assert rate == pytest.approx(400.0, rel=1e-6)
    assert r.update(0.0, 6.05) == pytest.approx(400.0)          # ROS time went back: ignored
    assert r.update(1e12, 6.1) == pytest.approx(400.0)          # a jump beyond 1e5 x: ignored
    assert r.update(1e12, 6.1) == pytest.approx(400.0)          # no steady time elapsed


def test_diagnostic_levels_match_the_message_and_their_choice():
    from diagnostic_msgs.msg import DiagnosticStatus
    assert (bytes([DIAG_OK]), bytes([DIAG_WARN]), bytes([DIAG_ERROR])) == (
        DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR)
    sup = _sup()
    assert diagnostic_verdict('unconfigured', sup, False, 'cannot reach the board') == (
        DIAG_ERROR, 'cannot reach the board')
    assert diagnostic_verdict('inactive', sup, True, '') == (DIAG_WARN, 'inactive: not active')
    sup.state, sup.reason = 'stopped', 'safety/state silent'
    assert diagnostic_verdict('active', sup, True, '') == (DIAG_WARN, 'stopped: safety/state silent')
    sup.state, sup.reason = 'following', ''
    assert diagnostic_verdict('active', sup, True, 'old nack') == (DIAG_OK, 'following')
    sup.fault = 'stall: ...'
    assert diagnostic_verdict('active', sup, True, '') == (DIAG_ERROR, 'stall: ...')


def test_command_bookkeeping_counts_and_throttles():
    sup = _sup()
    assert sup.record_write(Action('move', 5, 10.0), True) is None
    assert sup.counts()['moves_sent'] == 1
    logged = [sup.record_write(Action('move', 5, 10.0), False, 'NOT_HOMED', True) for _ in range(40)]
    assert sum(x is not None for x in logged) == 2 and 'refused by the board: NOT_HOMED' in logged[0]
    assert sup.record_write(Action('stop'), False, 'no answer') == 'stop not answered by the board: no answer'
    c = sup.counts()
    assert (c['moves_sent'], c['nacks'], c['nacks_not_homed'], c['stops_sent'], c['request_timeouts']) == (
        41, 40, 40, 1, 1)
    assert sup.note_link_events(True, True) == [
        'board reset or reconnected: position must be re-established', 'link re-established']
    assert sup.counts()['board_resets'] == sup.counts()['reconnects'] == 1


def test_a_latched_fault_is_counted_once_and_snapshot():
    sup = _sup()
    sup.safety.timeout = 1e9
    b = BoardState(0, 10, True, True, False, 0.0, 0, 1 << 4)       # DRIVER fault bit
    kinds = [sup.tick(0.0, 0.1 * k, b, True).kind for k in range(5)]
    assert kinds[0] == 'stop' and sup.counts()['faults'] == 1
    assert sup.take_new_fault().startswith('board reports fault bits') and sup.take_new_fault() is None
    snap = sup.snapshot(12.5, b)
    assert snap.stamp == 12.5 and snap.state == 'fault' and snap.measured == 0.0 and snap.board is b
    assert math.isnan(sup.snapshot(13.0, None).measured)


def test_host_loss_stow_record_from_the_parameters_and_refused_values():
    """Issue 35: the driver's host_loss_stow parameters -> the board's SET_HOST_LOSS_STOW."""
    from sslfr_drivers.axis.host_loss import configure_host_loss, describe, host_loss_request
    from sslfr_drivers.axis.params import params_for
    from sslfr_drivers.link import messages as m
    p = params_for('mirrors').defaults()
    r = host_loss_request(p)
    assert (r.mode, r.steps, r.delay_ms) == (m.HostLossMode.POSITION, round((math.pi / 2) / m.DEFAULT_STEP_RAD),
                                            60000)
    assert r.speed == pytest.approx(p['max_speed'] / m.DEFAULT_STEP_RAD)
    sw = host_loss_request({**p, 'host_loss_stow': 'switch', 'invert': True})
    assert sw.mode == m.HostLossMode.SWITCH and sw.switch == m.Switch.SLEEP and sw.speed < 0   # up = fewer steps
    assert host_loss_request({**p, 'host_loss_stow': 'off'}).mode == m.HostLossMode.OFF
    assert describe({**p, 'host_loss_stow': 'off'}) == 'host-loss stow off'
    table = params_for('mirrors')
    assert any('host_loss_stow_position' in e for e in table.validate({**p, 'host_loss_stow_position': -1.0}))
    assert table.validate({**p, 'host_loss_stow_delay': 0.0}) and table.validate({**p, 'host_loss_stow': 'up'})

    class Link:
        last_status = m.Status(0, 0, 0.0, 0, 0, int(m.FaultBits.HOST_LOSS), 0.0, 0)

        def request(self, msg):
            raise RuntimeError('NACK UNKNOWN_TYPE')          # an older firmware
    line = configure_host_loss(Link(), p)
    assert 'NOT set' in line and 'stowed by itself' in line


def test_a_lost_status_answer_reuses_the_previous_one_while_fresh_or_at_rest():
    """One late STATUS while idle (polls every idle_poll_period, 0.2 s, longer than 3
    control periods) keeps the board state of the previous poll (a CI run refused an
    operator's jog as 'board not answering' on one); a moving or homing board's older
    STATUS is not reused."""
    from sslfr_drivers.axis.board_session import reusable_status
    period, idle = 0.05, 0.2
    rest = BoardState(steps=10, target=10, moving=False, homed=True, homing=False, sensor=None)
    moving = BoardState(steps=10, target=90, moving=True, homed=True, homing=False, sensor=None)
    homing = BoardState(steps=10, target=10, moving=True, homed=False, homing=True, sensor=None)
    max_age, rest_age = 3 * period, idle + 2 * period
    for s in (rest, moving, homing):
        assert reusable_status(0.1, s, max_age, rest_age)               # within 3 control periods: any
    assert reusable_status(0.25, rest, max_age, rest_age)                # one idle poll + 2 periods: at rest
    assert not reusable_status(0.25, moving, max_age, rest_age)
    assert not reusable_status(0.25, homing, max_age, rest_age)
    assert not reusable_status(0.31, rest, max_age, rest_age)            # two answers lost: none


def test_a_refused_jog_says_which_of_driver_and_board_is_missing():
    from sslfr_drivers.axis.operator_input import check_jog
    rest = BoardState(steps=10, target=10, moving=False, homed=True, homing=False, sensor=None)
    assert check_jog('maintenance', False, rest, None, 0.01, 0.0, 0.1) == 'jog refused: driver not active'
    assert check_jog('maintenance', True, None, None, 0.01, 0.0, 0.1) == 'jog refused: board not answering'
    assert check_jog('maintenance', True, rest, None, 0.01, 0.0, 0.1) == ''


def test_the_session_reuses_a_resting_status_for_one_lost_answer_but_not_after_a_command():
    """AxisBoardSession.poll on a link whose STATUS answers are lost on demand: an idle
    board's previous STATUS stands in for one lost answer (0.25 s old with 0.05 s
    control periods); once a command went out after it (here a HOME), it does not: the
    board may be moving."""
    from sslfr_drivers.axis.board_session import AxisBoardSession
    from sslfr_drivers.axis.commands import ActionKind
    from sslfr_drivers.link import messages as msg
    from sslfr_drivers.link.board_link import LinkError, LinkState

    class Link:
        state, resets, lose = LinkState.UP, 0, False

        def request(self, message, **_kw):
            if isinstance(message, msg.GetStatus):
                if self.lose:
                    raise LinkError('time-out')
                return msg.Status(10, 10, 0.0, int(msg.StatusFlags.HOMED), 0, 0, float('nan'), 1000)
            return msg.Ack(message.TYPE)

    s = AxisBoardSession.__new__(AxisBoardSession)
    s.link, s.reference, s.request_timeout = Link(), None, 0.1
    s._seen_resets, s._last_ok, s._commanded, s.poll_failures, s.stale_polls = 0, None, False, 0, 0
    period, idle = 0.05, 0.2
    assert s.poll(0.0, 2 * period, 3 * period, idle + 2 * period).homed
    s.link.lose = True
    assert s.poll(0.25, 2 * period, 3 * period, idle + 2 * period) is not None and s.stale_polls == 1
    assert s.write(Action(ActionKind.HOME, switch=int(msg.Switch.LOW), speed=100.0)).ok
    assert s.poll(0.25, 2 * period, 3 * period, idle + 2 * period) is None
    assert s.poll(0.1, 2 * period, 3 * period, idle + 2 * period) is not None    # within 3 periods: as before
