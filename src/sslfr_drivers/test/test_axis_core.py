"""Unit tests of the axis driver's pure core (numbers in, numbers out)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sslfr_common.contract import JOINT_RANGE, STEP_ANGLE
from sslfr_drivers.axis.safety_watch import SafetyVerdict, SafetyWatch
from sslfr_drivers.axis.stall import StallDetector
from sslfr_drivers.axis.joint import Calibration, SoftLimits, move_speed
from sslfr_drivers.axis.trajectory import TrajectoryMsg, TrajectoryRejected, TrajectoryStore
from sslfr_drivers.axis.trajectory import validate_trajectory as _validate


def validate_trajectory(times, positions, velocities, now, limits):
    """One joint's points through the one validation."""
    return _validate(TrajectoryMsg.for_joint('mirrors', times, positions, velocities), 'mirrors', now, limits)


def offer(store, times, positions, velocities, now, limits):
    """Offer one joint's points to a store (the mirrors driver's)."""
    return store.offer(TrajectoryMsg.for_joint('mirrors', times, positions, velocities), 'mirrors', now, limits)


MIRRORS = SoftLimits(*JOINT_RANGE['mirrors'])


def test_seed_step_is_0_006_degrees():
    cal = Calibration()
    assert math.degrees(cal.joint_per_step) == pytest.approx(0.006)
    # seed 000 section 3.5.2: -45 .. +90 deg is 22500 steps
    assert cal.steps(math.pi / 2) - cal.steps(-math.pi / 4) == 22500


@given(theta=st.floats(-3, 3), ratio=st.floats(0.1, 100), offset=st.floats(-1, 1),
       invert=st.booleans())
def test_steps_round_trip_within_half_a_step(theta, ratio, offset, invert):
    cal = Calibration(STEP_ANGLE, ratio, offset, invert)
    back = cal.angle(cal.steps(theta))
    assert abs(back - theta) <= abs(cal.joint_per_step) / 2 + 1e-12


def test_gear_ratio_and_invert():
    cal = Calibration(math.radians(1.8), 10.0, 0.1, True)
    assert cal.steps(0.1 + math.radians(0.18)) == -1
    assert cal.step_rate(math.radians(1.8)) == pytest.approx(10.0)


@pytest.mark.parametrize('kw', [dict(step_angle=0.0), dict(gear_ratio=-1.0),
                                dict(step_angle=float('nan')), dict(offset=float('inf'))])
def test_bad_calibration_refused(kw):
    with pytest.raises(ValueError):
        Calibration(**kw)


def test_soft_limits():
    assert MIRRORS.contains(math.pi / 2) and not MIRRORS.contains(math.pi / 2 + 1e-6)
    assert MIRRORS.clamp(-1.0) == -math.pi / 4
    with pytest.raises(ValueError):
        SoftLimits(1.0, 0.0)


def test_move_speed_is_bounded():
    assert move_speed(0.0, 0.01, 0.1, 0.05, 0.001) == pytest.approx(0.05)
    assert move_speed(0.0, 0.001, 0.1, 0.05, 0.001) == pytest.approx(0.01)
    assert move_speed(0.0, 0.0, 0.1, 0.05, 0.001) == pytest.approx(0.001)


def test_trajectory_refusals_keep_last_good():
    store = TrajectoryStore()
    now = 1_700_000_000.0
    assert offer(store, [now, now + 10], [0.0, 0.1], None, now, MIRRORS) is None
    good = store.current
    for times, pos, vel, word in [
        ([now, now + 1], [0.0, float('nan')], None, 'non-finite'),
        ([now, now + 1], [0.0, 2.0], None, 'outside soft limits'),
        ([now - 10, now - 1], [0.0, 0.1], None, 'past-only'),
        ([now, now], [0.0, 0.1], None, 'strictly increasing'),
        ([], [], None, 'no points'),
        ([now, now + 1], [0.0, 0.1], [0.0, float('inf')], 'velocity'),
    ]:
        reason = offer(store, times, pos, vel, now, MIRRORS)
        assert reason is not None and word in reason
        assert store.current is good
    assert store.rejected == 6 and store.accepted == 1


def test_setpoint_interpolates_and_holds_on_starvation():
    store = TrajectoryStore()
    now = 100.0
    offer(store, [110.0, 120.0], [0.0, 0.2], None, now, MIRRORS)
    assert store.setpoint(105.0) == (0.0, 0.0, 'waiting')
    pos, vel, st_ = store.setpoint(115.0)
    assert st_ == 'following' and pos == pytest.approx(0.1) and vel == pytest.approx(0.02)
    assert store.setpoint(200.0) == (0.2, 0.0, 'starved')


@settings(max_examples=50)
@given(a=st.floats(-0.5, 0.5), w=st.floats(0.001, 0.01))
def test_hermite_interpolation_of_a_sine_is_accurate(a, w):
    t = np.linspace(0, 600, 61)
    traj = validate_trajectory(t, a * np.sin(w * t), a * w * np.cos(w * t), 0.0, SoftLimits(-1, 1))
    tt = np.linspace(0, 600, 997)
    err = max(abs(traj.sample(x)[0] - a * math.sin(w * x)) for x in tt)
    # Hermite error <= h^4 max|f''''| / 384 with h = 10 s
    assert err <= 10 ** 4 * abs(a) * w ** 4 / 384 + 1e-12


def test_validate_raises_declared_error():
    with pytest.raises(TrajectoryRejected):
        validate_trajectory([1.0], [0.0, 1.0], None, 0.0, MIRRORS)


def test_safety_watch_timeout_on_steady_clock():
    w = SafetyWatch('mirrors', 1.0)
    assert w.verdict(0.0)[0] is SafetyVerdict.STOP          # never heard
    w.receive(10.0, 0, False, [], 1)
    assert w.verdict(10.9)[0] is SafetyVerdict.FOLLOW
    v, reason = w.verdict(11.01)
    assert v is SafetyVerdict.STOP and 'silent' in reason
    # the same sequence again is not a heartbeat
    assert not w.receive(11.5, 0, False, [], 1)
    assert w.verdict(11.5)[0] is SafetyVerdict.STOP
    assert w.receive(11.6, 0, False, [], 2)
    assert w.verdict(11.6)[0] is SafetyVerdict.FOLLOW


def test_safety_silence_stops_then_stows_fail_safe():
    """Issues 7/9: supervisor gone -> stopped within the timeout, then stowing."""
    w = SafetyWatch('mirrors', 1.0, silent_stow_after=1.0)
    w.receive(10.0, 0, False, [], 1)
    assert w.verdict(11.5)[0] is SafetyVerdict.STOP
    v, reason = w.verdict(12.01)
    assert v is SafetyVerdict.STOW and 'fail-safe stow' in reason
    fresh = SafetyWatch('mirrors', 1.0)                       # never heard at boot: no motion at all
    assert fresh.verdict(1e6)[0] is SafetyVerdict.STOP


@pytest.mark.parametrize('level,stow,stopped,expect', [
    (3, False, [], SafetyVerdict.STOP),
    (3, True, [], SafetyVerdict.STOP),
    (1, False, ['mirrors'], SafetyVerdict.STOP),
    (1, False, ['mobile_structure'], SafetyVerdict.FOLLOW),
    (3, False, ['mobile_structure'], SafetyVerdict.FOLLOW),   # a switch trip stops its own axis only
    (3, True, ['mobile_structure'], SafetyVerdict.STOW),
    (3, False, ['mirrors', 'mobile_structure'], SafetyVerdict.STOP),
    (2, True, [], SafetyVerdict.STOW),
    (0, True, [], SafetyVerdict.STOW),
    (1, False, [], SafetyVerdict.FOLLOW),
])
def test_safety_levels(level, stow, stopped, expect):
    w = SafetyWatch('mirrors')
    w.receive(0.0, level, stow, stopped, 7, ['x'])
    assert w.verdict(0.1)[0] is expect


def test_lost_steps_detected():
    d = StallDetector(tolerance=0.005)
    assert d.update(0.0, 0.100, 0.102, False, False) is None
    reason = d.update(0.1, 0.100, 0.110, False, False)
    assert reason and 'lost steps' in reason


def test_stall_motor_steps_but_sensor_still():
    d = StallDetector(tolerance=1.0, window=1.0, min_motion=0.01)
    out = None
    for k in range(12):
        out = d.update(k * 0.1, 0.005 * k, 0.0, True, True) or out
    assert out and 'stall' in out


def test_no_stall_when_sensor_follows_with_noise():
    rng = np.random.default_rng(1)
    d = StallDetector(tolerance=0.003, window=1.0, min_motion=0.01)
    for k in range(100):
        s = 0.005 * k
        assert d.update(k * 0.1, s, s + rng.normal(0, 0.0005), True, True) is None


def test_stall_without_sensor_pending_move_not_moving():
    d = StallDetector(tolerance=0.01, window=1.0)
    assert d.update(0.0, 0.0, None, False, True) is None
    assert d.update(0.5, 0.0, None, False, True) is None
    assert 'pending' in d.update(1.2, 0.0, None, False, True)
    d.reset()
    assert d.update(2.0, 0.0, None, True, True) is None


# ----------------------------------------------------------------- supervisor
from sslfr_drivers.axis.commands import Action, BoardState  # noqa: E402
from sslfr_drivers.axis.supervisor import AxisSupervisor  # noqa: E402
from sslfr_drivers.axis.supervisor import AxisTuning as AxisConfig  # noqa: E402


def _sup(use_sensor=True, auto_home=True):
    cfg = AxisConfig('mirrors', Calibration(), MIRRORS, max_speed=0.05, min_speed=0.0005,
                     lead=0.05, stow_position=math.pi / 2, home_switch='sleep',
                     home_position=math.pi / 2, home_speed=0.02, use_sensor=use_sensor,
                     auto_home=auto_home)
    sup = AxisSupervisor(cfg)
    sup.safety.receive(0.0, 0, False, [], 1)
    return sup


def _board(steps=0, moving=False, homed=True, sensor=0.0, target=None):
    return BoardState(steps, steps if target is None else target, moving, homed, False, sensor)


def test_supervisor_follows_setpoint_ahead_by_lead():
    sup = _sup()
    offer(sup.store, [100.0, 200.0], [0.0, 0.1], None, 100.0, MIRRORS)
    act = sup.tick(150.0, 0.5, _board(), True)
    cal = Calibration()
    assert act.kind == 'move' and act.steps == cal.steps(0.05 + 0.001 * 0.05)
    assert sup.state == 'following'
    assert act.speed <= cal.step_rate(0.05) + 1e-9


def test_supervisor_never_moves_when_position_lost():
    sup = _sup(use_sensor=False)
    offer(sup.store, [100.0, 200.0], [0.0, 0.1], None, 100.0, MIRRORS)
    act = sup.tick(150.0, 0.5, _board(homed=False, sensor=None), True)
    assert act.kind == 'home' and act.speed > 0 and act.steps == Calibration().steps(math.pi / 2)
    sup2 = _sup(use_sensor=True)
    offer(sup2.store, [100.0, 200.0], [0.0, 0.1], None, 100.0, MIRRORS)
    acts = [sup2.tick(150.0, 0.5 + 0.05 * k, _board(steps=5, homed=False, sensor=0.0123 + d), True)
            for k, d in enumerate([1e-5, -1e-5, 2e-5, -2e-5, 0.0])]
    assert [a.kind for a in acts] == ['none'] * 4 + ['set_zero']          # 5 samples averaged
    assert acts[-1] == Action('set_zero', Calibration().steps(0.0123))
    sup3 = _sup(use_sensor=False, auto_home=False)
    offer(sup3.store, [100.0, 200.0], [0.0, 0.1], None, 100.0, MIRRORS)
    assert sup3.tick(150.0, 0.5, _board(homed=False, sensor=None), True).kind == 'none'
    assert sup3.state == 'fault'


def test_published_position_is_unknown_until_the_axis_is_referenced():
    """A board after power-up or a reset counts steps from 0 wherever the axis is: without
    a position sensor the published angle is NaN until homed (the safety supervisor
    once judged the mirrors' sleeping switch, closed at dawn, 90 deg from that 0);
    while homing the relative step count is published (stuck-switch travel)."""
    sup = _sup(use_sensor=False)
    cal = Calibration()
    assert math.isnan(sup.snapshot(1.0, None).measured)
    assert math.isnan(sup.snapshot(1.0, _board(steps=0, homed=False, sensor=None)).measured)
    homing = BoardState(120, 0, True, False, True, None)
    assert sup.snapshot(1.0, homing).measured == pytest.approx(cal.angle(120))
    assert sup.snapshot(1.0, _board(steps=300, homed=True, sensor=None)).measured == pytest.approx(cal.angle(300))
    # an absolute sensor knows the angle before referencing
    assert _sup(use_sensor=True).snapshot(1.0, _board(homed=False, sensor=0.25)).measured == 0.25
    assert math.isnan(_sup(use_sensor=False).snapshot(1.0, _board(homed=False, sensor=0.25)).measured)


def test_supervisor_stops_on_safety_silence_and_stows():
    sup = _sup()
    offer(sup.store, [100.0, 200.0], [0.0, 0.1], None, 100.0, MIRRORS)
    assert sup.tick(150.0, 0.9, _board(), True).kind == 'move'
    assert sup.tick(150.1, 1.05, _board(moving=True, steps=3, sensor=3 * Calibration().joint_per_step), True).kind == 'stop'
    assert sup.state == 'stopped'
    sup.safety.receive(1.1, 2, True, [], 2)
    act = sup.tick(150.2, 1.2, _board(), True)
    assert act.kind == 'move' and act.steps == Calibration().steps(math.pi / 2) and sup.state == 'stowing'


def test_supervisor_inactive_stops_and_stall_latches():
    sup = _sup()
    assert sup.tick(0.0, 0.1, _board(moving=True), False).kind == 'stop'
    offer(sup.store, [0.0, 100.0], [0.0, 0.5], None, 0.0, MIRRORS)
    sup.safety.timeout = 1e9
    kinds = []
    for k in range(15):   # motor steps, sensor stuck at 0
        steps = 100 * k
        kinds.append(sup.tick(10.0 + 0.1 * k, 0.1 * k, _board(steps=steps, moving=True, sensor=0.0), True).kind)
    assert 'stop' in kinds and sup.state == 'fault' and 'lost steps' in sup.fault
    assert sup.tick(20.0, 5.0, _board(steps=1500, sensor=0.0), True).kind == 'none'
    assert sup.state == 'fault'


def test_supervisor_starvation_holds_last_point():
    sup = _sup()
    offer(sup.store, [100.0, 110.0], [0.0, 0.01], None, 100.0, MIRRORS)
    cal = Calibration()
    act = sup.tick(500.0, 0.5, _board(steps=cal.steps(0.01), sensor=0.01), True)
    assert act.kind == 'none' and sup.state == 'holding'


def test_home_direction_toward_sleep_switch_inside_the_range():
    cfg = AxisConfig('mobile_structure', Calibration(), SoftLimits(-math.pi / 2, math.pi / 2),
                     0.05, 0.0005, 0.05, 0.0, 'sleep', 0.0, 0.02, use_sensor=False)
    sup = AxisSupervisor(cfg)
    sup.safety.receive(0.0, 0, False, [], 1)
    cal = Calibration()
    sup.tick(0.0, 0.1, BoardState(cal.steps(0.2), cal.steps(0.2), False, True, False, None), True)
    act = sup.tick(0.0, 0.2, BoardState(0, 0, False, False, False, None), True)   # reset at +0.2 rad
    assert act.kind == 'home' and act.speed < 0 and act.switch == 2 and act.steps == 0
    # a homing attempt that ended on the LOW switch goes back up
    act = sup.tick(0.0, 0.3, BoardState(0, 0, False, False, False, None, limit_bits=1), True)
    assert act.kind == 'home' and act.speed > 0


def test_setpoint_lead_scales_with_the_ros_time_rate():
    sup = _sup()
    offer(sup.store, [0.0, 1000.0], [0.0, 0.5], None, 0.0, MIRRORS)
    cal = Calibration()
    a1 = sup.tick(100.0, 0.5, _board(steps=cal.steps(0.05), sensor=0.05), True, time_rate=1.0)
    a40 = sup.tick(100.0, 0.6, _board(steps=cal.steps(0.05), sensor=0.05), True, time_rate=40.0)
    assert a1.steps == cal.steps(0.05 + 0.0005 * 0.05)
    assert a40.steps == cal.steps(0.05 + 0.0005 * 0.05 * 40)
    # the speed is per wall second: reach the target in one control period...
    assert a40.speed == pytest.approx(cal.step_rate(0.0005 * 40), rel=0.02)
    # ... but never above max_speed (0.05 rad/s)
    a400 = sup.tick(100.0, 0.7, _board(steps=cal.steps(0.05), sensor=0.05), True, time_rate=400.0)
    assert a400.speed == pytest.approx(cal.step_rate(0.05))


def test_board_fault_bits_latch_a_fault_and_match_the_protocol():
    from sslfr_drivers.link import messages as m
    from sslfr_drivers.axis.commands import BOARD_FAULT_DRIVER, BOARD_FAULT_STALL
    assert BOARD_FAULT_STALL == m.FaultBits.STALL and BOARD_FAULT_DRIVER == m.FaultBits.DRIVER
    sup = _sup()
    offer(sup.store, [100.0, 200.0], [0.0, 0.1], None, 100.0, MIRRORS)
    b = BoardState(0, 10, True, True, False, 0.0, 0, int(m.FaultBits.DRIVER))
    assert sup.tick(150.0, 0.5, b, True).kind == 'stop'
    assert sup.state == 'fault' and 'driver' in sup.fault


def test_sensor_fault_bit_drops_the_sensor():
    from sslfr_drivers.link import messages as m
    from sslfr_drivers.axis.board_session import board_from_status as board_state
    st = m.Status(100, 100, 0.0, int(m.StatusFlags.HAS_SENSOR | m.StatusFlags.HOMED), 0, 0, 0.5, 1)
    assert board_state(st).sensor == pytest.approx(0.5)
    st = m.Status(100, 100, 0.0, int(m.StatusFlags.HAS_SENSOR), 0, int(m.FaultBits.SENSOR), 0.5, 1)
    assert board_state(st).sensor is None
    st = m.Status(100, 100, 0.0, 0, 0, 0, float('nan'), 1)
    assert board_state(st).sensor is None


def test_next_tick_fast_while_under_way_else_at_the_safety_deadline():
    sup = _sup()                                     # safety/state received at steady 0.0
    assert sup.next_tick(0.0, 0.1, None, 1.0, 0.05, 0.5) == 0.05                 # no board
    assert sup.next_tick(0.0, 0.1, _board(moving=True), 1.0, 0.05, 0.5) == 0.05
    assert sup.next_tick(0.0, 0.1, _board(homed=False), 1.0, 0.05, 0.5) == 0.05
    assert sup.next_tick(0.0, 0.1, _board(), 1.0, 0.05, 0.5) == 0.5                # idle poll
    assert sup.next_tick(0.0, 0.7, _board(), 1.0, 0.05, 0.5) == pytest.approx(0.301)  # STOP deadline
    assert sup.next_tick(0.0, 1.6, _board(), 1.0, 0.05, 0.5) == pytest.approx(0.401)  # then STOW
    assert sup.next_tick(0.0, 1.98, _board(), 1.0, 0.05, 0.5) == 0.05              # never below fast
    offer(sup.store, [100.0, 200.0], [0.0, 0.1], None, 100.0, MIRRORS)
    assert sup.tick(150.0, 0.2, _board(), True).kind == 'move'
    assert sup.next_tick(150.0, 0.2, _board(), 1.0, 0.05, 0.5) == 0.05             # MOVE not reached yet


def test_next_tick_follows_the_sun_one_step_at_a_time():
    """A real-time tracking minute: the supervisor, polled only when next_tick says,
    sends one MOVE per step the setpoint crosses, never lags it by a step, and polls
    far less than the 20 Hz control rate."""
    sup = _sup()
    sup.safety.timeout = 1e9
    cal = Calibration()
    rate = 1.1 * cal.joint_per_step / 1.5            # about one step every 1.4 s (the sun)
    offer(sup.store, [0.0, 600.0], [0.1, 0.1 + 600.0 * rate], None, 0.0, MIRRORS)
    steps, t, ticks, moves, worst = cal.steps(0.1), 10.0, 0, 0, 0
    while t < 70.0:
        act = sup.tick(t, t, _board(steps=steps, sensor=cal.angle(steps)), True)
        ticks += 1
        if act.kind == 'move':
            moves += 1
            steps = act.steps                         # the board gets there within the tick
            act = sup.tick(t, t, _board(steps=steps, sensor=cal.angle(steps)), True)
            assert act.kind == 'none'
        worst = max(worst, abs(cal.steps(sup.store.setpoint(t + sup.cfg.lead)[0]) - steps))
        t += sup.next_tick(t, t, _board(steps=steps, sensor=cal.angle(steps)), 1.0, 0.05, 0.5)
    assert worst <= 1 and 38 <= moves <= 46, (worst, moves)
    assert ticks < 60 * 3, ticks                      # 20 Hz would be 1200
    # 90x faster than real time (a simulated day): a step every 17 ms, the control rate
    board = _board(steps=steps, sensor=cal.angle(steps))
    assert sup.next_tick(t, t, board, 90.0, 0.05, 0.5) == 0.05


def test_time_rate_ignores_a_step_right_after_a_clock_jump():
    from sslfr_drivers.axis.rates import TimeRate
    r = TimeRate()
    t_ros, t_st = 1000.0, 0.0
    for _ in range(40):                   # 90x, /clock every 50 ms wall
        t_ros, t_st = t_ros + 4.5, t_st + 0.05
        r.update(t_ros, t_st)
    assert 80 < r.rate < 100
    r.update(t_ros + 4.5, t_st + 0.002)   # an event-woken step 2 ms later, after a jump
    assert 80 < r.rate < 100, r.rate


def test_a_wind_stow_goes_to_the_wind_pose_a_silent_supervisor_to_the_stow_position():
    """Issue 35: safety's wind_stow -> wind_stow_position (face-up); any other stow, and
    the fail-safe stow of a silent supervisor, -> stow_position (sleeping)."""
    import dataclasses
    sup = _sup()
    sup.cfg = dataclasses.replace(sup.cfg, wind_stow_position=0.0)
    cal = Calibration()
    sup.safety.receive(1.0, 2, True, [], 2, ['wind gust ...'], wind_stow=True)
    act = sup.tick(150.0, 1.1, _board(steps=cal.steps(0.4), sensor=0.4), True)
    assert act.kind == 'move' and act.steps == cal.steps(0.0) and sup.state == 'stowing'
    sup.safety.receive(1.2, 2, True, [], 3, ['wind ...', 'outlet over-temperature ...'], wind_stow=False)
    act = sup.tick(150.1, 1.3, _board(steps=cal.steps(0.3), sensor=0.3), True)
    assert act.kind == 'move' and act.steps == cal.steps(math.pi / 2)
    sup.safety.receive(1.4, 2, True, [], 4, ['wind gust ...'], wind_stow=True)
    sup.safety.silent_stow_after = 0.5
    act = sup.tick(150.2, 3.5, _board(steps=cal.steps(0.5), moving=True, sensor=0.5), True)   # 2.1 s silent
    assert act.kind == 'move' and act.steps == cal.steps(math.pi / 2)


@pytest.mark.parametrize('invert', [False, True])
def test_steps_of_a_target_stay_inside_the_limits(invert):
    cal = Calibration(invert=invert)                             # 0.006 deg/step: 40 deg is 6666.67 steps
    lim = SoftLimits(math.radians(-40.0), math.radians(40.0))
    for theta in (math.radians(40.0), math.radians(41.0), math.radians(-40.0)):
        s = lim.steps(cal, theta)
        assert lim.contains(cal.angle(s), tol=0.0) and abs(cal.angle(s) - lim.clamp(theta)) < cal.step_angle
    margin = math.radians(0.05)
    s = lim.steps(cal, math.radians(40.0), margin)
    assert math.radians(40.0) - margin - cal.step_angle < cal.angle(s) <= math.radians(40.0) - margin
    assert lim.steps(cal, math.radians(12.0), margin) == cal.steps(math.radians(12.0))   # inside: the nearest
