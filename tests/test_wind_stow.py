"""Wind stow, topic level (issue 35 item 1): the REAL ``absorber_board`` (counting the
simulated cup anemometer on pin 7 of the simulated absorber board), ``safety`` and
``planner`` on DDS; the test injects a gusty wind and an over-temperature into the
simulated board, as ``./sslfr sim --fault wind:...`` and ``overtemp`` do.

Compressed, honestly: the release hold is 15 s (default 1800 s) and the gust limit
12 m/s (default 20 m/s); the nodes run on the system clock at real time (ROS time =
wall time, so the hold and the windows, on ROS time, are measured here in wall seconds;
src/sslfr_safety/test/test_wind_rules.py checks the hold at simulation speed).
"""
from __future__ import annotations

import datetime as dt
import math
import time

import pytest

from sslfr_common.contract import SAFETY_STATE, TRACKER_TRAJECTORY, WIND
from sslfr_common.timeconv import to_sec
from sslfr_sim.runner import SimThread
from sslfr_sim.sensors import AbsorberSim

pytestmark = pytest.mark.timeout(300)

GUST, HOLD, COOL = 12.0, 15.0, 2.0
START = dt.datetime(2026, 6, 21, 10, 0, tzinfo=dt.timezone.utc).timestamp()


@pytest.fixture
def plant(tmp_path, launch, ros):
    from trajectory_msgs.msg import JointTrajectory

    from sslfr_interfaces.msg import SafetyState, Wind
    sim = SimThread.plain(AbsorberSim({'start_utc': START, 'speed': 1.0, 'seed': 11}),
                          link=str(tmp_path / 'abs0')).start()
    box = {'wind': [], 'safety': [], 'traj': []}
    for key, typ, topic in (('wind', Wind, WIND.name), ('safety', SafetyState, SAFETY_STATE.name),
                            ('traj', JointTrajectory, TRACKER_TRAJECTORY.name)):
        ros.node.create_subscription(typ, topic, lambda m, k=key: box[k].append((time.monotonic(), m)), 10)
    nodes = [
        launch('sslfr_drivers', 'absorber_board', params={'port': str(tmp_path / 'abs0'), 'anemometer_pin': 7}),
        launch('sslfr_safety', 'safety', params={
            'require_site_and_time': False, 'watchdog.nodes': ['absorber_board'], 'watchdog.timeouts': [3.0],
            'watchdog.actions': ['STOW'], 'watchdog.startup_grace': 10.0, 'wind.enabled': True,
            'wind.gust_limit': GUST, 'wind.mean_limit': 14.0, 'wind.hysteresis': 3.0, 'wind.hold': HOLD,
            'temperature.auto_reset': True, 'temperature.cool_hold': COOL}),
        launch('sslfr_planner', 'planner', params={'state_dir': str(tmp_path / 'state'),
                                                   'stow.speeds': [0.2, 0.2, 0.2]}),
    ]

    def output():
        return '\n'.join(n.output() for n in nodes)
    assert ros.spin_until(lambda: box['safety'] and box['safety'][-1][1].level == SafetyState.OK
                          and len(box['wind']) > 8, 40), output()
    yield sim, box, output
    sim.stop()


def _fault(sim, kind, active, **kw):
    with sim.locked():
        assert sim.board.control({'cmd': 'fault', 'kind': kind, 'active': active, **kw})['ok']


def _kinds(state):
    from sslfr_safety.rules import rule_for
    return {rule_for(r).kind for r in state.reasons}


def _stow_target(box, after):
    """The last point of the newest trajectory received after ``after`` [steady s]."""
    trajs = [m for t, m in box['traj'] if t > after]
    return list(trajs[-1].points[-1].positions) if trajs else None


def test_a_gust_stows_within_2_s_to_the_wind_pose_and_the_release_waits_the_hold(plant, ros):
    from sslfr_interfaces.msg import SafetyState
    sim, box, output = plant
    assert max(m.speed for _, m in box['wind']) < GUST          # the calm default breeze
    # published at wind_rate (1 Hz) of the 4 Hz samples, and at once on a new gust maximum
    def gap(a, b):
        return to_sec(b.header.stamp) - to_sec(a.header.stamp)

    def pairs():
        return [(a, b) for (_, a), (_, b) in zip(box['wind'], box['wind'][1:])]

    def periodic():
        return [gap(a, b) for a, b in pairs() if b.gust <= a.gust]
    # in the first seconds the window's largest 3 s mean may rise at every publication (a
    # CI run saw nine in a row): wait for three periodic ones
    assert ros.spin_until(lambda: len(periodic()) >= 3, 30), [(m.gust, to_sec(m.header.stamp)) for _, m in box['wind']]
    assert min(periodic()) >= 0.9, periodic()
    assert all(b.gust > a.gust for a, b in pairs() if gap(a, b) < 0.9)
    t_fault = time.monotonic()
    _fault(sim, 'wind', True, value=20.0)

    def first(key, pred, since):
        return next((t for t, m in box[key] if t >= since and pred(m)), None)
    assert ros.spin_until(lambda: first('safety', lambda m: m.level == SafetyState.STOW, t_fault), 20), output()
    t_gust = first('wind', lambda m: m.speed > GUST, t_fault)
    t_stow = first('safety', lambda m: m.level == SafetyState.STOW, t_fault)
    assert t_gust is not None and t_stow - t_gust <= 2.0, (t_gust, t_stow)
    st = next(m for t, m in box['safety'] if t == t_stow)
    assert _kinds(st) == {'wind'} and st.stow_required and st.wind_stow
    # the planner stows to the wind pose (face-up), not to the sleeping position
    assert ros.spin_until(lambda: _stow_target(box, t_fault) == pytest.approx([0.0, 0.0, 0.0], abs=1e-6), 8)
    ros.spin_for(3.0)
    _fault(sim, 'wind', False)
    t_end = time.monotonic()
    assert ros.spin_until(lambda: first('safety', lambda m: m.level == SafetyState.OK, t_end), HOLD + 15), output()
    t_ok = first('safety', lambda m: m.level == SafetyState.OK, t_end)
    # the hold runs from the last wind message with a gust over its limit or a mean not
    # below the release threshold (14 - 3 m/s: the short mean of a young window can be)
    t_last = max(t for t, m in box['wind'] if m.speed > GUST or m.mean >= 14.0 - 3.0)
    print(f'last windy sample -> released: {t_ok - t_last:.2f} s (hold {HOLD} s)')
    assert HOLD - 0.5 <= t_ok - t_last <= HOLD + 2.5
    waiting = [m.wind_release_in for t, m in box['safety'] if t_last + 1.0 < t < t_ok - 1.0]
    assert waiting and all(0.0 < w <= HOLD for w in waiting)
    assert all(b <= a + 1e-6 for a, b in zip(waiting, waiting[1:]))          # counting down
    assert 'wind stow' in output() and 'release after' in output() and 'wind stow released' in output()


def test_a_wind_stow_and_an_over_temperature_stow_release_only_when_both_clear(plant, ros):
    from sslfr_interfaces.msg import SafetyState
    sim, box, output = plant

    def latest():
        return box['safety'][-1][1]

    # 1. both; the wind ends first: still stowed (hot), then released once cooled
    t_both = time.monotonic()
    _fault(sim, 'wind', True, value=20.0)
    _fault(sim, 'overtemp', True, value=200.0)
    assert ros.spin_until(lambda: _kinds(latest()) == {'wind', 'overtemp'}, 15), output()
    assert not latest().wind_stow                    # over-temperature: defocus (sleeping pose) wins
    assert ros.spin_until(lambda: (_stow_target(box, t_both) or [0])[0] == pytest.approx(math.pi / 2), 8), output()
    _fault(sim, 'wind', False)
    t_calm = time.monotonic()
    assert ros.spin_until(lambda: _kinds(latest()) == {'overtemp'}, HOLD + 15), output()
    assert time.monotonic() - t_calm >= HOLD - 1.0
    ros.spin_for(2.0)
    assert latest().level == SafetyState.STOW        # the wind cleared, the absorber did not
    _fault(sim, 'overtemp', False)
    assert ros.spin_until(lambda: latest().level == SafetyState.OK, COOL + 10), output()

    # 2. both; the absorber cools first: the wind stow goes on (now face-up), then releases
    _fault(sim, 'wind', True, value=20.0)
    _fault(sim, 'overtemp', True, value=200.0)
    assert ros.spin_until(lambda: _kinds(latest()) == {'wind', 'overtemp'}, 15), output()
    ros.spin_for(1.0)
    _fault(sim, 'overtemp', False)
    t_cool = time.monotonic()
    assert ros.spin_until(lambda: _kinds(latest()) == {'wind'}, COOL + 10), output()
    assert latest().level == SafetyState.STOW and latest().wind_stow
    assert ros.spin_until(lambda: _stow_target(box, t_cool) == pytest.approx([0.0, 0.0, 0.0], abs=1e-6), 8), output()
    _fault(sim, 'wind', False)
    t_calm = time.monotonic()
    assert ros.spin_until(lambda: latest().level == SafetyState.OK, HOLD + 15), output()
    assert time.monotonic() - t_calm >= HOLD - 1.0
