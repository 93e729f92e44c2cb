"""The cup anemometer core (pulses -> m/s, WMO 3 s gust and 10 min mean), on numbers
(issue 35 item 1)."""
from __future__ import annotations

import pytest

from sslfr_drivers.sensors import anemometer as an


# ------------------------------------------------------------------ anemometer core
def test_calibration_is_linear_with_the_starting_offset_and_inverts():
    assert an.speed(0.0) == 0.0
    assert an.speed(10.0) == pytest.approx(0.765 * 10 + 0.35)
    for v in (0.5, 3.0, 14.0, 40.0):
        assert an.speed(an.frequency(v)) == pytest.approx(v)
    assert an.frequency(0.2) == 0.0                   # below the starting threshold
    with pytest.raises(ValueError):
        an.check_calibration(0.0, 0.35)
    with pytest.raises(ValueError):
        an.check_calibration(0.765, -0.1)


def test_pulse_counter_intervals_wraps_resets_and_gaps():
    c = an.PulseCounter()
    assert c.add(1000, 10) is None
    assert c.add(1250, 15) == (0.25, 5)
    assert c.add(2**32 - 100, 2**32 - 3) is None                # count went back: reset
    assert c.add(150, 5) == (pytest.approx(0.25), 8)            # both fields wrap
    assert c.add(5000, 3) is None                               # count went back: reset
    assert c.add(8000, 4) is None                               # 3 s gap
    assert c.restarts == 3


def test_steady_rate_gives_speed_gust_and_mean_equal():
    w = an.WindStats()
    f = an.frequency(10.0)
    for _ in range(40):                                         # 10 s at 4 Hz
        r = w.add(0.25, round(f * 0.25 * 1000) / 1000)
    assert r.speed == pytest.approx(10.0, rel=1e-3)
    assert r.gust == pytest.approx(10.0, rel=1e-3) and r.mean == pytest.approx(10.0, rel=1e-3)
    assert r.window == pytest.approx(10.0) and r.pulse_rate == pytest.approx(f, rel=1e-3)


def test_gust_is_the_highest_3s_mean_and_mean_covers_10_minutes():
    """A 3 s burst at 25 m/s in 20 min of 5 m/s: gust 25 while it is in the 10 min
    window, the mean its time-weighted share; both forget it after 10 min."""
    w = an.WindStats()
    calm, burst = an.frequency(5.0), an.frequency(25.0)
    t = 0.0
    for _ in range(4 * 300):
        r = w.add(0.25, calm * 0.25)
        t += 0.25
    assert r.gust == pytest.approx(5.0)
    for _ in range(12):                                          # 3 s burst
        r = w.add(0.25, burst * 0.25)
    assert r.speed == pytest.approx(25.0) and r.gust == pytest.approx(25.0)
    assert r.mean == pytest.approx((5.0 * 300 + 25.0 * 3) / 303.0)
    for _ in range(4 * 300):
        r = w.add(0.25, calm * 0.25)
    assert r.window == pytest.approx(600.0)
    assert r.mean == pytest.approx((5.0 * 597 + 25.0 * 3) / 600.0, rel=1e-6)
    assert r.gust == pytest.approx(25.0)                          # 5 min after: still in the window
    for _ in range(4 * 303):                # + 3 s: the 3 s means that hold part of the burst
        r = w.add(0.25, calm * 0.25)
    assert r.gust == pytest.approx(5.0) and r.mean == pytest.approx(5.0)


def test_windows_run_on_ros_time_at_simulation_speed():
    """At --speed 400 the board samples every 0.25 s of its clock = 100 s of ROS time:
    the 3 s window holds the newest sample alone, the 10 min mean the last six, and
    ``window`` says 600 s of ROS time once full (a fault acts as in real time)."""
    w = an.WindStats()
    calm, storm = an.frequency(5.0), an.frequency(25.0)
    t = 1000.0
    for _ in range(10):                                         # 1000 s of calm
        t += 100.0
        r = w.add(0.25, calm * 0.25, t)
    assert r.window == pytest.approx(600.0) and r.mean == pytest.approx(5.0)
    t += 100.0
    r = w.add(0.25, storm * 0.25, t)                            # one 100 s sample of storm
    assert r.speed == pytest.approx(25.0) and r.gust == pytest.approx(25.0)
    assert r.mean == pytest.approx((5.0 * 5 + 25.0) / 6)
    for _ in range(6):                                          # 600 s later it is forgotten
        t += 100.0
        r = w.add(0.25, calm * 0.25, t)
    assert r.speed == pytest.approx(5.0) and r.gust == pytest.approx(5.0) and r.mean == pytest.approx(5.0)
    r = w.add(0.25, storm * 0.25, t - 5000.0)                   # ROS time went back: windows restart
    assert r.mean == pytest.approx(25.0) and r.window == pytest.approx(0.25)


def test_publish_gate_one_a_second_and_every_new_gust_maximum():
    """4 Hz readings: published once a second (the sample clock's jitter allowed) and
    at once whenever the gust is a new maximum; a restart forgets the last one."""
    g = an.PublishGate(1.0)
    assert g.due(0.0, 5.0)                          # the first
    assert not g.due(0.25, 5.0) and not g.due(0.5, 4.0) and not g.due(0.75, 5.0)
    assert g.due(0.97, 5.0)                         # 0.97 s: due (jitter)
    assert g.due(1.22, 7.5)                         # a new gust maximum: at once
    assert not g.due(1.47, 7.5) and not g.due(2.1, 6.0)
    assert g.due(2.22, 6.0)
    g.restart()
    assert g.due(2.47, 1.0)
    g.rate = 4.0
    assert g.due(2.72, 1.0)
