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


def test_absorbed_model_is_the_day_reports():
    from sslfr_planner.analysis.optics import OpticalParameters
    from sslfr_planner.analysis.performance import day_energy
    from sslfr_recording.day import reference
    ref = reference(str(CONFIG), 36.84, -2.46, 0.0)
    t = T0 + np.arange(0.0, 7200.0, 600.0)
    tab = ref(t)
    power = absorbed_model(str(CONFIG))
    axes = [np.asarray(getattr(tab, a)) for a in ('mirrors', 'mobile_structure', 'secondary_reflector')]
    q = [power(800.0, z, a, m, b, s) for z, a, m, b, s in zip(tab.zenith, tab.azimuth, *axes)]
    assert 1000.0 < min(q) and max(q) < 800.0 * 3.0        # a few hundred W per m^2 of aperture
    params = OpticalParameters(geometry=ref.collector.geometry)
    for k in range(len(t) - 1):      # the report's trapezoid over two samples = the mean of our two powers
        wh = day_energy(t[k:k + 2], [800.0, 800.0], tab.zenith[k:k + 2], tab.azimuth[k:k + 2],
                        *(x[k:k + 2] for x in axes), params, ref.collector.azimuth)
        assert wh * 3600.0 / 600.0 == pytest.approx(0.5 * (q[k] + q[k + 1]), rel=1e-9)
    assert power(800.0, math.pi / 2 + 0.01, 3.0, 0.0, 0.0, 0.0) == 0.0        # sun down
    assert math.isnan(power(800.0, 0.5, 3.0, math.nan, 0.0, 0.0))             # an axis unknown
    off = power(800.0, tab.zenith[0], tab.azimuth[0], axes[0][0] + 0.5, axes[1][0], axes[2][0])
    assert off < 0.5 * q[0]                                                    # mirrors far off: little absorbed


def test_field_state_energy_today_absorbed_and_thermal():
    calls = []

    def model(beam, zenith, azimuth, m, b, s):
        calls.append((beam, zenith, azimuth, m, b, s))
        return beam * 2.0
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
    assert calls[-1] == (500.0, 0.4, 3.1, 0.1, 0.2, 0.3)
    c1, c2 = st.snapshot(3.0, T0 + 1802)['collectors']
    assert c1['energy_today'] == {'absorbed_kwh': 0.5, 'thermal_kwh': 0.3}
    assert c2['energy_today'] == {'absorbed_kwh': None, 'thermal_kwh': None}
    assert c1['thermal_power'] == 600.0 and c1['flow'] == 1e-4
    assert st.snapshot(3.0, T0 + DAY)['collectors'][0]['energy_today']['absorbed_kwh'] is None   # next day
