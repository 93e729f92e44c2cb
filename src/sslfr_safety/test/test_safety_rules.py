"""Unit tests of the safety rules as data (sslfr_safety.rules) and of the rule
on axes whose driver is not driving them (issue 21), on a fake clock."""
from __future__ import annotations

import copy
import math
import re
from pathlib import Path

import pytest

from sslfr_common.contract import JOINTS, SWITCHES, Level, LinkState
from sslfr_safety import rules as R
from sslfr_safety.core import FakeClock, SafetyConfig, SafetyCore, with_changes
from sslfr_safety.params import TABLE, config_from

NIGHT, TRACKING = 0, 2
OPEN = {s: False for s in SWITCHES}
UP, DOWN, CONNECTING = LinkState.LINK_UP, LinkState.LINK_DOWN, LinkState.LINK_CONNECTING
README = Path(__file__).resolve().parents[1] / 'README.md'


def make(**changes):
    clock = FakeClock()
    return SafetyCore(with_changes(SafetyConfig(), cool_hold=5.0, **changes), clock), clock


def feed(core, clock, steps=1, dt=0.1, driver=None, report=True, temps=(60.0, 80.0), phase=NIGHT):
    """``steps`` x ``dt`` [s] of every watched node's messages; ``driver`` maps an axis to
    its (state, link_state, homed) report (default: active, link up, referenced);
    ``report=False`` leaves the axis statuses out (the drivers are silent)."""
    for _ in range(steps):
        clock.advance(dt)
        core.on_phase(phase, 'parameters')
        core.on_gps_fix(True)
        core.on_beam(800.0)
        for axis in JOINTS:
            state, link, homed = (driver or {}).get(axis, ('following', UP, True))
            if report:
                core.on_axis_status(axis, state == 'homing', 0.3)
                core.on_driver_state(axis, state, link, homed)
        core.on_limit_switches(OPEN)
        for name, value in zip(('inlet', 'outlet'), temps):
            core.on_temperature(name, value)
        core.evaluate()
    return core.state


def axis_reasons(core, axis='mobile_structure'):
    return [r for r in core.state.reasons if r.startswith(f'{axis} axis not ready')]


# ------------------------------------------------------------------ issue 21: idle drivers
def test_no_ok_at_start_up_before_every_watched_driver_reports_ready():
    """Drivers starting (under ros2 launch: safety up 1.4 s before the first driver
    status) are not OK: a watched driver never heard keeps its axis not ready; an
    unwatched one (a bench with fewer axes) is not judged."""
    core, clock = make()
    feed(core, clock, steps=5, report=False)
    assert core.state.level == Level.STOW
    assert sorted(r for r in core.state.reasons if 'no status from its driver yet' in r) == \
        [f'{a} axis not ready: no status from its driver yet' for a in sorted(JOINTS)]
    assert feed(core, clock, steps=5).level == Level.OK          # all three report ready
    bench, clock = make(watchdogs={'planner': (5.0, 'STOW'), 'mirrors_driver': (2.0, 'STOW')})
    feed(bench, clock, steps=5, report=False)
    assert [r for r in bench.state.reasons if 'axis not ready' in r] == \
        ['mirrors axis not ready: no status from its driver yet']


@pytest.mark.parametrize('state', ['unconfigured', 'inactive', 'finalized'])
def test_an_idle_driver_stows_naming_its_axis_until_active_and_referenced(state):
    core, clock = make()
    assert feed(core, clock, steps=120).level == Level.OK
    feed(core, clock, steps=30, driver={'mobile_structure': (state, UP, True)})
    assert core.state.level == Level.STOW and core.state.stow_required and core.state.stopped_axes == ()
    assert axis_reasons(core) == [f'mobile_structure axis not ready: its driver is {state}, not active']
    # configured again, link up, but the board lost its reference: still not ready
    feed(core, clock, steps=30, driver={'mobile_structure': ('homing', UP, False)})
    assert core.state.level == Level.STOW
    assert axis_reasons(core) == ['mobile_structure axis not ready: driver active, axis not referenced yet '
                                  '(state homing)']
    feed(core, clock, steps=1)                      # active and referenced: self-clearing
    assert core.state.level == Level.OK and core.state.reasons == ()


def test_a_board_link_not_up_stows_until_up_and_referenced():
    core, clock = make()
    feed(core, clock, steps=120)
    feed(core, clock, steps=5, driver={'mirrors': ('link_down', DOWN, False)})
    assert axis_reasons(core, 'mirrors') == ['mirrors axis not ready: board link down']
    feed(core, clock, steps=5, driver={'mirrors': ('link_down', CONNECTING, False)})
    assert axis_reasons(core, 'mirrors') == ['mirrors axis not ready: board link connecting']
    feed(core, clock, steps=5, driver={'mirrors': ('following', UP, True)})    # the board kept its reference
    assert core.state.level == Level.OK


def test_an_active_driver_homing_again_is_no_fault():
    """The axis rule is raised by a driver that is not active; an active driver that
    re-homes (board reset) with its link up keeps the axis ready."""
    core, clock = make()
    feed(core, clock, steps=120)
    feed(core, clock, steps=50, driver={'mirrors': ('homing', UP, False)})
    assert core.state.level == Level.OK


def test_after_a_silence_the_restarted_driver_must_be_referenced_again():
    core, clock = make()
    feed(core, clock, steps=120)
    feed(core, clock, steps=25, report=False)      # every driver silent 2.5 s (killed): the watchdogs
    assert core.state.level == Level.STOW
    assert 'mobile_structure_driver silent > 2.0 s (heartbeat watchdog)' in core.state.reasons
    assert axis_reasons(core) == []                 # silence is the watchdog's to report
    # back, self-activated, but still homing: the watchdog clears, the axis rule holds
    feed(core, clock, steps=10, driver={a: ('homing', UP, False) for a in JOINTS})
    assert core.state.level == Level.STOW
    assert not any('heartbeat watchdog' in r for r in core.state.reasons)
    assert axis_reasons(core) and len(core.state.reasons) == 3
    feed(core, clock, steps=1)
    assert core.state.level == Level.OK


def test_a_stow_watched_node_not_heard_yet_keeps_the_start_up_stowed_without_alarm():
    """Within the start-up grace a node whose watchdog action is STOW (the absorber
    board: over-temperature would be unknown) keeps the tracker stowed, named, before
    the never-heard alarm; a WARN node (gps, irradiance) is not judged yet."""
    core, clock = make()
    clock.advance(1.0)
    core.on_phase(NIGHT, 'parameters')
    core.on_gps_fix(True)
    for axis in JOINTS:
        core.on_axis_status(axis, False, 0.3)
        core.on_driver_state(axis, 'following', UP, True)
    state = core.evaluate()
    assert state.level == Level.STOW and 'absorber_board not heard yet (start-up)' in state.reasons
    assert not [r for r in state.reasons if 'irradiance' in r or 'never heard' in r], state.reasons
    core.on_limit_switches(OPEN)
    for name in ('inlet', 'outlet'):
        core.on_temperature(name, 60.0)
    assert core.evaluate().level == Level.OK, core.state.reasons


def test_never_reported_watched_axes_are_not_ready_then_judged_by_their_reports():
    clock = FakeClock()
    core = SafetyCore(with_changes(SafetyConfig(), require_site_and_time=False), clock)
    clock.advance(11.0)
    state = core.evaluate()
    assert state.level == Level.STOW
    assert [r for r in state.reasons if 'axis not ready' in r] == \
        [f'{a} axis not ready: no status from its driver yet' for a in JOINTS]
    core.on_driver_state('mirrors', 'unconfigured', DOWN, False)
    state = core.evaluate()
    assert state.level == Level.STOW and 'mirrors axis not ready: its driver is unconfigured, not active' \
        in state.reasons and 'mirrors axis not ready: no status from its driver yet' not in state.reasons


# ------------------------------------------------------------------ rules as data
def test_the_verdict_is_read_only():
    core, clock = make()
    feed(core, clock, steps=120, phase=TRACKING)
    core.on_temperature('outlet', 151.0)                          # a stored fault
    core.on_driver_state('mirrors', 'inactive', UP, True)         # a self-clearing one
    clock.advance(30.0)                                           # time passes: silent sensors due
    keep = {k: v for k, v in vars(core).items() if k not in ('clock', 'rules')}
    before = copy.deepcopy(keep)
    first = core.verdict()
    assert core.verdict() == first and core.conditions() == core.conditions()
    assert {k: v for k, v in vars(core).items() if k not in ('clock', 'rules')} == before
    # the time-detected faults are raised by the time handler, not by the verdict
    assert not any('thermocouple silent' in r for r in first.reasons)
    assert any('thermocouple silent' in r for r in core.evaluate().reasons)


def test_each_rule_is_one_entry_with_texts_hint_and_clearing():
    kinds = [r.kind for r in R.RULES]
    assert len(set(kinds)) == len(kinds)
    assert set(kinds) == {'overtemp', 'thermocouple', 'switch', 'stuck_switch', 'estop', 'post_estop',
                          'watchdog', 'site', 'time', 'axis', 'wind', 'anemometer'}
    for rule in R.RULES:
        assert rule.reasons and rule.hint.endswith('.'), rule.kind
        if rule.clears is R.Clear.SELF:
            assert rule.condition is not None, rule.kind
        if rule.clears in (R.Clear.RECOVERY, R.Clear.RELEASE):
            assert rule.blocker is not None, rule.kind
        for variant, template in rule.reasons.items():       # every text finds its own rule
            sample = template.format_map(_Any())
            assert R.rule_for(sample) is rule, (rule.kind, variant, sample)
    cfg = SafetyConfig()
    assert R.RULES[0].clearing(cfg) is R.Clear.RESET
    assert R.RULES[0].clearing(with_changes(cfg, auto_reset=True)) is R.Clear.RESET_OR_RECOVERY
    assert R.RULES[1].clearing(with_changes(cfg, sensor_fault_latched=True)) is R.Clear.RESET
    assert R.hint_for('something new') == ''


class _Any(dict):
    """format_map filler: every field is 1.5 (numbers) or a word (strings)."""

    def __missing__(self, key):
        return _Sample()


class _Sample(float):
    def __new__(cls):
        return super().__new__(cls, 1.5)

    def __format__(self, spec):
        return format(1.5, spec) if spec else 'x'


def test_adding_a_rule_is_one_entry_judged_by_the_generic_evaluation():
    low_beam = R.Rule('low_beam', Level.WARN, R.Clear.SELF, {'low': 'beam {beam:.0f} W/m^2 below 100'},
                      'Clouds: nothing to do.',
                      condition=lambda core, _n, _t: ('low', {'beam': core.beam})
                      if core.beam is not None and core.beam < 100.0 else None)
    clock = FakeClock()
    core = SafetyCore(with_changes(SafetyConfig(), require_site_and_time=False, watchdogs={}), clock,
                      rules=(*R.RULES, low_beam))
    core.on_beam(40.0)
    assert core.evaluate().level == Level.WARN and core.state.reasons == ('beam 40 W/m^2 below 100',)
    core.on_beam(400.0)
    assert core.evaluate().level == Level.OK


def test_the_readme_rule_table_is_the_rules():
    text = README.read_text()
    rows = re.findall(r'^\| `([a-z_]+)(?::<[a-z]+>)?` \| ([A-Z/ ()a-z]+?) \| ([a-z ,()_-]+?) \|', text, re.M)
    assert rows, 'no rule table in the README'
    doc = {kind: (level.strip(), clears.strip()) for kind, level, clears in rows}
    want = {}
    for rule in R.RULES:
        level = rule.level.name if isinstance(rule.level, Level) else 'WARN or STOW (table)'
        clears = rule.clears.value + (f' ({rule.option[1].value} with {rule.option[0]})' if rule.option else '')
        want[rule.kind] = (level, clears)
    assert doc == want


# ------------------------------------------------------------------ parameters: one table
def test_parameter_table_defaults_make_the_default_config_and_bad_values_are_named():
    values = TABLE.defaults()
    assert TABLE.validate(values) == []
    assert config_from(values) == SafetyConfig()
    bad = {**values, 'watchdog.actions': ['PANIC'] * 7}
    assert any('WARN or STOW' in e for e in TABLE.validate(bad))
    assert any('lengths differ' in e for e in TABLE.validate({**values, 'watchdog.timeouts': [1.0]}))
    assert any('publish_rate' in e for e in TABLE.validate({**values, 'publish_rate': 5.0}))
    assert any('temperature.limit' in e for e in TABLE.check_overrides({'temperature.limit': 1e6}))
    assert any('did you mean' in e for e in TABLE.check_overrides({'temperature.limt': 100.0}))
    assert TABLE.check_overrides({'temperature.valid_min': 500.0, 'temperature.valid_max': 400.0})
    assert math.isclose(TABLE.by_name['min_valid_unix_time'].default, 1_704_067_200.0)
