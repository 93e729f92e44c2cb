"""Topic-level acceptance of the planner node (issue 4): the real ``planner``
executable runs as a process; this test process drives /clock (use_sim_time) and
subscribes to its topics. References: the ephemeris core (sslfr_planner.tracking_table),
evaluated in this process for the same instants."""
from __future__ import annotations

import datetime as dt
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from sslfr_common.contract import (CLOCK, GPS_FIX, PLANNER_REPLAN, PLANNER_SET_MODE, SAFETY_STATE, TRACKER_PHASE,
                                   TRACKER_TRAJECTORY)

from conftest import ROOT

CONFIG = ROOT / 'src' / 'sslfr_bringup' / 'config'
PHASES = ['NIGHT', 'PRE_DAWN', 'TRACKING', 'STOWING', 'MANUAL', 'STOW', 'MAINTENANCE']


def _utc(*args) -> float:
    return dt.datetime(*args, tzinfo=dt.timezone.utc).timestamp()


def _qos_tl1():
    from sslfr_common.node import qos
    return qos(TRACKER_PHASE)


def _stamp(t) -> float:
    return t.sec + t.nanosec * 1e-9


def _points(msg) -> np.ndarray:
    """Absolute point times [s] of a JointTrajectory."""
    t0 = _stamp(msg.header.stamp)
    return np.array([t0 + p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points])


def _planner_cfg(config: Path | None, overrides: dict) -> dict:
    """The parameters the node will use (defaults <- file <- overrides)."""
    from sslfr_planner.planner_params import PLANNER_PARAMS
    cfg = PLANNER_PARAMS.defaults()
    if config is not None:
        data = yaml.safe_load(config.read_text())
        for section in ('/**', 'planner'):
            cfg.update((data.get(section) or {}).get('ros__parameters') or {})
    cfg.update(overrides)
    return PLANNER_PARAMS.coerce(cfg)


class SimClock:
    """Publishes /clock from the test and steps it in lockstep with the node."""

    def __init__(self, ros):
        from rosgraph_msgs.msg import Clock
        self.ros, self.Clock = ros, Clock
        self.pub = ros.node.create_publisher(Clock, CLOCK.name, 10)
        self.now = 0.0
        self.started = False

    def set(self, t: float) -> None:
        from builtin_interfaces.msg import Time
        self.now = t
        ns = int(round(t * 1e9))
        self.pub.publish(self.Clock(clock=Time(sec=ns // 10**9, nanosec=ns % 10**9)))

    def step_until(self, t: float, box: list, timeout: float = 5.0) -> None:
        """Set the clock to ``t`` (re-sent until the node answers) and wait for a
        message in ``box`` stamped at or after ``t`` (the first call also waits for
        the node to start and be discovered)."""
        if not self.started:
            timeout, self.started = max(timeout, 25.0), True
        n = len(box)

        def answered():
            return len(box) > n and _stamp(box[-1].header.stamp) >= t - 1e-6
        deadline = 0
        while not answered():
            self.set(t)
            self.ros.spin_until(answered, 0.25)
            deadline += 1
            assert deadline * 0.25 < timeout, f'node did not answer clock {t}'


def _start(launch, tmp_path, config: Path | None, overrides: dict, sim=True):
    """Start the planner with ``config`` then ``overrides`` (a second params file, so
    it wins over the first: rcl gives params files precedence over ``-p``)."""
    params = {'state_dir': str(tmp_path / 'state'), **overrides}
    if sim:
        params['use_sim_time'] = True
    extra = tmp_path / f'overrides-{len(list(tmp_path.glob("overrides-*.yaml")))}.yaml'
    extra.write_text(yaml.safe_dump({'planner': {'ros__parameters': params}}))
    ros_args = ['--params-file', str(config)] if config is not None else []
    ros_args += ['--params-file', str(extra)]
    return launch('sslfr_planner', 'planner', ros_args=ros_args)


# ------------------------------------------------------------------ phase sequences
def _schedule(t0: float, t1: float, transitions: list[float], fine: float = 60.0,
              coarse: float = 1800.0, margin: float = 300.0) -> list[float]:
    """Clock instants from t0 to t1: fine steps within ``margin`` of a transition."""
    out, t = [], t0
    while t < t1:
        out.append(t)
        near = any(abs(t - x) < margin for x in transitions)
        t += fine if near or any(0 < x - t < coarse for x in transitions) else coarse
    out.append(t1)
    return out


CASES = {
    # name: config file, date (UTC), overrides, expected sequence, expected day_type
    'almeria_summer': ('almeria_sslfr.yaml', (2026, 6, 21), {}, ['NIGHT', 'PRE_DAWN', 'TRACKING',
                                                                  'STOWING', 'NIGHT'], 0),
    'bucaramanga': ('bucaramanga_single_axis.yaml', (2026, 3, 20), {},
                    ['NIGHT', 'PRE_DAWN', 'TRACKING', 'STOWING', 'NIGHT'], 0),
    'florianopolis_winter': ('florianopolis_lepten.yaml', (2026, 6, 21), {},
                             ['NIGHT', 'PRE_DAWN', 'TRACKING', 'STOWING', 'NIGHT'], 0),
    'polar_winter': (None, (2026, 12, 21), {'site.latitude_deg': 78.22, 'site.longitude_deg': 15.65,
                                            'site.elevation': 10.0}, ['NIGHT'], 2),
    'polar_summer': (None, (2026, 6, 21), {'site.latitude_deg': 78.22, 'site.longitude_deg': 15.65,
                                           'site.elevation': 10.0}, ['TRACKING'], 1),
}


@pytest.mark.timeout(60)
@pytest.mark.parametrize('case', list(CASES))
def test_phase_sequence_over_a_simulated_day(case, launch, ros, tmp_path):
    from sslfr_interfaces.msg import TrackerPhase
    from sslfr_planner.day_cycle import DayCycle
    from sslfr_planner.site_source import SiteFix

    name, date, overrides, expected, day_type = CASES[case]
    config = CONFIG / name if name else None
    overrides = {'time_jump_threshold': 7200.0, **overrides}
    cfg = _planner_cfg(config, overrides)
    site = SiteFix(cfg['site.latitude_deg'], cfg['site.longitude_deg'], cfg['site.elevation'],
                   'parameters')
    ref = DayCycle(cfg, site)
    # the local solar day containing noon of `date` at the site
    day = ref.day_index(_utc(*date, 12) - cfg['site.longitude_deg'] * 240)
    t0, t1 = ref.day_start(day) + 30.0, ref.day_start(day) + 86400.0 - 30.0
    plan = ref.schedule(day)
    ph = plan.table.phase
    changes = np.nonzero(np.diff(ph))[0] + 1
    transitions = [float(plan.table.t[i]) for i in changes]
    expected_changes = [(float(plan.table.t[i]), PHASES[ph[i]]) for i in changes]

    proc = _start(launch, tmp_path, config, overrides)
    box = ros.collect(TrackerPhase, TRACKER_PHASE.name, _qos_tl1())
    clock = SimClock(ros)
    for t in _schedule(t0, t1, transitions):
        clock.step_until(t, box)
    seq = []
    for m in box:
        if not seq or seq[-1][1] != m.phase_name:
            seq.append((_stamp(m.header.stamp), m.phase_name))
    assert [s[1] for s in seq] == expected, (seq, [m.reason for m in box[:3]], proc.output()[-2000:])
    # each change seen within one fine clock step (60 s) after the core's table says so
    for (ts, name_), (tx, name_x) in zip(seq[1:], expected_changes):
        assert name_ == name_x and 0 <= ts - tx <= 60.0 + 1e-6, (ts, tx, name_)
    last = box[-1]
    assert last.day_type == day_type
    assert last.site_source == 'parameters' and last.mode == 'auto'
    assert last.latitude == pytest.approx(cfg['site.latitude_deg'], abs=1e-9)
    if day_type == 0:
        assert _stamp(last.sunrise) == pytest.approx(plan.events.sunrise, abs=1e-6)
        assert _stamp(last.sunset) == pytest.approx(plan.events.sunset, abs=1e-6)
    else:
        assert _stamp(last.sunrise) == 0.0 and _stamp(last.sunset) == 0.0
    assert 'Traceback' not in proc.output()


# ------------------------------------------------------- trajectory vs the core table
@pytest.mark.timeout(60)
def test_trajectory_equals_core_and_is_never_in_the_past(launch, ros, tmp_path):
    from sslfr_planner.tracking_table import evaluate
    from sslfr_planner.day_cycle import make_collector, make_site
    from sslfr_planner.site_source import SiteFix
    from trajectory_msgs.msg import JointTrajectory

    config = CONFIG / 'almeria_sslfr.yaml'
    overrides = {'republish_period': 0.5}
    cfg = _planner_cfg(config, overrides)
    site = make_site(cfg, SiteFix(cfg['site.latitude_deg'], cfg['site.longitude_deg'],
                                  cfg['site.elevation'], 'parameters'))
    coll = make_collector(cfg)
    proc = _start(launch, tmp_path, config, overrides)
    box = ros.collect(JointTrajectory, TRACKER_TRAJECTORY.name, _qos_tl1())
    clock = SimClock(ros)
    # around sunrise (PRE_DAWN -> TRACKING inside the horizon), mid-day with fractional
    # clock values, a 1 h backward jump, and across local midnight
    sunrise = evaluate(np.array([_utc(2026, 6, 21, 5)]), site, coll).events.sunrise
    instants = [sunrise - 700.3 + 37.7 * k for k in range(25)]
    instants += [_utc(2026, 6, 21, 12, 0, 0) + 0.999, _utc(2026, 6, 21, 11, 0, 0) + 0.25]
    instants += [_utc(2026, 6, 21, 23, 58, 30) + k * 13.1 for k in range(10)]
    worst = 0.0
    checked = 0
    for t in instants:
        clock.step_until(t, box)
        msg = box[-1]
        assert msg.joint_names == ['mirrors', 'mobile_structure', 'secondary_reflector']
        times = _points(msg)
        assert len(times) == 121 and times[0] > t and times[0] - t <= 1.0 + 1e-6, (times[0], t)
        assert np.allclose(np.diff(times), 1.0, atol=1e-6)
        pos = np.array([p.positions for p in msg.points])
        vel = np.array([p.velocities for p in msg.points])
        assert pos.shape == (121, 3) and vel.shape == (121, 3) and np.all(np.isfinite(vel))
        ref = evaluate(times, site, coll)
        refpos = np.stack([ref.mirrors, ref.mobile_structure, ref.secondary_reflector], axis=1)
        worst = max(worst, float(np.max(np.abs(pos - refpos))))
        checked += 1
    assert checked == len(instants)
    assert worst <= 1e-9, worst
    # every trajectory ever received starts after the clock the node was answering
    assert all(_points(m)[0] > _stamp(m.header.stamp) - 1.0 for m in box)
    print(f'trajectory vs core: {checked} horizons, max |diff| = {worst:.3g} rad')
    assert 'Traceback' not in proc.output()


@pytest.mark.timeout(60)
def test_trajectory_follows_the_described_mirror_law(launch, ros, tmp_path):
    """Seed 004's site config names its collector description: the planner commands the
    common drive a theta_T (Table 1's pace 0.4962), not theta_T / 2."""
    from sslfr_planner import description
    from sslfr_planner.day_cycle import make_collector, make_site
    from sslfr_planner.site_source import SiteFix
    from sslfr_planner.tracking_table import evaluate
    from trajectory_msgs.msg import JointTrajectory

    config = CONFIG / 'florianopolis_lepten.yaml'
    overrides = {'republish_period': 0.5}
    cfg = _planner_cfg(config, overrides)
    site = make_site(cfg, SiteFix(cfg['site.latitude_deg'], cfg['site.longitude_deg'],
                                  cfg['site.elevation'], 'parameters'))
    coll = make_collector(cfg, description.load(CONFIG / cfg['collector.description']))
    proc = _start(launch, tmp_path, config, overrides)
    box = ros.collect(JointTrajectory, 'tracker/trajectory', _qos_tl1())
    clock = SimClock(ros)
    t = _utc(2026, 6, 21, 18, 0, 0) + 0.5              # 15:00 local: theta_T ~ +50 deg
    clock.step_until(t, box)
    times = _points(box[-1])
    pos = np.array([p.positions for p in box[-1].points])
    ref = evaluate(times, site, coll)
    assert np.all(ref.phase == 2)
    assert np.max(np.abs(pos[:, 0] - ref.mirrors)) <= 1e-9
    assert np.allclose(pos[:, 0], 0.4962 * ref.transversal, atol=1e-9)
    assert np.min(np.abs(pos[:, 0] - ref.transversal / 2)) > np.radians(0.1)
    assert 'laws lepten_linear/horizontal' in proc.output() and 'Traceback' not in proc.output()


# ------------------------------------------------------------------- clock jumps
@pytest.mark.timeout(60)
def test_replans_within_one_second_of_a_3h_clock_jump(launch, ros, tmp_path):
    from sslfr_interfaces.msg import TrackerPhase
    from trajectory_msgs.msg import JointTrajectory

    config = CONFIG / 'almeria_sslfr.yaml'
    proc = _start(launch, tmp_path, config, {'republish_period': 30.0, 'phase_period': 0.1})
    traj = ros.collect(JointTrajectory, TRACKER_TRAJECTORY.name, _qos_tl1())
    phases = ros.collect(TrackerPhase, TRACKER_PHASE.name, _qos_tl1())
    clock = SimClock(ros)
    t0 = _utc(2026, 6, 21, 22, 30, 0)      # 22:40 local solar: NIGHT of the 21st
    for k in range(3):
        clock.step_until(t0 + k, phases)
    before = _stamp(phases[-1].sunrise)
    n_traj = len(traj)
    jump = t0 + 3 * 3600.0                  # GPS corrects the clock: 3 h later, next day
    got_at = None
    for k in range(11):                     # the clock then runs on in 0.1 s steps
        clock.step_until(jump + 0.1 * k, phases)
        fresh = [m for m in traj[n_traj:] if _points(m)[0] > jump]
        if fresh:
            got_at = clock.now
            break
    assert got_at is not None and got_at - jump <= 1.0, proc.output()[-1500:]
    assert all(_points(m)[0] > jump for m in traj[n_traj:])
    after = _stamp(phases[-1].sunrise)
    assert after - before == pytest.approx(86400.0, abs=120.0)     # the next day's plan
    assert proc.wait_for_output('ROS time jumped by +10797', 5) or \
        proc.wait_for_output('ROS time jumped by +10798', 1), proc.output()[-1500:]


# --------------------------------------------------------------- site persistence
@pytest.mark.timeout(60)
def test_persisted_site_is_used_after_a_restart_without_gps(launch, ros, tmp_path):
    from sensor_msgs.msg import NavSatFix, NavSatStatus
    from sslfr_interfaces.msg import TrackerPhase

    proc = _start(launch, tmp_path, CONFIG / 'almeria_sslfr.yaml', {}, sim=False)
    phases = ros.collect(TrackerPhase, TRACKER_PHASE.name, _qos_tl1())
    pub = ros.node.create_publisher(NavSatFix, GPS_FIX.name, 10)
    bad = NavSatFix(latitude=50.0, longitude=10.0, altitude=1.0)
    bad.status.status = NavSatStatus.STATUS_NO_FIX
    good = NavSatFix(latitude=7.1254, longitude=-73.1198, altitude=959.0)
    good.status.status = NavSatStatus.STATUS_FIX
    good.position_covariance = [4.0, 0, 0, 0, 4.0, 0, 0, 0, 9.0]
    good.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN

    def gps_used():
        pub.publish(bad)
        pub.publish(good)
        return bool(phases) and phases[-1].site_source == 'gps'
    assert ros.spin_until(gps_used, 20), proc.output()[-1500:]
    assert phases[-1].latitude == pytest.approx(7.1254) and phases[-1].altitude == 959.0
    assert not any(m.latitude == 50.0 for m in phases)
    state = json.loads((tmp_path / 'state' / 'planner_site.json').read_text())
    assert state['latitude_deg'] == 7.1254 and state['longitude_deg'] == -73.1198
    assert proc.stop() == 0, proc.output()
    ros.node.destroy_publisher(pub)

    phases.clear()
    proc2 = _start(launch, tmp_path, CONFIG / 'almeria_sslfr.yaml', {}, sim=False)
    assert ros.spin_until(lambda: bool(phases), 20), proc2.output()
    m = phases[-1]
    assert m.site_source == 'persisted', proc2.output()
    assert (m.latitude, m.longitude, m.altitude) == (7.1254, -73.1198, 959.0)


# ------------------------------------------------- modes, safety and parameters
@pytest.mark.timeout(60)
def test_modes_safety_stow_and_parameter_refusal(launch, ros, tmp_path):
    from rcl_interfaces.msg import Parameter as ParamMsg
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rcl_interfaces.srv import GetParameters, SetParameters
    from sslfr_interfaces.msg import SafetyState, TrackerPhase
    from sslfr_interfaces.srv import SetMode
    from std_srvs.srv import Trigger
    from trajectory_msgs.msg import JointTrajectory

    proc = _start(launch, tmp_path, CONFIG / 'almeria_sslfr.yaml', {'republish_period': 1.0})
    phases = ros.collect(TrackerPhase, TRACKER_PHASE.name, _qos_tl1())
    traj = ros.collect(JointTrajectory, TRACKER_TRAJECTORY.name, _qos_tl1())
    clock = SimClock(ros)
    t = _utc(2026, 6, 21, 10, 0, 0)              # TRACKING in Almeria
    clock.step_until(t, phases)
    assert phases[-1].phase_name == 'TRACKING'

    def call_mode(mode):
        return ros.call(SetMode, PLANNER_SET_MODE.name, SetMode.Request(mode=mode))

    res = call_mode('fly')
    assert not res.success and 'fly' in res.message and res.mode == 'auto'
    res = call_mode('manual')
    assert res.success and res.mode == 'manual'
    t += 2
    clock.step_until(t, traj)
    assert phases[-1].phase_name == 'MANUAL'
    pos = np.array([p.positions for p in traj[-1].points])
    assert np.all(pos == pos[0]) and all(v == 0.0 for p in traj[-1].points for v in p.velocities)

    res = call_mode('stow')
    assert res.success
    t += 2
    clock.step_until(t, traj)
    assert phases[-1].phase_name == 'STOW' and phases[-1].reason.startswith('operator')
    mir = np.array([p.positions[0] for p in traj[-1].points])
    vmir = np.array([p.velocities[0] for p in traj[-1].points])
    # ramp from the held pose to the sleeping position at stow.speeds[0] = 0.0175 rad/s
    assert np.all(np.diff(mir) >= 0) and mir[-1] == pytest.approx(math.pi / 2)
    assert np.diff(mir)[0] == pytest.approx(0.0175) and vmir[0] == pytest.approx(0.0175)
    assert mir[0] - pos[0, 0] == pytest.approx(0.0175 * (_points(traj[-1])[0] - (t - 2)), abs=1e-6)
    res = call_mode('manual')
    assert not res.success and 'refused' in res.message and res.mode == 'stow'
    assert call_mode('auto').success

    # the safety supervisor requires a stow: STOW whatever the mode
    safety = ros.node.create_publisher(SafetyState, SAFETY_STATE.name, 10)
    msg = SafetyState(level=SafetyState.STOW, stow_required=True,
                      reasons=['safety: outlet 152.3 degC > 150 degC'])

    def stowed():
        safety.publish(msg)
        return bool(phases) and phases[-1].phase_name == 'STOW'
    assert ros.spin_until(stowed, 10)
    assert 'outlet 152.3' in phases[-1].reason
    t += 200
    clock.step_until(t, traj)
    mir = np.array([p.positions[0] for p in traj[-1].points])
    assert mir[-1] == pytest.approx(math.pi / 2) or np.all(np.diff(mir) >= 0)
    msg.stow_required, msg.level = False, SafetyState.OK

    def released():
        safety.publish(msg)
        return phases[-1].phase_name == 'TRACKING'
    assert ros.spin_until(released, 10)

    # parameters: an invalid value is refused, the last good one stays
    def set_param(name, ptype, **value):
        req = SetParameters.Request(parameters=[ParamMsg(
            name=name, value=ParameterValue(type=ptype, **value))])
        return ros.call(SetParameters, 'planner/set_parameters', req).results[0]
    r = set_param('horizon', ParameterType.PARAMETER_DOUBLE, double_value=-5.0)
    assert not r.successful and 'horizon' in r.reason
    r = set_param('collector.law', ParameterType.PARAMETER_STRING, string_value='wobble')
    assert not r.successful and 'collector.law' in r.reason
    r = set_param('site.latitude_deg', ParameterType.PARAMETER_DOUBLE, double_value=float('nan'))
    assert not r.successful
    r = set_param('state_dir', ParameterType.PARAMETER_STRING, string_value='/proc/sslfr_state')
    assert not r.successful and 'state_dir' in r.reason and '/proc' in r.reason, r.reason
    got = ros.call(GetParameters, 'planner/get_parameters',
                   GetParameters.Request(names=['horizon', 'collector.law']))
    assert got.values[0].double_value == 120.0 and got.values[1].string_value == 'continuous'
    r = set_param('horizon', ParameterType.PARAMETER_INTEGER, integer_value=60)
    assert r.successful, r.reason
    t += 5
    clock.step_until(t, traj)
    assert len(traj[-1].points) == 61
    rep = ros.call(Trigger, PLANNER_REPLAN.name, Trigger.Request())
    assert rep.success and 'sunrise' in rep.message, rep.message
    assert 'Traceback' not in proc.output()


@pytest.mark.timeout(30)
def test_invalid_start_parameters_refuse_to_start(launch, tmp_path):
    proc = _start(launch, tmp_path, None, {'horizon': -5.0, 'collector.law': 'wobble'}, sim=False)
    assert proc.wait_for_output('invalid parameters', 15), proc.output()
    proc.proc.wait(10)
    assert proc.proc.returncode == 2
    out = proc.output()
    assert 'horizon' in out and 'Traceback' not in out
