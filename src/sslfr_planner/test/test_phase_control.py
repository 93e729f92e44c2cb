"""Unit tests of the planner's tick decisions (phase_control) and outgoing messages
(messages): override poses, replans and publish cadence on the real day cycle of the
Almeria configuration (no rclpy, no DDS)."""
from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest

from sslfr_common.contract import JOINTS, DayType, Phase
from sslfr_planner.day_cycle import DayCycle
from sslfr_planner.phase_control import PHASE, SUN, TRAJECTORY, PhaseControl, diagnostic_summary
from sslfr_planner.planner_params import PLANNER_PARAMS
from sslfr_planner.site_source import SiteFix

CFG = PLANNER_PARAMS.defaults()            # Almeria, 120 s horizon at 1 s, stow 0.0175 rad/s
SPEED = CFG['stow.speeds'][0]


def _utc(*a) -> float:
    return dt.datetime(*a, tzinfo=dt.timezone.utc).timestamp()


@pytest.fixture(scope='module')
def cycle() -> DayCycle:
    c = DayCycle(CFG, SiteFix(CFG['site.latitude_deg'], CFG['site.longitude_deg'], CFG['site.elevation'],
                              'parameters'))
    c.plan(_utc(2026, 6, 21, 10))
    return c


def _publish_all(ctl: PhaseControl, tick, now: float) -> None:
    for topic, due in ((PHASE, tick.publish_phase), (SUN, tick.publish_sun),
                       (TRAJECTORY, tick.publish_trajectory)):
        if due:
            ctl.published(topic, now)


def _started(cycle, now: float, mode: str = 'auto') -> PhaseControl:
    ctl = PhaseControl(mode)
    assert ctl.replan_reason(now, cycle) == 'start-up'
    ctl.replanned()
    tick = ctl.tick(now, cycle, CFG)
    _publish_all(ctl, tick, now)
    return ctl


# ------------------------------------------------------------------ replans
def test_replan_requests_and_new_day(cycle):
    ctl = PhaseControl('auto')
    now = _utc(2026, 6, 21, 10)
    assert ctl.replan_reason(now, cycle) == 'start-up'
    ctl.request_replan('gps fix 120 m from the planned site (parameters)')
    assert ctl.replan_reason(now, cycle).startswith('gps fix')
    ctl.replanned()
    assert ctl.replan_reason(now, cycle) is None
    # seed 000 Step 5: the next local solar day replans on its own
    tomorrow = cycle.day_start(cycle.current_schedule.day + 1) + 1.0
    assert ctl.replan_reason(tomorrow, cycle) == 'new day'
    with pytest.raises(ValueError):
        PhaseControl('fly')


# ------------------------------------------------------------------ cadence
def test_publish_cadence_on_ros_time(cycle):
    now = _utc(2026, 6, 21, 10)
    ctl = PhaseControl('auto')
    ctl.replanned()
    first = ctl.tick(now, cycle, CFG)
    assert first.phase_change == (None, Phase.TRACKING)
    assert first.publish_phase and first.publish_sun and first.publish_trajectory
    _publish_all(ctl, first, now)
    t = now + 0.2
    tick = ctl.tick(t, cycle, CFG)
    assert (tick.phase_change, tick.publish_phase, tick.publish_sun, tick.publish_trajectory) == \
        (None, False, False, False)
    t = now + CFG['phase_period']                                    # 1 s
    tick = ctl.tick(t, cycle, CFG)
    assert tick.publish_phase and tick.publish_sun and not tick.publish_trajectory
    _publish_all(ctl, tick, t)
    t = now + CFG['republish_period']                                # 5 s
    tick = ctl.tick(t, cycle, CFG)
    assert tick.publish_trajectory
    _publish_all(ctl, tick, t)
    # ROS time went backwards (a bag replayed again, a clock reset): everything now
    t = now + 2.0
    tick = ctl.tick(t, cycle, CFG)
    assert tick.publish_phase and tick.publish_sun and tick.publish_trajectory


def test_trajectory_retried_until_published_and_forced_by_a_replan(cycle):
    now = _utc(2026, 6, 21, 10)
    ctl = _started(cycle, now)
    ctl.replanned()                                   # e.g. parameters changed
    tick = ctl.tick(now + 0.2, cycle, CFG)
    assert tick.publish_trajectory and not tick.publish_phase
    # not published (a NaN in the horizon): due again at the next tick
    tick = ctl.tick(now + 0.4, cycle, CFG)
    assert tick.publish_trajectory
    ctl.published(TRAJECTORY, now + 0.4)
    assert not ctl.tick(now + 0.6, cycle, CFG).publish_trajectory


# ------------------------------------------------------------------ overrides
def test_safety_stow_ramps_from_the_commanded_pose_and_reasons_republish(cycle):
    now = _utc(2026, 6, 21, 10)
    ctl = _started(cycle, now)
    assert ctl.phase == Phase.TRACKING and ctl.reason == 'day cycle: TRACKING'
    assert ctl.on_safety(True, ['safety: outlet 152.3 degC > 150 degC'])
    assert not ctl.on_safety(True, ['safety: outlet 152.3 degC > 150 degC'])     # nothing new
    t = now + 0.7
    tick = ctl.tick(t, cycle, CFG)
    assert tick.phase_change == (Phase.TRACKING, Phase.STOW)
    assert tick.publish_phase and tick.publish_trajectory
    assert ctl.reason == 'safety: safety: outlet 152.3 degC > 150 degC'
    start_time, start_pose, target = ctl.stow_start
    assert start_time == t
    assert np.array_equal(start_pose, cycle.auto_pose(t))
    assert np.array_equal(target, cycle.sleep_pose(t))
    _publish_all(ctl, tick, t)
    h = ctl.horizon(t, cycle, CFG)
    assert h.t[0] == math.floor(t) + 1 and len(h) == 121
    # the mirrors ramp up to the sleeping position (+pi/2) at stow.speeds[0]
    assert h.positions[0, 0] == pytest.approx(start_pose[0] + SPEED * (h.t[0] - t), abs=1e-12)
    assert np.all(np.diff(h.positions[:, 0]) >= 0) and h.velocities[0, 0] == SPEED
    # new reasons while stowed: republished, the ramp keeps its anchor
    assert ctl.on_safety(True, ['safety: e-stop'])
    tick = ctl.tick(t + 0.2, cycle, CFG)
    assert tick.phase_change is None and tick.publish_phase and ctl.stow_start[0] == t
    # released: back to the day cycle, trajectory at once
    assert ctl.on_safety(False, [])
    tick = ctl.tick(t + 0.4, cycle, CFG)
    assert tick.phase_change == (Phase.STOW, Phase.TRACKING) and tick.publish_trajectory


def test_manual_hold_is_kept_into_maintenance_and_stow_starts_from_it(cycle):
    now = _utc(2026, 6, 21, 10)
    ctl = _started(cycle, now)
    assert ctl.request_mode('manual').success and ctl.mode == 'manual'
    t1 = now + 30.0
    assert ctl.tick(t1, cycle, CFG).phase_change == (Phase.TRACKING, Phase.MANUAL)
    held = cycle.auto_pose(t1)
    assert np.array_equal(ctl.hold_pose, held)
    h = ctl.horizon(t1 + 600.0, cycle, CFG)                 # ten minutes later: still there
    assert np.all(h.positions == held) and np.all(h.velocities == 0.0)
    assert ctl.request_mode('maintenance').success
    ctl.tick(t1 + 60.0, cycle, CFG)
    assert ctl.phase == Phase.MAINTENANCE and np.array_equal(ctl.hold_pose, held)
    assert ctl.request_mode('stow').success
    t2 = t1 + 120.0
    ctl.tick(t2, cycle, CFG)
    assert ctl.phase == Phase.STOW and np.array_equal(ctl.stow_start[1], held)
    assert np.allclose(ctl.commanded_pose(t2 + 10.0, cycle, CFG['stow.speeds'])[0], held[0] + 10.0 * SPEED)
    res = ctl.request_mode('manual')                       # stow -> manual is refused
    assert not res.success and ctl.mode == 'stow'


def test_diagnostic_summary_levels():
    assert diagnostic_summary(Phase.TRACKING, 'gps', 'planning failed: boom', 10.0, 60.0) == \
        ('error', 'planning failed: boom')
    assert diagnostic_summary(Phase.TRACKING, 'gps', 'planning failed: boom', 61.0, 60.0) == \
        ('ok', 'TRACKING; site from gps')
    assert diagnostic_summary(None, 'gps', '', 0.0, 60.0) == ('warn', 'waiting for ROS time')
    assert diagnostic_summary(Phase.NIGHT, 'parameters', '', 0.0, 60.0) == \
        ('warn', 'NIGHT; site from parameters (no GPS fix yet)')
    assert diagnostic_summary(Phase.STOW, 'persisted', '', 0.0, 60.0)[0] == 'ok'


# ------------------------------------------------------------------ messages
def test_messages(cycle):
    from sslfr_planner.messages import phase_msg, sun_msg, trajectory_msg

    now = _utc(2026, 6, 21, 10) + 0.25
    ctl = _started(cycle, now)
    h = ctl.horizon(now, cycle, CFG)
    msg = trajectory_msg(h)
    assert list(msg.joint_names) == list(JOINTS) and len(msg.points) == 121
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (int(h.t[0]), 0)
    assert [(p.time_from_start.sec, p.time_from_start.nanosec) for p in msg.points[:3]] == [(0, 0), (1, 0), (2, 0)]
    assert list(msg.points[5].positions) == h.positions[5].tolist()
    assert list(msg.points[5].velocities) == h.velocities[5].tolist()

    ph = phase_msg(ctl, cycle.current_schedule, cycle.site_fix, now)
    ev = cycle.current_schedule.events
    assert (ph.phase, ph.phase_name, ph.mode, ph.reason) == (Phase.TRACKING, 'TRACKING', 'auto',
                                                             'day cycle: TRACKING')
    assert (ph.header.stamp.sec, ph.header.stamp.nanosec) == (int(now), 250_000_000)
    assert ph.day_type == DayType.DAY_NORMAL and ph.site_source == 'parameters'
    assert ph.sunrise.sec + ph.sunrise.nanosec * 1e-9 == pytest.approx(ev.sunrise, abs=1e-9)
    assert ph.latitude == CFG['site.latitude_deg']
    assert phase_msg(ctl, None, cycle.site_fix, now).sunrise.sec == 0        # no plan yet: unset

    sun = cycle.sun(now)
    s = sun_msg(sun, now)
    assert (s.zenith, s.azimuth, s.transversal, s.longitudinal) == sun[:4]
    assert s.above_horizon and s.algorithm == 'spa'


def test_immediate_step_is_the_tick_or_the_shortest_publication_period():
    """/clock at real time (20 Hz: 0.05 s steps) is left to the 0.2 s tick timer; a
    faster simulation's steps, and steps as long as a publication period, tick at once."""
    from sslfr_planner.phase_control import immediate_step
    assert immediate_step({'phase_period': 1.0, 'sun_period': 1.0}, 0.2) == 0.2
    assert immediate_step({'phase_period': 0.1, 'sun_period': 1.0}, 0.2) == 0.1
    assert immediate_step({'phase_period': 5.0, 'sun_period': 0.15}, 0.2) == 0.15
    assert 0.05 < immediate_step({'phase_period': 1.0, 'sun_period': 1.0}, 0.2)     # 20 Hz /clock at 1x


# ------------------------------------------------------------------ wind stow (issue 35)
def test_a_wind_stow_ramps_to_the_wind_pose_and_another_stow_reason_retargets_to_sleep(cycle):
    now = _utc(2026, 6, 21, 10)
    ctl = _started(cycle, now)
    start = ctl.commanded_pose(now, cycle, CFG['stow.speeds'])
    assert ctl.on_safety(True, ['wind gust 21.0 m/s > 20.0 m/s (3 s mean): wind stow'], wind_stow=True)
    t = now + 0.2
    tick = ctl.tick(t, cycle, CFG)
    assert tick.phase_change[1] == Phase.STOW and tick.publish_trajectory
    _publish_all(ctl, tick, t)
    assert np.allclose(ctl.stow_start[2], CFG['stow.wind_pose'])
    far = ctl.commanded_pose(t + 3600.0, cycle, CFG['stow.speeds'])
    assert np.allclose(far, [0.0, 0.0, 0.0]) and not np.allclose(start, far)
    # over-temperature joins: the stow is no longer for wind only -> the sleeping pose
    assert ctl.on_safety(True, ['wind ...', 'outlet over-temperature ...'], wind_stow=False)
    t2 = t + 10.0
    mid = ctl.commanded_pose(t2, cycle, CFG['stow.speeds'])
    tick = ctl.tick(t2, cycle, CFG)
    assert tick.phase_change is None and tick.publish_trajectory
    assert np.allclose(ctl.stow_start[1], mid)                       # a new ramp from where it was
    assert np.allclose(ctl.stow_start[2], cycle.sleep_pose(t2))
    assert ctl.commanded_pose(t2 + 3600.0, cycle, CFG['stow.speeds'])[0] == pytest.approx(math.pi / 2)
    # an operator stow is never a wind stow
    ctl2 = _started(cycle, now, mode='stow')
    assert np.allclose(ctl2.stow_start[2], cycle.sleep_pose(now))
