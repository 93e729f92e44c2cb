"""Unit tests of the planner's parameter table and day cycle (no rclpy)."""
from __future__ import annotations

import datetime as dt
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from sslfr_common.contract import Phase
from sslfr_planner.tracking_table import evaluate
from sslfr_planner.day_cycle import STEP_RATE, DayCycle
from sslfr_planner.planner_params import PLANNER_PARAMS
from sslfr_planner.site_source import SiteFix
from sslfr_planner.trajectory import horizon_times

NIGHT, PRE_DAWN, TRACKING, STOWING = Phase.NIGHT, Phase.PRE_DAWN, Phase.TRACKING, Phase.STOWING

CONFIG = Path(__file__).resolve().parents[2] / 'sslfr_bringup' / 'config'


def _utc(*a) -> float:
    return dt.datetime(*a, tzinfo=dt.timezone.utc).timestamp()


def _cfg_from(name: str) -> dict:
    data = yaml.safe_load((CONFIG / name).read_text())
    cfg = PLANNER_PARAMS.defaults()
    for section in ('/**', 'planner'):
        cfg.update(data[section]['ros__parameters'])
    return PLANNER_PARAMS.coerce(cfg)


def _cycle(cfg: dict) -> DayCycle:
    return DayCycle(cfg, SiteFix(cfg['site.latitude_deg'], cfg['site.longitude_deg'],
                                   cfg['site.elevation'], 'parameters'))


# ---------------------------------------------------------------------- parameters
def test_defaults_are_valid_and_every_spec_documents_its_unit():
    assert PLANNER_PARAMS.validate(PLANNER_PARAMS.defaults()) == []
    for s in PLANNER_PARAMS:
        assert s.description and s.unit
        if isinstance(s.default, (int, float)) and not isinstance(s.default, bool):
            assert s.lo is not None and s.hi is not None and s.lo <= s.default <= s.hi, s.name


@pytest.mark.parametrize('spec', [s for s in PLANNER_PARAMS if s.lo is not None], ids=lambda s: s.name)
def test_out_of_range_and_nan_refused(spec):
    cfg = PLANNER_PARAMS.defaults()
    bad = spec.hi + abs(spec.hi) + 1
    cfg[spec.name] = [bad] * (spec.length or 1) if isinstance(spec.default, list) else \
        (int(bad) if isinstance(spec.default, int) else bad)
    errs = PLANNER_PARAMS.validate(cfg)
    assert errs and spec.name in errs[0]
    if isinstance(spec.default, float):
        assert spec.check(math.nan) and spec.check(math.inf)


def test_type_choice_and_cross_rules():
    assert 'expected a bool' in PLANNER_PARAMS.by_name['site.delta_t_model'].check(1)
    assert 'not one of' in PLANNER_PARAMS.by_name['collector.law'].check('wobble')
    assert 'expected an integer' in PLANNER_PARAMS.by_name['collector.n_per_side'].check(2.5)
    assert '3 values' in PLANNER_PARAMS.by_name['stow.speeds'].check([0.1, 0.1])
    cfg = PLANNER_PARAMS.defaults()
    cfg['step'], cfg['horizon'] = 10.0, 5.0
    assert any('horizon' in e for e in PLANNER_PARAMS.validate(cfg))
    cfg = PLANNER_PARAMS.defaults()
    cfg['collector.tracking_start'] = 3600.0
    assert any('both' in e for e in PLANNER_PARAMS.validate(cfg))
    cfg['collector.tracking_end'] = 1800.0
    assert any('before' in e for e in PLANNER_PARAMS.validate(cfg))
    cfg = PLANNER_PARAMS.defaults()
    del cfg['horizon']
    assert PLANNER_PARAMS.validate(cfg) == ['horizon: missing']


@pytest.mark.parametrize('name', ['almeria_sslfr.yaml', 'bucaramanga_single_axis.yaml',
                                  'florianopolis_lepten.yaml', 'site_template.yaml'])
def test_seed_configs_are_valid_and_use_only_declared_keys(name):
    data = yaml.safe_load((CONFIG / name).read_text())
    keys = set(data['/**']['ros__parameters']) | set(data['planner']['ros__parameters'])
    assert keys <= set(PLANNER_PARAMS.by_name), keys - set(PLANNER_PARAMS.by_name)
    assert PLANNER_PARAMS.validate(_cfg_from(name)) == []
    DayCycle.check_config(_cfg_from(name))


def test_site_template_documents_every_parameter():
    data = yaml.safe_load((CONFIG / 'site_template.yaml').read_text())
    keys = set(data['/**']['ros__parameters']) | set(data['planner']['ros__parameters'])
    assert keys == set(PLANNER_PARAMS.by_name)


def test_seed_numbers_in_configs():
    a = _cfg_from('almeria_sslfr.yaml')
    assert a['site.latitude_deg'] == pytest.approx(36 + 50 / 60 + 7 / 3600, abs=1e-6)
    assert a['site.longitude_deg'] == pytest.approx(-(2 + 24 / 60 + 8 / 3600), abs=1e-6)
    assert 2 * a['collector.n_per_side'] + 1 == 25 and a['collector.mirror_width'] == 0.06
    b = _cfg_from('bucaramanga_single_axis.yaml')
    assert b['collector.mirror_width'] + b['collector.gap'] == pytest.approx(0.15)
    assert 2 * b['collector.n_per_side'] == 10 and not b['collector.central_mirror']
    assert (b['collector.tracking_start'], b['collector.tracking_end']) == (7 * 3600.0, 17 * 3600.0)
    f = _cfg_from('florianopolis_lepten.yaml')
    assert math.degrees(f['collector.azimuth']) == pytest.approx(4.6, abs=1e-5)
    # seed 004: Z_abs = 3.75 m is the aim point (f + D/2); the lines 0.45 m wide
    assert f['collector.receiver_height'] + f['collector.tube_diameter'] / 2 == pytest.approx(3.75, abs=1e-4)
    assert f['collector.mirror_width'] == 0.45
    assert b['collector.receiver_height'] + b['collector.tube_diameter'] / 2 == pytest.approx(0.75, abs=1e-4)


# ------------------------------------------------------------------- day schedules
def test_day_table_is_the_core_table_and_covers_the_local_day():
    cfg = _cfg_from('almeria_sslfr.yaml')
    p = _cycle(cfg)
    now = _utc(2026, 6, 21, 10, 0, 0) + 0.5
    plan = p.plan(now)
    assert plan.start <= now < plan.start + 86400 and plan.table.t.size == 86401
    assert plan.start == pytest.approx(_utc(2026, 6, 21) - cfg['site.longitude_deg'] * 240)
    sample = plan.table.t[::997]
    ref = evaluate(sample, p.site, p.collector)
    assert np.array_equal(plan.table.mirrors[::997], ref.mirrors)
    assert np.array_equal(plan.table.phase[::997], ref.phase)
    ph = plan.table.phase
    seq = [int(ph[0])] + [int(x) for i, x in enumerate(ph[1:]) if x != ph[i]]
    assert seq == [NIGHT, PRE_DAWN, TRACKING, STOWING, NIGHT]
    assert plan.events.day_type == 'normal' and plan.events.sunrise < plan.events.solar_noon
    assert '2026-06-21 normal: sunrise 04:5' in plan.describe()


def test_horizon_positions_and_rates():
    p = _cycle(_cfg_from('almeria_sslfr.yaml'))
    now = _utc(2026, 6, 21, 10, 0, 0) + 0.3
    p.plan(now)
    t = horizon_times(now, 120.0, 1.0)
    h = p.auto_horizon(t)
    ref = evaluate(t, p.site, p.collector)
    assert np.array_equal(h.positions[:, 0], ref.mirrors)
    # rates: central differences of the same law, compared with a fine derivative
    fine = evaluate(np.concatenate([t - 0.25, t + 0.25]), p.site, p.collector)
    d = (fine.mirrors[t.size:] - fine.mirrors[:t.size]) / 0.5
    assert np.allclose(h.velocities[:, 0], d, rtol=1e-3, atol=0)      # ~3e-5 rad/s
    assert np.all(np.abs(h.velocities) < STEP_RATE)
    # non-integer instants are evaluated by the core: identical numbers
    t2 = horizon_times(now, 30.0, 0.5)
    h2 = p.auto_horizon(t2)
    assert np.array_equal(h2.positions[:, 0], evaluate(t2, p.site, p.collector).mirrors)


def test_horizon_across_local_midnight_and_pre_dawn_step():
    p = _cycle(_cfg_from('almeria_sslfr.yaml'))
    plan = p.plan(_utc(2026, 6, 21, 12))
    t = horizon_times(plan.start + 86400 - 60.5, 120.0, 1.0)
    h = p.auto_horizon(t)
    ref = evaluate(t, p.site, p.collector)
    assert np.array_equal(h.positions[:, 1], ref.mobile_structure)
    # PRE_DAWN begins with a step from sleeping to the initial position: rate 0 there
    start = plan.events.sunrise - p.collector.pre_dawn_lead
    t = horizon_times(start - 30.2, 60.0, 1.0)
    h = p.auto_horizon(t)
    jump = np.nonzero(np.abs(np.diff(h.positions[:, 0])) > 0.1)[0]
    assert jump.size == 1
    k = jump[0]
    assert h.velocities[k, 0] == 0.0 and h.velocities[k + 1, 0] == 0.0
    assert h.positions[k, 0] == pytest.approx(math.pi / 2)


def test_bucaramanga_window_and_15_minute_steps():
    cfg = _cfg_from('bucaramanga_single_axis.yaml')
    p = _cycle(cfg)
    plan = p.plan(_utc(2026, 3, 20, 17))
    tab = plan.table
    ws, we = _utc(2026, 3, 20, 12), _utc(2026, 3, 20, 22)      # 7:00 and 17:00 UTC-5
    assert plan.window == (ws, we)
    tr = tab.phase == TRACKING
    assert tab.t[tr][0] == ws and tab.t[tr][-1] == we - 1
    pre = tab.phase == PRE_DAWN
    assert tab.t[pre][0] == ws - 600 and tab.t[pre][-1] == ws - 1
    assert np.all(tab.mirrors[pre] == tab.mirrors[tr][0])             # initial position
    sto = tab.phase == STOWING
    assert tab.t[sto][0] == we and np.all(tab.mirrors[sto] == math.pi / 2)
    assert np.all(tab.mobile_structure == 0.0) and np.all(tab.secondary_reflector == 0.0)
    # 15-minute steps: the mirrors change only on multiples of 900 s
    m = tab.mirrors[tr]
    changes = tab.t[tr][1:][np.diff(m) != 0]
    assert changes.size == 39 and np.all(changes % 900 == 0)
    # the sun is already up before 7:00 but the mirrors still sleep
    assert plan.events.sunrise < ws - 600
    night_up = (tab.t > plan.events.sunrise) & (tab.t < ws - 600)
    assert np.all(tab.phase[night_up] == NIGHT) and np.all(tab.mirrors[night_up] == math.pi / 2)


@pytest.mark.parametrize('date,day_type,phase', [((2026, 12, 21), 'polar_night', NIGHT),
                                                  ((2026, 6, 21), 'polar_day', TRACKING)])
def test_polar_days(date, day_type, phase):
    cfg = PLANNER_PARAMS.defaults()
    cfg.update({'site.latitude_deg': 78.22, 'site.longitude_deg': 15.65})
    p = _cycle(cfg)
    plan = p.plan(_utc(*date, 11))
    assert plan.events.day_type == day_type and plan.events.sunrise is None
    assert np.all(plan.table.phase == phase)
    zen, az, tt, tl, above, algo = p.sun(_utc(*date, 11))
    assert above == (phase == TRACKING) and algo == 'spa' and 0 <= az < 2 * math.pi


def test_sleep_pose_and_day_index():
    p = _cycle(PLANNER_PARAMS.defaults())
    pose = p.sleep_pose(_utc(2026, 1, 1))
    assert pose.tolist() == [math.pi / 2, 0.0, 0.0]
    for t in np.linspace(_utc(2026, 1, 1), _utc(2026, 1, 3), 37):
        d = p.day_index(t)
        assert p.day_start(d) <= t < p.day_start(d) + 86400
    with pytest.raises(ValueError):
        DayCycle.check_config({**PLANNER_PARAMS.defaults(), 'collector.law': 'wobble'})
