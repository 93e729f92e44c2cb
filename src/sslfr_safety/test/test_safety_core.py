"""Unit tests of the safety rules (sslfr_safety.core), on numbers, with an
injected clock (steady and wall time moved by hand)."""
from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sslfr_common.contract import JOINTS as AXES
from sslfr_common.contract import SWITCH_AXIS, SWITCHES, Level, LinkState
from sslfr_safety.core import (FakeClock, SafetyConfig,
                                       SafetyCore, with_changes)

TRACKING, NIGHT, STOW_PHASE = 2, 0, 5
OPEN = {s: False for s in SWITCHES}


def make(**changes):
    """A core with a fake clock, past the start-up grace, every node healthy."""
    clock = FakeClock()
    cfg = with_changes(SafetyConfig(), cool_hold=5.0, **changes)
    core = SafetyCore(cfg, clock)
    return core, clock


def feed(core, clock, dt=0.1, steps=1, phase=NIGHT, temps=(60.0, 80.0), switches=None,
         positions=None, homing=(), beam=800.0, wall_step=0.0):
    """Advance ``steps`` x ``dt`` [s] delivering every watched node's messages."""
    for _ in range(steps):
        clock.advance(dt)
        if wall_step:
            clock.step_wall(wall_step)
            wall_step = 0.0
        core.on_phase(phase, 'parameters')
        core.on_gps_fix(True)
        core.on_beam(beam)
        for axis in AXES:
            pos = (positions or {}).get(axis, 0.3)
            core.on_axis_status(axis, axis in homing, pos)
            # the driver part of the same status: active, link up, referenced
            core.on_driver_state(axis, 'homing' if axis in homing else 'following', LinkState.LINK_UP, True)
        core.on_limit_switches({**OPEN, **(switches or {})})
        for name, value in zip(('inlet', 'outlet'), temps):
            if value is not None:
                core.on_temperature(name, value)
        core.evaluate()
    return core.state


def test_healthy_system_is_ok_and_switch_axis_table_is_documented():
    core, clock = make()
    assert feed(core, clock, steps=150).level == Level.OK        # 15 s, past the grace
    assert core.state.reasons == () and core.state.stopped_axes == ()
    assert SWITCH_AXIS == {'initial': 'mirrors', 'last': 'mirrors', 'sleeping': 'mirrors',
                           'longitudinal_1': 'mobile_structure', 'longitudinal_2': 'secondary_reflector'}


def test_over_temperature_stows_at_once_and_stays_latched_until_cooled_held_and_reset():
    core, clock = make()
    feed(core, clock, steps=120)
    core.on_temperature('outlet', 150.0)                # exactly the limit: not exceeded
    assert core.evaluate().level == Level.OK
    core.on_temperature('outlet', 150.3)
    state = core.evaluate()                            # no time has passed
    assert state.level == Level.STOW and state.stow_required
    assert any('outlet over-temperature' in r and '150.3' in r for r in state.reasons)
    since = state.since
    # still hot, and between limit - hysteresis and limit: refused, unchanged
    for temp in (152.0, 145.0):
        feed(core, clock, steps=20, temps=(60.0, temp))
        before = core.state
        ok, msg = core.reset()
        assert not ok and 'still hot' in msg and 'outlet' in msg
        assert core.evaluate() == before
    # cooled below 140 degC, but not for the hold time (5 s here)
    feed(core, clock, steps=20, temps=(60.0, 139.0))
    ok, msg = core.reset()
    assert not ok and 'cooling' in msg
    # no return to OK by itself (auto-reset off by default), however long it cools
    feed(core, clock, steps=100, temps=(60.0, 100.0))
    assert core.state.level == Level.STOW and core.state.since == since
    ok, msg = core.reset()
    assert ok and 'overtemp:outlet' in msg
    assert core.state.level == Level.OK and core.state.reasons == ()


def test_auto_reset_policy_clears_after_the_hold_time_when_enabled():
    core, clock = make(auto_reset=True)
    feed(core, clock, steps=120)
    feed(core, clock, steps=1, temps=(151.0, 80.0))
    assert core.state.level == Level.STOW
    feed(core, clock, steps=30, temps=(139.0, 80.0))    # 3 s < 5 s hold
    assert core.state.level == Level.STOW
    feed(core, clock, steps=30, temps=(139.0, 80.0))
    assert core.state.level == Level.OK


@pytest.mark.parametrize('value,flag,word', [(math.nan, False, 'NaN'), (25.0, True, 'open circuit'),
                                             (math.inf, False, 'outside'), (-200.0, False, 'outside')])
def test_invalid_thermocouple_stows_immediately_until_it_recovers(value, flag, word):
    core, clock = make()
    feed(core, clock, steps=120)
    core.on_temperature('inlet', value, open_circuit=flag)
    state = core.evaluate()
    assert state.level == Level.STOW
    assert any(r.startswith('inlet thermocouple invalid') and word in r for r in state.reasons)
    feed(core, clock, steps=30, temps=(math.nan if flag else value, 80.0))   # still invalid: held
    assert core.state.level == Level.STOW
    ok, msg = core.reset()                                      # nothing to reset: it is not latched
    assert not ok and 'clears by itself' in msg
    feed(core, clock, steps=19)                                 # valid for 1.9 s < 2 s recovery hold
    assert core.state.level == Level.STOW
    feed(core, clock, steps=2)
    assert core.state.level == Level.OK
    assert core.counters['invalid_samples'] == 31


def test_latched_thermocouple_policy_needs_a_reset():
    core, clock = make(sensor_fault_latched=True)
    feed(core, clock, steps=120)
    feed(core, clock, steps=2, temps=(60.0, math.nan))
    ok, msg = core.reset()
    assert not ok and 'outlet thermocouple still invalid' in msg
    feed(core, clock, steps=10)
    ok, msg = core.reset()
    assert not ok and 'outlet thermocouple valid for 0.9 s of 2.0 s' in msg
    feed(core, clock, steps=30)
    assert core.state.level == Level.STOW                      # recovered, but latched
    assert core.reset()[0] and core.state.level == Level.OK


def test_silent_thermocouple_stows_within_two_seconds_only_while_tracking():
    core, clock = make()
    feed(core, clock, steps=120, phase=NIGHT, temps=(60.0, None))   # outlet silent at night: fine
    assert core.state.level == Level.OK
    feed(core, clock, steps=19, phase=TRACKING, temps=(60.0, None))  # 1.9 s of tracking
    assert core.state.level == Level.OK
    feed(core, clock, steps=2, phase=TRACKING, temps=(60.0, None))
    assert core.state.level == Level.STOW
    assert any('outlet thermocouple silent > 2.0 s while tracking' in r for r in core.state.reasons)
    # the planner stows (phase STOW): not tracking any more, but the sensor is still
    # silent, so the stow holds (no stow/track oscillation) until it speaks again
    feed(core, clock, steps=50, phase=STOW_PHASE, temps=(60.0, None))
    assert core.state.level == Level.STOW
    feed(core, clock, steps=19, phase=STOW_PHASE)
    assert core.state.level == Level.STOW                       # valid for < 2 s
    feed(core, clock, steps=2, phase=STOW_PHASE)
    assert core.state.level == Level.OK


def test_stuck_thermocouple_while_sun_on_receiver():
    core, clock = make(stuck_timeout=30.0)
    # constant value but night, then tracking with a cloud (beam below 200 W/m^2): not stuck
    feed(core, clock, steps=400, phase=NIGHT, temps=(60.0, 80.0))
    feed(core, clock, steps=400, phase=TRACKING, temps=(60.0, 80.0), beam=50.0)
    assert core.state.level == Level.OK
    # a moving inlet, a frozen outlet with the sun on: stuck after 30 s
    for k in range(290):
        feed(core, clock, phase=TRACKING, temps=(60.0 + 0.25 * (k % 2), 80.0))
    assert core.state.level == Level.OK
    feed(core, clock, steps=20, phase=TRACKING, temps=(60.0, 80.0))
    assert core.state.level == Level.STOW
    assert any('outlet thermocouple stuck at 80.00 degC' in r for r in core.state.reasons)
    assert not any(r.startswith('inlet') for r in core.state.reasons)
    feed(core, clock, steps=50, phase=STOW_PHASE, temps=(60.0, 80.0))
    assert core.state.level == Level.STOW                       # still frozen: held
    feed(core, clock, steps=1, phase=STOW_PHASE, temps=(60.0, 80.25))
    assert core.state.level == Level.OK


def test_limit_switch_outside_homing_stops_its_axis_and_names_the_switch():
    core, clock = make()
    feed(core, clock, steps=120)
    feed(core, clock, steps=1, switches={'longitudinal_1': True}, positions={'mobile_structure': 0.6})
    state = core.state
    assert state.level == Level.ESTOP and state.stopped_axes == ('mobile_structure',)
    assert state.stow_required      # the other axes go to their safe position
    assert any('limit switch longitudinal_1 tripped outside homing' in r for r in state.reasons)
    # reset acknowledges the trip although the switch is still closed (jog it off)
    assert core.reset()[0] and core.state.level == Level.OK
    feed(core, clock, steps=3, switches={'longitudinal_1': True}, positions={'mobile_structure': 0.6})
    assert core.state.level == Level.OK                  # acknowledged, not re-tripped
    feed(core, clock, steps=1)                           # opens: re-armed
    feed(core, clock, steps=1, switches={'longitudinal_1': True}, positions={'mobile_structure': 0.6})
    assert core.state.level == Level.ESTOP


@pytest.mark.parametrize('switch,axis,pos', [('sleeping', 'mirrors', math.pi / 2),
                                             ('initial', 'mirrors', -math.pi / 4),
                                             ('last', 'mirrors', math.pi / 4),
                                             ('longitudinal_2', 'secondary_reflector', 0.0)])
def test_switch_closed_at_its_nominal_position_or_while_homing_is_not_a_trip(switch, axis, pos):
    core, clock = make()
    feed(core, clock, steps=120)
    feed(core, clock, steps=20, switches={switch: True}, positions={axis: pos + 0.02})
    assert core.state.level == Level.OK
    feed(core, clock, steps=2)
    feed(core, clock, steps=5, switches={switch: True}, positions={axis: pos + 0.5}, homing=(axis,))
    assert core.state.level == Level.OK
    feed(core, clock, steps=12, positions={axis: pos + 0.5})   # parked > switch_lookback (1 s)
    feed(core, clock, steps=1, switches={switch: True}, positions={axis: pos + 0.5})
    assert core.state.level == Level.ESTOP and core.state.stopped_axes == (axis,)
    assert any(f'limit switch {switch} tripped' in r for r in core.state.reasons)


def test_switch_closure_with_unknown_axis_position_is_judged_once_a_position_is_known():
    clock = FakeClock()
    core = SafetyCore(SafetyConfig(watchdogs={}, require_site_and_time=False), clock)
    core.on_limit_switches({**OPEN, 'last': True, 'longitudinal_2': True})   # no axis status yet
    clock.advance(30.0)
    core.on_axis_status('mirrors', False, math.nan)      # driver up, no board: cannot move
    assert core.evaluate().level == Level.OK
    core.on_limit_switches({**OPEN, 'last': True})      # longitudinal_2 opened meanwhile
    core.on_axis_status('mirrors', False, 0.3, commanded=0.3)
    core.on_axis_status('secondary_reflector', False, 0.6, commanded=0.6)
    state = core.evaluate()
    assert state.level == Level.ESTOP and state.stopped_axes == ('mirrors',)
    assert [r.split(' (')[0] for r in state.reasons] == ['limit switch last tripped outside homing']


def test_dawn_mirrors_asleep_on_their_switch_then_homed_is_not_a_trip():
    """Power-up at dawn: the mirrors rest on the sleeping switch, the driver publishes an
    unknown position (not referenced) before it starts homing: no trip, then homing
    and tracking away from the switch."""
    clock = FakeClock()
    core = SafetyCore(SafetyConfig(watchdogs={}, require_site_and_time=False), clock)
    core.on_axis_status('mirrors', False, math.nan)            # stopped, not referenced
    core.on_limit_switches({**OPEN, 'sleeping': True})
    clock.advance(0.2)
    core.on_axis_status('mirrors', False, math.nan)
    assert core.evaluate().level == Level.OK
    core.on_axis_status('mirrors', True, 0.0)                  # homing: relative steps
    clock.advance(0.2)
    core.on_axis_status('mirrors', False, math.pi / 2, commanded=math.pi / 2)   # homed there
    core.on_limit_switches(OPEN)
    core.on_axis_status('mirrors', False, 0.3, commanded=0.3)
    assert core.evaluate().level == Level.OK


def test_stow_switch_reached_before_the_status_says_stow_is_expected():
    """A link drop of the mirrors makes this core require a stow; the secondary
    reflector runs to its stow switch (0 rad) faster than its 5 Hz status reports the
    new command (seen on the firmware rig at 120x: a trip with 'secondary_reflector at
    0.098 rad, commanded 0.098 rad'). Its stow position is on its path for the
    look-back after a stow verdict, not later."""
    core, clock = make()
    pos = {'secondary_reflector': 0.098}
    feed(core, clock, steps=20, positions=pos)
    assert core.state.level == Level.OK
    clock.advance(0.1)
    core.on_driver_state('mirrors', 'link_down', LinkState.LINK_CONNECTING, False)
    assert core.evaluate().stow_required
    clock.advance(0.15)                       # no new secondary status yet: 0.098 / 0.098
    core.on_limit_switches({**OPEN, 'longitudinal_2': True})
    assert core.evaluate().level == Level.STOW, core.state.reasons
    # the same closure long after the last stow verdict is a trip
    core2, clock2 = make()
    feed(core2, clock2, steps=20, positions=pos)
    core2.on_driver_state('mirrors', 'link_down', LinkState.LINK_CONNECTING, False)
    core2.evaluate()
    feed(core2, clock2, steps=15, positions=pos)          # ready again: OK for 1.5 s
    assert core2.state.level == Level.OK
    core2.on_limit_switches({**OPEN, 'longitudinal_2': True})
    assert core2.evaluate().level == Level.ESTOP


def test_switch_on_the_commanded_path_is_expected_even_with_a_stale_measurement():
    """Stowing at 2 rad/s (sim speed): the 5 Hz status lags, but the sleeping switch
    (the target) and the last switch (passed on the way) are on the path."""
    core, clock = make()
    feed(core, clock, steps=120)
    core.on_axis_status('mirrors', False, 0.4, commanded=math.pi / 2)
    for name in ('last', 'sleeping'):
        core.on_limit_switches({**OPEN, name: True})
        assert core.evaluate().level == Level.OK, name
    core.on_limit_switches(OPEN)
    core.on_limit_switches({**OPEN, 'initial': True})     # behind the axis: a trip
    assert core.evaluate().level == Level.ESTOP


def test_switch_passed_by_a_moving_axis_is_expected_despite_message_delays():
    """Stowing at 0.6 rad/s: the 'last' switch (0.785 rad) closes on the way, but its
    message arrives after a status that already shows the axis past it (0.842 rad)."""
    core, clock = make()
    feed(core, clock, steps=120)
    for k in range(10):                           # statuses at 5 Hz while stowing
        clock.advance(0.1)
        core.on_axis_status('mirrors', False, 0.3 + 0.06 * k, commanded=math.pi / 2)
    clock.advance(0.05)
    core.on_axis_status('mirrors', False, 0.842, commanded=math.pi / 2)
    core.on_limit_switches({**OPEN, 'last': True})
    assert core.evaluate().level == Level.OK
    # the same closure with the axis parked at 1.2 rad for more than the look-back: a trip
    core.on_limit_switches(OPEN)
    for _ in range(12):
        clock.advance(0.1)
        core.on_axis_status('mirrors', False, 1.2, commanded=1.2)
    core.on_limit_switches({**OPEN, 'last': True})
    assert core.evaluate().level == Level.ESTOP


def test_stuck_closed_switch_detected_at_homing():
    core, clock = make()
    feed(core, clock, steps=120)
    # homing mirrors: 'initial' stays closed while the axis travels 0.3 rad
    for k in range(10):
        feed(core, clock, switches={'initial': True}, homing=('mirrors',),
             positions={'mirrors': 0.6 + 0.03 * k})
    state = core.state
    assert state.level == Level.ESTOP and state.stopped_axes == ('mirrors',)
    assert any('limit switch initial stuck closed' in r for r in state.reasons)
    ok, msg = core.reset()
    assert not ok and 'initial still reads closed' in msg
    feed(core, clock, steps=2)
    assert core.reset()[0]
    # two mirror switches closed together during homing: one of them is stuck
    feed(core, clock, steps=2, switches={'last': True, 'sleeping': True}, homing=('mirrors',),
         positions={'mirrors': 1.0})
    assert {'limit switch last stuck closed', 'limit switch sleeping stuck closed'} <= {
        r.split(' (')[0] for r in core.state.reasons}
    # a healthy homing: the switch opens as the axis leaves it -> no fault
    core2, clock2 = make()
    feed(core2, clock2, steps=120)
    feed(core2, clock2, steps=2, switches={'sleeping': True}, homing=('mirrors',), positions={'mirrors': 1.57})
    for k in range(10):
        feed(core2, clock2, homing=('mirrors',), positions={'mirrors': 1.5 - 0.05 * k})
    assert core2.state.level == Level.OK


def test_heartbeat_watchdogs_follow_the_table_and_name_the_node():
    core, clock = make(watchdogs={'planner': (5.0, 'STOW'), 'irradiance': (3.0, 'WARN')})
    feed(core, clock, steps=120)
    for _ in range(35):                  # irradiance stops; everyone else speaks
        clock.advance(0.1)
        core.on_phase(NIGHT, 'persisted')
        core.evaluate()
    assert core.state.level == Level.WARN
    assert core.state.reasons == ('irradiance silent > 3.0 s (heartbeat watchdog)',)
    for _ in range(30):                  # the planner too: STOW, both named
        clock.advance(0.2)
        core.evaluate()
    assert core.state.level == Level.STOW
    assert 'planner silent > 5.0 s (heartbeat watchdog)' in core.state.reasons
    feed(core, clock, steps=1)           # both back: self-clearing, no reset needed
    assert core.state.level == Level.OK


def test_never_heard_nodes_are_judged_after_the_startup_grace():
    clock = FakeClock()
    core = SafetyCore(with_changes(SafetyConfig(), require_site_and_time=False), clock)
    clock.advance(11.0)
    assert not [r for r in core.evaluate().reasons if 'heartbeat' in r]   # within the grace
    clock.advance(1.5)
    state = core.evaluate()
    assert state.level == Level.STOW
    assert 'mirrors_driver never heard > 2.0 s (heartbeat watchdog)' in state.reasons


def test_estop_latched_until_release_and_then_stows_until_reset():
    core, clock = make()
    feed(core, clock, steps=120)
    before = core.state
    ok, msg = core.estop(False)                        # release without e-stop: refused
    assert not ok and 'no e-stop' in msg and core.evaluate() == before
    ok, msg = core.estop(True)
    assert ok
    state = core.state
    assert state.level == Level.ESTOP and state.stopped_axes == AXES and not state.stow_required
    assert core.estop(True) == (True, 'e-stop already engaged')
    feed(core, clock, steps=50)
    assert core.state.level == Level.ESTOP             # latched
    ok, msg = core.reset()
    assert not ok and 'release it first' in msg and core.state.level == Level.ESTOP
    assert core.estop(False)[0]
    assert core.state.level == Level.STOW and core.state.stow_required and core.state.stopped_axes == ()
    feed(core, clock, steps=10)
    assert core.state.level == Level.STOW              # no return to tracking by itself
    assert core.reset()[0] and core.state.level == Level.OK
    ok, msg = core.reset()
    assert not ok and 'nothing latched' in msg
    assert core.counters['refused_requests'] == 3


def test_no_site_or_no_time_keeps_the_tracker_asleep():
    clock = FakeClock(wall=1_750_000_000.0)
    core = SafetyCore(SafetyConfig(watchdogs={}), clock)
    state = core.evaluate()
    assert state.level == Level.STOW and any(r.startswith('no site') for r in state.reasons)
    core.on_phase(NIGHT, 'persisted')
    assert core.evaluate().level == Level.OK
    core.on_phase(NIGHT, 'gps')                        # planner waits for a fix this boot
    assert core.evaluate().level == Level.STOW
    core.on_gps_fix(False)
    assert core.evaluate().level == Level.STOW
    core.on_gps_fix(True)
    assert core.evaluate().level == Level.OK
    # a 1970 system clock (Pi without RTC) and no fix: no time
    clock2 = FakeClock(wall=86_400.0)
    core2 = SafetyCore(SafetyConfig(watchdogs={}), clock2)
    core2.on_phase(NIGHT, 'persisted')
    assert [r.split(':')[0] for r in core2.evaluate().reasons] == ['no time']
    core2.on_gps_fix(True)
    assert core2.evaluate().level == Level.OK


@pytest.mark.parametrize('step', [3600.0, -3600.0])
def test_wall_clock_step_neither_fakes_a_timeout_nor_stalls_a_watchdog(step):
    core, clock = make()
    feed(core, clock, steps=120, phase=TRACKING)
    assert core.state.level == Level.OK
    core.drain_transitions()
    since = core.state.since
    # every node keeps talking; the wall clock jumps by +/- 1 h in the middle
    feed(core, clock, steps=100, phase=TRACKING, wall_step=step)
    feed(core, clock, steps=100, phase=TRACKING)
    assert core.state.level == Level.OK and core.state.since == since
    assert core.drain_transitions() == []
    # and a watchdog still fires on time after the step (not stalled, not shifted)
    for _ in range(21):
        clock.advance(0.1)
        core.on_phase(TRACKING, 'parameters')
        for axis in AXES:
            core.on_axis_status(axis, False, 0.3)
        core.on_beam(800.0)
        core.on_gps_fix(True)
        core.on_temperature('inlet', 60.0)
        core.on_temperature('outlet', 80.0)
        core.evaluate()
    clock.advance(0.1)
    core.on_temperature('inlet', 60.0)
    core.on_temperature('outlet', 80.0)
    core.evaluate()
    assert core.state.level == Level.OK                  # absorber_board alive via temperatures
    # a node silent for 2.1 s on the steady clock trips, whatever the wall clock did
    core2, clock2 = make()
    feed(core2, clock2, steps=120)
    clock2.step_wall(step)
    clock2.advance(2.05)
    core2.on_phase(NIGHT, 'parameters')
    state = core2.evaluate()
    assert state.level == Level.STOW
    assert 'mirrors_driver silent > 2.0 s (heartbeat watchdog)' in state.reasons


def test_transitions_are_recorded_with_added_and_removed_reasons():
    core, clock = make()
    feed(core, clock, steps=120)
    core.drain_transitions()
    feed(core, clock, temps=(151.0, 80.0))
    (tr,) = core.drain_transitions()
    assert (tr.old_level, tr.new_level) == (Level.OK, Level.STOW)
    assert 'inlet over-temperature' in tr.added[0] and tr.removed == ()
    assert 'OK -> STOW' in str(tr)


@pytest.mark.parametrize('changes,word', [
    ({'temperature_limit': math.nan}, 'temperature_limit'),
    ({'hysteresis': -1.0}, 'hysteresis'),
    ({'silent_timeout': 0.0}, 'silent_timeout'),
    ({'watchdogs': {'planner': (5.0, 'PANIC')}}, 'WARN or STOW'),
    ({'watchdogs': {'toaster': (5.0, 'WARN')}}, 'toaster'),
    ({'switch_positions': {'initial': 0.0}}, 'switch_positions'),
])
def test_bad_configuration_is_refused_and_the_core_keeps_the_old_one(changes, word):
    core, _ = make()
    old = core.config
    with pytest.raises(ValueError, match=word):
        core.configure(_unchecked(old, **changes))
    assert core.config is old


def _unchecked(config, **changes):
    from dataclasses import replace
    return replace(config, **changes)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 200.0), st.floats(0.0, 200.0)), min_size=1, max_size=40))
def test_property_stow_iff_a_sample_exceeded_the_limit(samples):
    """Over-temperature latch invariant: without a reset, the level is >= STOW exactly
    from the first sample above 150 degC on, and never before."""
    core, clock = make(watchdogs={})
    tripped = False
    for inlet, outlet in samples:
        clock.advance(0.25)
        core.on_phase(NIGHT, 'parameters')
        core.on_temperature('inlet', inlet)
        core.on_temperature('outlet', outlet)
        tripped |= inlet > 150.0 or outlet > 150.0
        assert (core.evaluate().level >= Level.STOW) == tripped


def test_a_one_movement_collector_is_judged_on_what_it_has():
    """Issue 34: seed 004's collector has the mirrors' driver, the absorber and irradiance
    boards and no GPS: the absent axes and the GPS are never faults; its own silent
    driver still is, and a status of an axis it lacks is refused and counted."""
    clock = FakeClock()
    present = ('planner', 'mirrors_driver', 'absorber_board', 'irradiance')
    full = SafetyConfig()
    cfg = with_changes(full, present=present, require_site_and_time=False,
                       watchdogs={n: s for n, s in full.watchdogs.items() if n in present})
    core = SafetyCore(cfg, clock)
    assert cfg.joints == ('mirrors',) and set(core.axes) == {'mirrors'}

    def tick(mirrors=True):
        clock.advance(0.1)
        core.on_phase(TRACKING, 'parameters')
        core.on_beam(800.0)
        if mirrors:
            core.on_axis_status('mirrors', False, 0.3)
            core.on_driver_state('mirrors', 'following', LinkState.LINK_UP, True)
        core.on_limit_switches(OPEN)
        core.on_temperature('inlet', 60.0)
        core.on_temperature('outlet', 80.0)
        return core.evaluate()
    for _ in range(150):
        state = tick()
    assert state.level == Level.OK, state.reasons
    core.on_axis_status('mobile_structure', False, 0.1)
    assert core.counters['invalid_samples'] == 1
    for _ in range(30):                                  # its own driver falls silent: a fault
        state = tick(mirrors=False)
    assert state.level == Level.STOW and any('mirrors_driver silent' in r for r in state.reasons), state.reasons
    with pytest.raises(ValueError, match='not in this collector'):
        with_changes(cfg, watchdogs={'gps': (5.0, 'WARN')})
