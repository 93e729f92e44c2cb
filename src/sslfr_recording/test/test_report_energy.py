"""The day report's absorbed-energy estimate (issue 10): ideal vs achieved angles."""
from datetime import datetime, timezone

import numpy as np
import pytest

from sslfr_recording.report_energy import energy_estimate

SITE = {'latitude': 36.8353, 'longitude': -2.4022, 'altitude': 22.0}
T0 = datetime(2024, 6, 21, 10, 0, tzinfo=timezone.utc).timestamp()


def _ideal(t):
    from sslfr_planner.tracking_table import evaluate
    from sslfr_planner.day_cycle import make_collector
    from sslfr_planner.planner_params import PLANNER_PARAMS
    from sslfr_planner.site import Site
    return evaluate(t, Site.from_degrees(36.8353, -2.4022, 22.0), make_collector(PLANNER_PARAMS.defaults()))


def test_measured_equal_to_ideal_achieves_everything():
    t = T0 + np.arange(0.0, 3600.0, 10.0)
    table = _ideal(t)
    measured = {a: (t, {'measured': np.asarray(getattr(table, a))})
                for a in ('mirrors', 'mobile_structure', 'secondary_reflector')}
    e = energy_estimate(SITE, t, np.full(t.size, 800.0), measured, None)
    assert e['ideal_kwh'] > 0.1  # ~1 h of 800 W/m2 on 3 m2 of mirrors at ~70 % yield
    assert e['achieved_kwh'] == pytest.approx(e['ideal_kwh'], rel=1e-9)


def test_a_mirror_error_costs_energy_and_stow_costs_all():
    t = T0 + np.arange(0.0, 3600.0, 10.0)
    table = _ideal(t)
    beam = np.full(t.size, 800.0)
    off = {'mirrors': (t, {'measured': np.asarray(table.mirrors) + np.radians(1.0)})}
    e = energy_estimate(SITE, t, beam, off, None)
    assert 0.0 < e['achieved_kwh'] < 0.9 * e['ideal_kwh']
    assert 'taken as ideal' in e['note']
    stowed = {'mirrors': (t, {'measured': np.full(t.size, np.pi / 2)})}
    assert energy_estimate(SITE, t, beam, stowed, None)['achieved_kwh'] == 0.0


def test_no_site_or_no_beam_says_why():
    t = T0 + np.arange(0.0, 60.0, 10.0)
    assert 'no site' in energy_estimate({}, t, np.full(t.size, 800.0), {}, None)['note']
    assert 'no valid beam' in energy_estimate(SITE, t, np.full(t.size, np.nan), {}, None)['note']
