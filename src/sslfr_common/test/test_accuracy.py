"""The accuracy alarm (sslfr_common.accuracy) on numbers: thresholds, window,
moves left out, hysteresis, time above each threshold, the loss quoted."""
from __future__ import annotations

import math

import pytest

from sslfr_common.accuracy import CLEAR, ERROR, MOVE_CAP, OK, WARN, AccuracyAlarm, AccuracyConfig

D = math.radians
#: a loss table (error [rad], smallest, largest loss [%]): seed 000's study rounded
TABLE = ((0.0, 0.0, 0.0), (D(0.06), 0.0, 0.2), (D(0.36), 2.47, 3.38), (D(1.0), 41.41, 55.32))


def feed(alarm, t0, t1, dt, error_of, setpoint_of=lambda t: 0.3 + 1e-5 * t, following=True):
    """Samples every ``dt`` s of ROS time; returns the level changes [(t, level, line)]."""
    out, t = [], t0
    while t <= t1 + 1e-9:
        sp = setpoint_of(t)
        ev = alarm.sample(t, following, sp, sp + error_of(t))
        if ev:
            out.append((t, *ev))
        t += dt
    return out


def test_ramp_raises_warn_then_error_with_the_loss_and_counts_the_time():
    a = AccuracyAlarm('mirrors', AccuracyConfig(window=10.0, loss_table=TABLE))
    # tracking cleanly for 100 s, then the error grows 0.001 deg/s (a slipping coupling)
    ev = feed(a, 0.0, 100.0, 0.2, lambda t: D(0.005))
    assert ev == [] and a.level == OK and a.tracking
    ev = feed(a, 100.2, 600.0, 0.2, lambda t: D(0.005 + 0.001 * (t - 100.0)))
    levels = [lvl for _, lvl, _ in ev]
    assert levels == [WARN, ERROR], ev
    (t_warn, _, warn_line), (t_err, _, err_line) = ev
    # RMS over a 10 s window of a ramp lags the ramp by ~5 s
    assert 100 + (0.06 - 0.005) / 0.001 < t_warn < 100 + (0.06 - 0.005) / 0.001 + 6
    assert 100 + (0.36 - 0.005) / 0.001 < t_err < 100 + (0.36 - 0.005) / 0.001 + 6
    assert '> 0.060 deg' in warn_line and 'estimated optical loss 0.0-0.2 %' in warn_line
    assert '> 0.360 deg' in err_line and 'estimated optical loss 2.5-3.4 %' in err_line
    assert a.time_above[WARN] == pytest.approx(600.0 - t_warn, abs=0.3)
    assert a.time_above[ERROR] == pytest.approx(600.0 - t_err, abs=0.3)
    v = a.values()
    assert v['level'] == 'ERROR' and float(v['time_above_error_s']) == pytest.approx(a.time_above[ERROR], abs=0.1)


def test_a_short_spike_is_filtered_and_levels_clear_with_hysteresis():
    a = AccuracyAlarm('mobile_structure', AccuracyConfig(window=60.0))
    # one sample of 0.2 deg among 0.01 deg ones: RMS over 300 samples stays low
    ev = feed(a, 0.0, 120.0, 0.2, lambda t: D(0.2) if abs(t - 60.0) < 0.1 else D(0.01))
    assert ev == [] and a.level == OK
    ev = feed(a, 120.2, 300.0, 0.2, lambda t: D(0.07))
    assert [lvl for _, lvl, _ in ev] == [WARN]
    assert 'not estimated for this axis' in ev[0][2]       # no loss table: the mirrors' driver has one
    # just below the threshold but above CLEAR x threshold: still WARN
    ev = feed(a, 300.2, 500.0, 0.2, lambda t: D(0.06 * (CLEAR + 0.1)))
    assert ev == [] and a.level == WARN
    ev = feed(a, 500.2, 700.0, 0.2, lambda t: D(0.01))
    assert [lvl for _, lvl, _ in ev] == [OK]


def test_moves_and_other_states_are_not_judged():
    a = AccuracyAlarm('mirrors', AccuracyConfig(window=5.0))
    feed(a, 0.0, 10.0, 0.2, lambda t: D(0.01))
    # a stow ramp (setpoint at 1 deg/s) with a large lag: a deliberate move
    ev = feed(a, 10.2, 40.0, 0.2, lambda t: D(-2.0), setpoint_of=lambda t: 0.3 + D(1.0) * (t - 10.0))
    assert ev == [] and not a.tracking
    # after the ramp stops, the axis is still off: not judged until settled or MOVE_CAP
    # after the move began (10.2 s)
    ev = feed(a, 40.2, 10.2 + MOVE_CAP - 1, 0.2, lambda t: D(0.5), setpoint_of=lambda t: 1.0)
    assert ev == [] and not a.tracking
    ev = feed(a, 10.2 + MOVE_CAP, 10.2 + MOVE_CAP + 20, 0.2, lambda t: D(0.5), setpoint_of=lambda t: 1.0)
    assert [lvl for _, lvl, _ in ev] == [ERROR], 'an axis that never arrives is judged after MOVE_CAP'
    # holding / stowing / stopped: not judged, the alarm clears
    ev = feed(a, 400.0, 410.0, 0.2, lambda t: D(0.5), following=False)
    assert [lvl for _, lvl, _ in ev] == [OK] and 'not tracking' in ev[0][2]
    # back to following within SETTLE: judged again from the first settled sample
    ev = feed(a, 410.2, 420.0, 0.2, lambda t: D(0.02))
    assert ev == [] and a.tracking and a.level == OK
    # NaN measured (position unknown): not judged
    assert a.sample(421.0, True, 0.3, math.nan) is None and not a.tracking


def test_time_never_counts_across_a_pause_or_a_clock_jump():
    a = AccuracyAlarm('mirrors', AccuracyConfig(warn=D(0.03), error=D(0.2), window=1.0))
    # the first following sample starts a move; within SETTLE, judged from the second one
    feed(a, 0.0, 10.0, 1.0, lambda t: D(0.04))
    assert a.level == WARN and a.time_above[WARN] == pytest.approx(9.0)
    above = a.time_above[WARN]
    a.sample(11.0, False, 0.3, 0.3)
    a.sample(500.0, True, 0.3, 0.3 + D(0.04))   # back after a pause: first sample is a move start
    assert a.time_above[WARN] == above
    assert a.sample(500.0, True, 0.3, 0.3) is None     # the same snapshot twice
    a.sample(100.0, True, 0.3, 0.3 + D(0.04))           # time went back (a new sim run)
    assert a.time_above[WARN] == above


def test_level_changes_are_logged_by_a_real_rclpy_logger():
    """Each severity from its own call site: rclpy raises 'Logger severity cannot be
    changed between calls' when one call site logs two severities (a timer callback
    raising would end the driver's process)."""
    from collections import namedtuple

    from rclpy.impl.rcutils_logger import RcutilsLogger
    Snapshot = namedtuple('Snapshot', 'stamp state commanded setpoint measured')     # the driver's fields
    log = RcutilsLogger('accuracy_test')
    a = AccuracyAlarm('mirrors', AccuracyConfig(window=0.5))     # the latest sample alone
    a.phase = 2                                                   # TRACKING
    sp = 0.3
    seen = []
    for k, err in enumerate([0.0, 0.0, 0.1, 0.1, 0.5, 0.5, 0.0, 0.0, 0.1, 0.1]):
        a.sample_snapshot(Snapshot(float(k + 1), 'following', sp, sp, sp + D(err)), 'active', log)
        seen.append(a.level)
    a.sample_snapshot(Snapshot(20.0, 'stopped', sp, sp, sp + D(0.5)), 'active', log)
    assert seen == [OK, OK, WARN, WARN, ERROR, ERROR, OK, OK, WARN, WARN] and a.level == OK


def test_only_sun_tracking_is_judged():
    """The driver following its trajectory during the planner's TRACKING phase (or
    waiting for the newest trajectory's first point); not the night's sleeping pose,
    a stow ramp's hold, a manual hold, or before any phase is known."""
    from collections import namedtuple

    from sslfr_common.accuracy import tracking
    assert tracking('following', 2) and tracking('waiting', 2)
    for state, phase in (('following', 0), ('following', 5), ('holding', 2), ('stowing', 2), ('following', None)):
        assert not tracking(state, phase), (state, phase)
    Snapshot = namedtuple('Snapshot', 'stamp state commanded setpoint measured')
    a = AccuracyAlarm('mirrors', AccuracyConfig(window=0.5))
    for k in range(5):                       # at night, off the setpoint: never judged
        a.sample_snapshot(Snapshot(float(k), 'following', 1.5, 1.5, 1.5 + D(0.5)), 'active', None)
    assert not a.tracking and a.level == OK


def test_the_loss_table_parameter_is_refused_unless_a_table():
    from sslfr_common.accuracy import PARAM_SPECS
    from sslfr_common.tracking_loss import to_flat
    spec = next(s for s in PARAM_SPECS if s.name == 'accuracy.loss_table')
    assert spec.check([0.0, 0.0, 0.0]) is None and spec.check(to_flat(TABLE)) is None
    assert 'rows of three' in spec.check([0.0, 0.0])
    assert 'increase' in spec.check([0.0, 0.0, 0.0, 0.0, 1.0, 1.0])
    assert 'smallest <= largest' in spec.check([0.0, 0.0, 0.0, 0.01, 2.0, 1.0])
    assert spec.check([0.0, 0.0, 0.0, 0.01, -1.0, 1.0])                     # below the range
    cfg = AccuracyConfig.from_params({'accuracy.warn_threshold': D(0.06), 'accuracy.error_threshold': D(0.36),
                                      'accuracy.window': 60.0, 'accuracy.loss_table': to_flat(TABLE)})
    assert cfg.loss_table == TABLE


def test_filtered_is_the_rms_of_the_window_over_a_long_day():
    """The running sum behind ``filtered`` equals the RMS recomputed over the window,
    after a day of samples with errors spanning five decades (no rounding carried)."""
    import random
    rnd = random.Random(7)
    a = AccuracyAlarm('mirrors', AccuracyConfig(window=30.0))
    kept, t = [], 0.0
    for k in range(40000):
        t += 0.2
        err = D(rnd.choice((1e-4, 1e-3, 1e-2, 0.05)) * rnd.random()) if k < 39000 else D(1e-6)
        a.sample(t, True, 0.3, 0.3 + err)
        if k == 0:
            continue                             # a start is a move: judged from the next sample
        assert a.tracking
        kept = [(ts, e) for ts, e in kept if ts >= t - 30.0] + [(t, err)]
        if k % 997 == 0 or k > 39990:
            assert a.filtered == pytest.approx(math.sqrt(sum(e * e for _, e in kept) / len(kept)), rel=1e-9)
