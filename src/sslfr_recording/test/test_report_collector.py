"""The day report follows the run's collector description (issue 34): only its movements,
their ideal from its law, the absorbed energy on its optics, every line's error against
the exact eqs. 3-4 of seed 004 with its 0.085 / 0.12 deg budget. Synthetic recorded
days (a :class:`Day` built in memory) of the one-movement collectors of seeds 003 and 004."""
import math
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest

from sslfr_recording import report, report_render
from sslfr_recording.day import Day, Series, reference, run_description
from sslfr_recording.report_energy import energy_estimate

CONFIG = Path(__file__).resolve().parents[2] / 'sslfr_bringup' / 'config'
LEPTEN = str(CONFIG / 'florianopolis_lepten.yaml')
BUCARAMANGA = str(CONFIG / 'bucaramanga_single_axis.yaml')
ALMERIA = str(CONFIG / 'almeria_sslfr.yaml')
SITES = {LEPTEN: (-27.6013, -48.5184, 30.0), BUCARAMANGA: (7.1, -73.12, 930.0), ALMERIA: (36.8353, -2.4022, 22.0)}


def _status(t, measured, setpoint):
    n = t.size
    return Series(t, {'measured': np.asarray(measured, float), 'setpoint': np.asarray(setpoint, float),
                      'commanded': np.asarray(setpoint, float), 'error': np.asarray(measured) - setpoint,
                      'state': ['following'] * n, 'link_state': np.zeros(n, int), 'frames_lost': np.zeros(n, int),
                      'frames_bad': np.zeros(n, int), 'homed': np.ones(n, bool), 'fault_bits': np.zeros(n, int),
                      'steps': np.zeros(n, int)})


def synthetic_day(config, t0, t1, error_deg=0.0, step=10.0, beam=850.0, extra_axes=True):
    """A clear recorded day of the collector of ``config``: TRACKING all along, the
    mirrors drive at the reference's command + ``error_deg``; with ``extra_axes`` a
    mobile_structure and secondary_reflector status too (axes the collector lacks)."""
    lat, lon, alt = SITES[config]
    t = np.arange(t0, t1 + step / 2, step)
    ref = reference(config, lat, lon, alt)
    cmd = ref(t)
    axes = {a: Series() for a in ('mirrors', 'mobile_structure', 'secondary_reflector')}
    axes['mirrors'] = _status(t, cmd.mirrors + math.radians(error_deg), cmd.mirrors)
    if extra_axes:
        for a in ('mobile_structure', 'secondary_reflector'):
            axes[a] = _status(t, np.full(t.size, 0.3), np.zeros(t.size))   # 0.3 rad off: would show if listed
    n = t.size
    phase = Series(t[:1], {'phase': np.array([2]), 'name': ['TRACKING'], 'reason': [''], 'mode': ['auto'],
                           'site_source': ['gps'], 'latitude': np.array([lat]), 'longitude': np.array([lon]),
                           'altitude': np.array([alt]), 'day_type': np.array([0]), 'sunrise': np.array([t0 - 3600.0]),
                           'solar_noon': np.array([t0]), 'sunset': np.array([t1 + 3600.0])})
    empty = Series()
    return Day(bag='synthetic', start=float(t[0]), end=float(t[-1]), axes=axes, joints={}, phase=phase,
               safety=Series(t[:1], {'level': np.array([0]), 'reasons': [[]], 'stow_required': np.array([False]),
                                     'stopped_axes': [[]]}),
               inlet=empty, outlet=empty, beam=Series(t, {'g': np.full(n, beam), 'saturated': np.zeros(n, bool)}),
               fix=empty, trajectory=empty, trajectories=[], topics={},
               logs=Series(np.zeros(0), {'level': np.zeros(0), 'name': [], 'msg': []}))


def _utc(*a):
    return datetime(*a, tzinfo=timezone.utc).timestamp()


def test_lepten_report_lists_its_one_movement_and_every_line():
    t0 = _utc(2026, 6, 21, 13, 0)                       # 10:00 local, theta_T about -30 deg
    day = synthetic_day(LEPTEN, t0, t0 + 3600.0, error_deg=0.01)
    rep = report.analyse(day, LEPTEN)
    assert rep.collector == 'florianopolis_lepten' and rep.joints == ('mirrors',)
    assert list(rep.tracking) == ['mirrors'] and list(rep.accuracy) == ['mirrors'] and list(rep.links) == ['mirrors']
    vs_ideal = rep.tracking['mirrors']['ideal']
    assert vs_ideal.max == pytest.approx(math.radians(0.01), rel=1e-6)      # the law's drive is the ideal
    ln = rep.lines
    assert len(ln['lines']) == 10 and ln['samples'] == 361
    assert [r['line'] for r in ln['lines']] == list(range(1, 11))
    for r in ln['lines']:     # the drive's 0.01 deg on top of Table 1's linearisation (< 0.021 deg)
        assert r['law_max'] < math.radians(0.021)
        assert abs(r['held'].max - math.radians(0.01)) <= r['law_max'] + 1e-9
        assert r['within'] == 1.0
    text = report_render.render_text(rep)
    assert 'mobile_structure' not in text and 'secondary_reflector' not in text
    assert 'budget 0.085 deg for |theta_T| <= 45 deg, 0.12 deg up to 80 deg' in text
    assert ln['judged'] == ln['samples']                              # |theta_T| < 80 deg all along
    e = rep.energy
    assert e['ideal_kwh'] > 0 and math.isfinite(e['achieved_kwh'])
    # the exact angles aim every line's centre at the receiver's axis; a 0.45 m line's beam
    # is wider than the 0.15 m receiver, so 0.01 deg off may catch a few 1e-5 more
    assert 0.95 < e['achieved_kwh'] / e['ideal_kwh'] <= 1.0 + 1e-4
    assert e['law_kwh'] == pytest.approx(e['ideal_kwh'], rel=0.01)       # Table 1's law: within its budget


def test_lepten_drive_off_by_a_quarter_degree_is_beyond_the_budget_and_costs_energy():
    t0 = _utc(2026, 6, 21, 13, 0)
    good = report.analyse(synthetic_day(LEPTEN, t0, t0 + 1800.0), LEPTEN)
    bad = report.analyse(synthetic_day(LEPTEN, t0, t0 + 1800.0, error_deg=0.25), LEPTEN)
    assert all(r['within'] == 0.0 for r in bad.lines['lines'])
    assert all(r['within'] == 1.0 for r in good.lines['lines'])
    assert bad.energy['achieved_kwh'] < good.energy['achieved_kwh']
    assert bad.energy['ideal_kwh'] == pytest.approx(good.energy['ideal_kwh'], rel=1e-12)


def test_accuracy_alarm_quotes_the_collectors_own_loss_table():
    """The same 0.25 deg drive error: seed 004's wide receiver forgives it (its loss table
    at Florianopolis), seed 003's bench does not; the report quotes each one's own."""
    t0 = _utc(2026, 6, 21, 13, 0)
    texts = {}
    for config in (LEPTEN, BUCARAMANGA):
        rep = report.analyse(synthetic_day(config, t0, t0 + 1800.0, error_deg=0.25), config)
        a = rep.accuracy['mirrors']
        assert a['peak'] > a['warn'] and len(a['loss_table']) > 2
        texts[config] = next(ln for ln in report_render.render_text(rep).splitlines()
                             if ln.strip().startswith('mirrors') and 'judged; largest' in ln)
    assert 'estimated optical loss 0.0-0.0 %' in texts[LEPTEN], texts
    low = float(texts[BUCARAMANGA].split('estimated optical loss ')[1].split('-')[0])
    assert low > 1.0, texts


def test_bucaramanga_steps_ideal_and_energy():
    """Seed 003's 15-minute steps: the ideal of the mirrors is the stepped law (the
    drive holds the sun of each step's middle), the law costs a few % against every
    line exact, and the line errors show the steps (up to ~7.5 min of sun: ~0.9 deg)."""
    t0 = _utc(2026, 3, 21, 15, 0)                       # 10:00 local
    rep = report.analyse(synthetic_day(BUCARAMANGA, t0, t0 + 3600.0), BUCARAMANGA)
    assert rep.joints == ('mirrors',) and rep.tracking['mirrors']['ideal'].max == pytest.approx(0.0, abs=1e-12)
    ref = reference(BUCARAMANGA, *SITES[BUCARAMANGA])
    drive = ref(np.arange(t0, t0 + 3601, 10.0)).mirrors
    assert np.unique(np.round(drive, 12)).size == 5                    # 15-min holds over the hour
    e = rep.energy
    assert 0.85 < e['law_kwh'] / e['ideal_kwh'] < 1.0
    assert e['achieved_kwh'] == pytest.approx(e['law_kwh'], rel=1e-9)
    worst = max(r['held'].max for r in rep.lines['lines'])
    assert math.radians(0.5) < worst < math.radians(1.2)


def test_seed000_report_keeps_three_movements_and_no_line_table():
    t0 = _utc(2026, 6, 21, 10, 0)
    day = synthetic_day(ALMERIA, t0, t0 + 600.0, extra_axes=False)
    ref = reference(ALMERIA, *SITES[ALMERIA])
    tab = ref(day.axes['mirrors'].t)
    for a in ('mobile_structure', 'secondary_reflector'):
        day.axes[a] = _status(day.axes['mirrors'].t, getattr(tab, a), getattr(tab, a))
    rep = report.analyse(day, ALMERIA)
    assert rep.joints == ('mirrors', 'mobile_structure', 'secondary_reflector')
    assert list(rep.tracking) == list(rep.joints)
    assert 'horizontal rows' in rep.lines['note']
    e = rep.energy
    assert e['achieved_kwh'] == pytest.approx(e['ideal_kwh'], rel=1e-9) and e['ideal_kwh'] > 0


def test_without_a_description_the_recorded_axes_are_reported():
    t0 = _utc(2026, 6, 21, 10, 0)
    day = synthetic_day(ALMERIA, t0, t0 + 600.0, extra_axes=False)
    rep = report.analyse(day, None)
    assert rep.joints == ('mirrors',) and rep.collector == ''
    assert 'no collector description' in report_render.render_text(rep)


def test_run_description_and_energy_names_the_collector():
    assert run_description(LEPTEN).name == 'florianopolis_lepten'
    assert run_description(None) is None
    t = _utc(2026, 6, 21, 13, 0) + np.arange(0.0, 600.0, 10.0)
    e = energy_estimate({'latitude': -27.6013, 'longitude': -48.5184, 'altitude': 30.0}, t,
                        np.full(t.size, 800.0), {}, LEPTEN)
    assert 'florianopolis_lepten' in e['note'] and 'taken as ideal' in e['note']
    assert e['achieved_kwh'] == pytest.approx(e['law_kwh'], rel=1e-12)
