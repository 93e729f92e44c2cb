"""The field page's energy of the day (sslfr_field.energy) on numbers: the day's
trapezoids, gaps, unknown samples and midnight; the absorbed-power model against the
day report's (sslfr_planner.analysis.performance.day_energy) on the same samples."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sslfr_field.energy import DAY, DayIntegral, absorbed_model
from sslfr_field.live import FieldState

CONFIG = Path(__file__).resolve().parents[2] / 'sslfr_bringup' / 'config' / 'almeria_sslfr.yaml'
T0 = 1781092800.0          # 2026-06-10 12:00 UTC [s]


def test_day_integral_trapezoids_gaps_unknowns_and_midnight():
    d = DayIntegral(max_gap=10.0)
    assert d.kwh() is None
    for k in range(0, 3601):                    # 1000 W for one hour at 1 Hz: 1 kWh
        d.add(T0 + k, 1000.0)
    assert d.kwh() == pytest.approx(1.0)
    d.add(T0 + 3600 + 60, 1000.0)              # a 60 s gap (station did not hear): nothing across it
    assert d.kwh() == pytest.approx(1.0)
    d.add(T0 + 3600 + 61, 1000.0)
    assert d.kwh() == pytest.approx(1.0 + 1000.0 / 3.6e6)
    d.add(T0 + 3600 + 62, math.nan)            # unknown ends the trapezoid ...
    d.add(T0 + 3600 + 63, 1000.0)              # ... so the next one starts afresh
    assert d.kwh() == pytest.approx(1.0 + 1000.0 / 3.6e6)
    d.add(T0 + 10, 5000.0)                      # older than the last sample: ignored
    d.add(0.0, 5000.0)                          # no ROS time yet: ignored
    assert d.kwh() == pytest.approx(1.0 + 1000.0 / 3.6e6)
    midnight = (T0 // DAY + 1) * DAY
    assert d.kwh(now=midnight + 1) is None      # asked on the next day: today's is unknown
    d.add(midnight + 1, 200.0)                  # a new day starts from zero
    d.add(midnight + 2, 200.0)
    assert d.kwh() == pytest.approx(200.0 / 3.6e6)


@pytest.mark.parametrize('config', ['almeria_sslfr.yaml', 'bucaramanga_single_axis.yaml', 'florianopolis_lepten.yaml'])
def test_absorbed_energy_is_the_day_reports_achieved_energy(config):
    """The page's integral of the model over the samples = the day report's achieved
    energy (sslfr_recording.report_energy) on the same beam, sun and measured axes."""
    from sslfr_recording.day import reference
    from sslfr_recording.report_energy import energy_estimate
    path = CONFIG.parent / config
    if not path.exists():
        pytest.skip(f'{config} not shipped')
    site = {'latitude': 36.84, 'longitude': -2.46, 'altitude': 0.0}
    ref = reference(str(path), site['latitude'], site['longitude'], site['altitude'])
    model = absorbed_model(str(path))
    assert set(model.joints) == set(ref.joints)
    t = T0 + np.arange(0.0, 1800.0, 5.0)
    tab = ref(t)
    beam = 750.0 + 50.0 * np.sin(t / 300.0)
    measured = {a: np.asarray(getattr(tab, a), dtype=float) + 0.002 for a in model.joints}   # a small error
    report = energy_estimate(site, t, beam, {a: (t, {'measured': m}) for a, m in measured.items()}, str(path))
    day = DayIntegral(max_gap=10.0)
    for k in range(t.size):
        day.add(t[k], model(beam[k], tab.zenith[k], tab.azimuth[k], {a: measured[a][k] for a in model.joints}))
    assert report['achieved_kwh'] > 0.0
    assert day.kwh() == pytest.approx(report['achieved_kwh'], rel=1e-9)


def test_absorbed_model_unknowns_and_the_sun_down():
    model = absorbed_model(str(CONFIG))
    angles = {a: 0.0 for a in model.joints}
    assert model(800.0, math.pi / 2 + 0.01, 3.0, angles) == 0.0                 # sun down
    assert math.isnan(model(800.0, 0.5, 3.0, {**angles, 'mirrors': math.nan}))   # an axis unknown
    assert math.isnan(model(800.0, 0.5, 3.0, {}))                               # no axis heard


def test_field_state_energy_today_absorbed_and_thermal():
    calls = []

    def model(beam, zenith, azimuth, angles):
        calls.append((beam, zenith, azimuth, angles))
        return beam * 2.0
    model.joints = ('mirrors', 'mobile_structure', 'secondary_reflector')
    st = FieldState([('c1', '/c1', ''), ('c2', '/c2', '')], models={'c1': model})
    st.on_beam('c1', 1.0, 500.0, T0)                       # no sun, no axes yet: unknown
    assert st.snapshot(1.0, T0)['collectors'][0]['energy_today'] == {'absorbed_kwh': 0.0, 'thermal_kwh': None}
    st.on_sun('c1', 1.0, 0.4, 3.1)
    for a, x in (('mirrors', 0.1), ('mobile_structure', 0.2), ('secondary_reflector', 0.3)):
        st.on_axis('c1', 1.0, a, 'following', 0.0, x)
    for k in range(1801):                                   # 1000 W for half an hour
        st.on_beam('c1', 2.0, 500.0, T0 + 1 + k)
        st.on_thermal('c1', 2.0, 1e-4, 600.0, T0 + 1 + k)
        st.on_beam('c2', 2.0, 500.0, T0 + 1 + k)            # no model: no absorbed energy
    assert calls[-1] == (500.0, 0.4, 3.1, {'mirrors': 0.1, 'mobile_structure': 0.2, 'secondary_reflector': 0.3})
    c1, c2 = st.snapshot(3.0, T0 + 1802)['collectors']
    assert c1['energy_today'] == {'absorbed_kwh': 0.5, 'thermal_kwh': 0.3}
    assert c2['energy_today'] == {'absorbed_kwh': None, 'thermal_kwh': None}
    assert c1['thermal_power'] == 600.0 and c1['flow'] == 1e-4
    assert st.snapshot(3.0, T0 + DAY)['collectors'][0]['energy_today']['absorbed_kwh'] is None   # next day
