"""Wind: the anemometer core (pulses -> m/s, WMO 3 s gust and 10 min mean) and the
safety supervisor's wind rules, on numbers with an injected clock (issue 35 item 1)."""
from __future__ import annotations

import math
import random

import pytest

from sslfr_common.contract import Level
from sslfr_drivers.safety.core import FakeClock, SafetyConfig, SafetyCore, with_changes
from sslfr_drivers.safety.params import TABLE, config_from
from sslfr_drivers.safety.rules import hint_for, rule_for
from sslfr_drivers.sensors import anemometer as an
from sslfr_drivers.sim.world import GustyWind

from test_safety_core import NIGHT, feed


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


def test_simulated_gusty_wind_has_the_mean_and_a_usual_gust_factor():
    wind, stats = GustyWind(12.0, random.Random(3)), an.WindStats()
    count = 0.0
    last = 0
    for _ in range(4 * 600):
        count += an.frequency(wind.step(0.25)) * 0.25
        r = stats.add(0.25, int(count) - last)
        last = int(count)
    assert r.mean == pytest.approx(12.0, rel=0.15)
    assert 1.2 < r.gust / r.mean < 2.0


# ------------------------------------------------------------------ safety wind rules
def make(**changes):
    clock = FakeClock()
    cfg = with_changes(SafetyConfig(), wind_enabled=True, wind_hold=60.0, **changes)
    return SafetyCore(cfg, clock), clock


def blow(core, clock, speed, mean=None, seconds=1.0, dt=0.25, **kw):
    """Feed every node and ``seconds`` of wind messages (4 Hz)."""
    n = max(1, round(seconds / dt))
    for _ in range(n):
        feed(core, clock, dt=dt, **kw)
        core.on_wind(speed, speed, speed if mean is None else mean, 600.0)
        core.evaluate()
    return core.state


def test_gust_stows_at_once_in_the_wind_pose_and_releases_only_after_the_hold():
    core, clock = make()
    assert blow(core, clock, 5.0, seconds=15).level == Level.OK
    feed(core, clock)
    core.on_wind(21.0, 21.0, 8.0, 600.0)            # one 3 s mean over the 20 m/s limit
    st = core.evaluate()
    assert st.level == Level.STOW and st.stow_required and st.wind_stow
    assert rule_for(st.reasons[0]).kind == 'wind' and 'gust 21.0 m/s > 20.0' in st.reasons[0]
    assert hint_for(st.reasons[0])
    assert st.wind_release_in == pytest.approx(60.0)      # the hold counts from the gust
    st = blow(core, clock, 5.0, seconds=30)
    assert st.level == Level.STOW and 29.0 < st.wind_release_in < 31.0
    st = blow(core, clock, 5.0, seconds=29)
    assert st.level == Level.STOW and st.wind_release_in < 2.0
    st = blow(core, clock, 5.0, seconds=2)
    assert st.level == Level.OK and math.isnan(st.wind_release_in) and not st.wind_stow
    assert any('released' in n for n in core.drain_notes())


def test_mean_over_limit_stows_and_a_windy_spell_restarts_the_hold():
    core, clock = make()
    blow(core, clock, 5.0, seconds=15)
    st = blow(core, clock, 15.0, mean=14.5, seconds=1)
    assert st.level == Level.STOW and 'mean 14.5 m/s > 14.0' in st.reasons[0]
    st = blow(core, clock, 5.0, mean=10.0, seconds=40)
    assert st.wind_release_in == pytest.approx(20.0, abs=0.6)
    st = blow(core, clock, 12.0, mean=12.0, seconds=5)     # above 14 - 3: not calm
    assert st.level == Level.STOW and st.wind_release_in == math.inf
    notes = core.drain_notes()
    assert any('hold restarts' in n for n in notes) and any('release after 60 s' in n for n in notes)
    st = blow(core, clock, 5.0, mean=10.9, seconds=59)
    assert st.level == Level.STOW
    assert blow(core, clock, 5.0, mean=10.9, seconds=2).level == Level.OK
    # a refused reset says it clears by itself
    blow(core, clock, 25.0, seconds=0.25)
    ok, text = core.reset()
    assert not ok and 'wind' in text and 'calm' in text


def test_wind_and_over_temperature_together_release_only_when_both_clear():
    core, clock = make(cool_hold=5.0, auto_reset=True)
    blow(core, clock, 5.0, seconds=15)
    st = blow(core, clock, 25.0, seconds=0.5, temps=(60.0, 170.0))
    assert st.level == Level.STOW and not st.wind_stow           # over-temperature: sleeping pose
    assert {rule_for(r).kind for r in st.reasons} == {'wind', 'overtemp'}
    st = blow(core, clock, 5.0, seconds=10, temps=(60.0, 80.0))  # cooled + held: overtemp clears
    assert [rule_for(r).kind for r in st.reasons] == ['wind'] and st.wind_stow
    st = blow(core, clock, 5.0, seconds=52, temps=(60.0, 80.0))
    assert st.level == Level.OK
    # the other order: the wind calms first, the absorber is still hot
    st = blow(core, clock, 25.0, seconds=0.5, temps=(60.0, 170.0))
    st = blow(core, clock, 5.0, seconds=62, temps=(60.0, 170.0))
    assert [rule_for(r).kind for r in st.reasons] == ['overtemp']
    assert blow(core, clock, 5.0, seconds=7, temps=(60.0, 80.0)).level == Level.OK


def test_silent_anemometer_warns_then_is_treated_as_wind():
    core, clock = make(wind_silent_warn=5.0, wind_silent_stow=30.0)
    blow(core, clock, 5.0, seconds=15)
    st = feed(core, clock, dt=0.5, steps=12)                      # 6 s silent
    assert st.level == Level.WARN and rule_for(st.reasons[0]).kind == 'anemometer'
    st = feed(core, clock, dt=0.5, steps=50)                      # 31 s silent
    assert st.level == Level.STOW and st.wind_stow and 'anemometer silent > 30 s' in st.reasons[0]
    assert st.wind_release_in == math.inf
    st = blow(core, clock, 5.0, seconds=58)
    assert st.level == Level.STOW
    assert blow(core, clock, 5.0, seconds=3).level == Level.OK


def test_never_heard_anemometer_warns_after_the_grace_and_no_wind_rules_when_disabled():
    core, clock = make(wind_silent_stow=0.0)
    st = feed(core, clock, dt=0.5, steps=60)
    assert st.level == Level.WARN and 'never heard' in st.reasons[0]
    off = SafetyCore(SafetyConfig(), FakeClock())
    assert not off.config.wind_enabled
    st = feed(off, off.clock, dt=0.5, steps=60)
    off.on_wind(40.0, 40.0, 40.0, 600.0)
    assert off.evaluate().level == Level.OK


def test_stuck_zero_through_moving_clouds_warns():
    core, clock = make(wind_stuck_window=60.0, wind_stuck_beam_swing=200.0)
    for k in range(4 * 70):
        feed(core, clock, dt=0.25, beam=800.0 if (k // 40) % 2 else 450.0)   # clouds every 10 s
        core.on_wind(0.0, 0.0, 0.0, 600.0)
        st = core.evaluate()
    assert st.level == Level.WARN and 'stuck cups' in st.reasons[0]
    # a clear sky at 0 m/s is calm, not a fault
    core, clock = make(wind_stuck_window=60.0)
    st = blow(core, clock, 0.0, seconds=70, beam=800.0)
    assert st.level == Level.OK


def test_wind_parameters_documented_and_refused_when_bad():
    values = TABLE.defaults() if hasattr(TABLE, 'defaults') else {s.name: s.default for s in TABLE.specs}
    assert config_from(values).wind_gust_limit == 20.0
    for spec in TABLE.specs:
        if spec.name.startswith('wind.'):
            assert spec.description and spec.unit
    with pytest.raises(ValueError, match='hysteresis'):
        config_from({**values, 'wind.hysteresis': 20.0})
    with pytest.raises(ValueError, match='silent_stow'):
        config_from({**values, 'wind.silent_warn': 30.0, 'wind.silent_stow': 10.0})
    assert TABLE.validate({**values, 'wind.gust_limit': -1.0})
    core, _ = make()
    core.on_wind(math.nan, 1.0, 1.0, 600.0)
    assert core.counters['bad_inputs'] == 1
