"""Day tables: phases, axis commands, longitudinal laws, seed 001 tilts, properties."""
import datetime as dt
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from sslfr_common.contract import Phase
from sslfr_planner import laws, raytrace
from sslfr_planner.collector import Collector, FieldGeometry
from sslfr_planner.tracking_table import evaluate, tabulate_day
from sslfr_planner.events import sun_events
from sslfr_planner.site import Site

NIGHT, PRE_DAWN, TRACKING, STOWING = Phase.NIGHT, Phase.PRE_DAWN, Phase.TRACKING, Phase.STOWING

ALMERIA = Site.from_degrees(36.8353, -2.4022, 22.0)


def _dms(d, m, s):
    return d + m / 60 + s / 3600


# seed 001 Table 3: the five cities
CITIES = {
    'Almeria': (_dms(36, 50, 7), -_dms(2, 24, 8), 22.0),
    'Rome': (_dms(41, 53, 30), _dms(12, 30, 40), 52.0),
    'Budapest': (_dms(47, 29, 52), _dms(19, 2, 23), 111.0),
    'Berlin': (_dms(52, 31, 27), _dms(13, 24, 37), 37.0),
    'Helsinki': (_dms(60, 10, 10), _dms(24, 56, 7), 26.0),
}


@pytest.fixture(scope='module')
def june():
    return tabulate_day(dt.date(2026, 6, 21), ALMERIA, Collector(), 10.0)


def test_day_cycle_order_and_events(june):
    ev = june.events
    p = june.phase
    changes = [int(p[0])] + [int(x) for i, x in enumerate(p[1:]) if x != p[i]]
    assert changes == [NIGHT, PRE_DAWN, TRACKING, STOWING, NIGHT]
    tr = june.t[p == TRACKING]
    assert abs(tr[0] - ev.sunrise) <= 10 and abs(tr[-1] - ev.sunset) <= 10
    pd_ = june.t[p == PRE_DAWN]
    assert pd_[-1] < ev.sunrise and ev.sunrise - pd_[0] <= 600
    st_ = june.t[p == STOWING]
    assert st_[0] >= ev.sunset and st_[-1] - ev.sunset < 600


def test_axis_commands_per_phase(june):
    c = Collector()
    p = june.phase
    night = (p == NIGHT) | (p == STOWING)
    assert np.all(june.mirrors[night] == c.sleeping)
    assert np.all(june.mobile_structure[night] == 0.0) and np.all(june.secondary_reflector[night] == 0.0)
    tr = p == TRACKING
    # mirrors: seed 000 eq. 13 in the tilted rows' frame (theta_t / 2 when the rows are horizontal)
    sun = raytrace.sun_vector(june.zenith[tr], june.azimuth[tr])
    tilted = raytrace.transversal_angle(sun, june.mobile_structure[tr])
    np.testing.assert_allclose(june.mirrors[tr], np.clip(tilted / 2, -math.pi / 4, math.pi / 2))
    flat = np.abs(june.mobile_structure[tr]) < 1e-9
    np.testing.assert_allclose(june.mirrors[tr][flat], june.transversal[tr][flat] / 2)
    np.testing.assert_allclose(june.mobile_structure[tr], june.secondary_reflector[tr])
    # the continuous law: theta_z/2 toward the sun at noon, through 0 when the sun crosses the
    # east-west vertical plane (summer mornings and evenings: rows face north)
    noon = int(np.argmin(june.zenith))
    assert 0.0 < june.mobile_structure[noon] - june.zenith[noon] / 2 < math.radians(0.5)
    assert june.mobile_structure[tr][0] < 0 and june.mobile_structure[tr][-1] < 0
    # PRE_DAWN holds the commands of the sunrise instant
    at_rise = evaluate(np.array([june.events.sunrise + 0.01]), ALMERIA, c)
    pdw = p == PRE_DAWN
    np.testing.assert_allclose(june.mirrors[pdw], at_rise.mirrors[0], atol=1e-6)
    np.testing.assert_allclose(june.mobile_structure[pdw], at_rise.mobile_structure[0], atol=1e-6)
    # horizontal rows: sunrise at beta_0 = -45 deg, sunset at +45 deg (seed 000 section 4)
    flat = tabulate_day(dt.date(2026, 6, 21), ALMERIA, Collector(law='horizontal'), 10.0)
    assert math.isclose(flat.mirrors[flat.phase == PRE_DAWN][0], -math.pi / 4, abs_tol=1e-3)
    assert abs(flat.mirrors[flat.phase == TRACKING][-1] - math.pi / 4) < math.radians(0.5)


def test_noon_signs_northern_and_southern_hemisphere():
    for lat, sign in ((36.8, 1.0), (-27.6, -1.0)):
        site = Site.from_degrees(lat, 0.0)
        ev = sun_events(dt.date(2026, 3, 20), site)
        instants = np.array([ev.solar_noon - 7200, ev.solar_noon, ev.solar_noon + 7200])
        tab = evaluate(instants, site, Collector())
        assert tab.transversal[0] < 0 < tab.transversal[2]          # morning -, afternoon +
        assert abs(tab.transversal[1]) < 1e-4
        assert np.sign(tab.mobile_structure[1]) == sign             # rows face the sun
        assert 0 < abs(tab.mobile_structure[1]) - tab.zenith[1] / 2 < math.radians(1.0)
        tab = evaluate(instants, site, Collector(law='eq16'))
        assert np.all(np.sign(tab.mobile_structure) == sign)        # eq. 16: rows face the equator
        assert math.isclose(abs(tab.mobile_structure[1]), tab.zenith[1] / 2, rel_tol=1e-12)


@pytest.mark.parametrize('city', list(CITIES))
def test_seed001_optimum_fixed_tilts(city):
    lat, lon, elev = CITIES[city]
    site = Site.from_degrees(lat, lon, elev)
    tab = tabulate_day(dt.date(2026, 3, 20), site, Collector(law='optimum_fixed'), 600.0)
    assert np.allclose(tab.mobile_structure, math.radians(lat) / 2, atol=1e-15)   # beta_M = lat/2
    assert np.allclose(tab.secondary_reflector, math.radians(lat), atol=1e-15)    # beta_a = lat
    assert np.all(tab.phase[tab.mirrors != Collector().sleeping] != NIGHT)


def test_horizontal_and_daily_laws():
    tab = tabulate_day(dt.date(2026, 6, 21), ALMERIA, Collector(law='horizontal'), 900.0)
    assert np.all(tab.mobile_structure == 0) and np.all(tab.secondary_reflector == 0)
    ev = sun_events(dt.date(2026, 6, 21), ALMERIA)
    tab = tabulate_day(dt.date(2026, 6, 21), ALMERIA, Collector(law='daily'), 900.0)
    # once a day: the value changes at local mean midnight (00:09:36 UTC at 2.4 W)
    local_day = np.floor((tab.t + math.degrees(ALMERIA.longitude) * 240.0) / 86400.0)
    assert np.ptp(tab.mobile_structure[local_day == local_day[-1]]) == 0.0
    assert len(np.unique(tab.mobile_structure)) == 2
    noon = evaluate(np.array([ev.solar_noon]), ALMERIA, Collector(law='eq16'))
    # (latitude - declination)/2 = seed 000 eq. 16 at solar noon (refraction ~ 1e-4 rad apart)
    assert abs(tab.mobile_structure[0] - noon.mobile_structure[0]) < 2e-4
    assert math.isclose(tab.mobile_structure[0], (math.radians(36.8353) - math.radians(23.44)) / 2, abs_tol=1e-3)


@pytest.mark.parametrize('law', ['eq16', 'optimum_fixed'])
def test_a_receiver_the_collector_does_not_move_stays_horizontal(tmp_path, law):
    """Seed 000 without its secondary_reflector movement: the rows follow the law's beta_M,
    the receiver's column is the fixed tilt (0), under any law; with both, beta_a is the law's."""
    import yaml
    from sslfr_planner import description
    from sslfr_planner.day_cycle import make_collector
    from sslfr_planner.planner_params import PLANNER_PARAMS
    seed = yaml.safe_load((description.Path(__file__).resolve().parents[2] / 'sslfr_bringup' / 'config'
                           / 'collectors' / 'almeria_three_movement.yaml').read_text())
    seed['movements']['mobile_structure']['law'] = seed['movements']['secondary_reflector']['law'] = law
    both = description.parse(seed, 'both')
    seed['movements'].pop('secondary_reflector')
    seed['boards'] = [b for b in seed['boards'] if b['name'] != 'secondary_reflector']
    seed['sensors'] = [x for x in seed['sensors'] if x['board'] != 'secondary_reflector']
    rows = description.parse(seed, 'rows')
    t = sun_events(dt.date(2026, 6, 21), ALMERIA).solar_noon + np.array([-7200.0, 0.0, 3600.0])
    tabs = [evaluate(t, ALMERIA, make_collector(PLANNER_PARAMS.defaults(), desc)) for desc in (both, rows)]
    np.testing.assert_array_equal(tabs[0].mobile_structure, tabs[1].mobile_structure)
    assert np.all(np.abs(tabs[0].secondary_reflector) > 0.1) and np.all(tabs[1].secondary_reflector == 0.0)
    np.testing.assert_array_equal(tabs[0].mirrors, tabs[1].mirrors)   # beta_0 = theta_t'/2 whatever beta_a


def test_law_signs():
    bm, ba = laws.eq16(np.array([1.0, 0.5]), 0.6)
    np.testing.assert_array_equal(bm, [0.5, 0.25])
    np.testing.assert_array_equal(laws.eq16(np.array([1.0]), -0.6)[0], [-0.5])      # southern site
    np.testing.assert_array_equal(laws.eq16(np.array([1.0]), 0.6, math.pi)[0], [-0.5])  # +p end north
    g = FieldGeometry()
    # the sun toward +p (south) -> rows face south; toward -p -> north; in the east-west plane -> flat
    suns = raytrace.sun_vector(np.radians([40.0, 40.0, 40.0]), np.radians([180.0, 0.0, 90.0]))
    bm, ba = laws.continuous(suns, g)
    assert bm[0] > 0 and bm[1] < 0 and abs(bm[2]) < 1e-12
    np.testing.assert_allclose(bm[0], -bm[1], rtol=1e-12)
    np.testing.assert_array_equal(bm, ba)
    assert laws.optimum_fixed(-0.5) == (-0.25, -0.5)
    assert laws.optimum_fixed(0.5, math.pi) == (-0.25, -0.5)


def test_polar_day_tracks_all_day_and_polar_night_sleeps():
    tromso = Site.from_degrees(69.65, 18.96)
    summer = tabulate_day(dt.date(2026, 6, 21), tromso, Collector(), 300.0)
    winter = tabulate_day(dt.date(2026, 12, 21), tromso, Collector(), 300.0)
    assert np.all(summer.phase == TRACKING) and summer.events.day_type == 'polar_day'
    assert np.all(winter.phase == NIGHT) and winter.events.day_type == 'polar_night'
    assert np.all(winter.mirrors == math.pi / 2)


def test_tracking_step_holds_the_mid_interval_position():
    c = Collector(tracking_step=900.0)
    tab = tabulate_day(dt.date(2026, 3, 20), Site.from_degrees(7.1254, -73.1198), c, 60.0)  # Bucaramanga
    tr = tab.phase == TRACKING
    k = np.floor(tab.t[tr] / 900.0)
    for kk in np.unique(k)[2:-2]:
        vals = tab.mirrors[tr][k == kk]
        assert np.ptp(vals) == 0.0
        mid = evaluate(np.array([kk * 900.0 + 450.0]), Site.from_degrees(7.1254, -73.1198), Collector())
        assert math.isclose(vals[0], mid.mirrors[0], abs_tol=1e-9)


def test_evaluate_matches_plan_day_at_any_instant(june):
    idx = np.array([0, 1700, 1750, 3000, 5000, 7000, 8639])
    one = evaluate(june.t[idx], ALMERIA, Collector())
    for name in ('phase', 'mirrors', 'mobile_structure', 'secondary_reflector', 'zenith', 'transversal'):
        np.testing.assert_allclose(getattr(one, name), getattr(june, name)[idx], atol=1e-12)


def test_evaluate_sparse_instants_over_years():
    t = np.array([0.0, 1e9, 2e9, 3e9])
    tab = evaluate(t, ALMERIA, Collector())
    assert tab.phase.shape == (4,) and np.all(np.isfinite(tab.mirrors))
    for i in range(4):
        one = evaluate(t[i:i + 1], ALMERIA, Collector())
        assert one.phase[0] == tab.phase[i] and math.isclose(one.mirrors[0], tab.mirrors[i], abs_tol=1e-12)


def test_bad_inputs_rejected():
    with pytest.raises(ValueError):
        Site.from_degrees(91.0, 0.0)
    with pytest.raises(ValueError):
        Collector(law='sideways')
    with pytest.raises(ValueError):
        Collector(gear_ratio=(1.0, 0.0, 1.0))
    with pytest.raises(ValueError):
        evaluate(np.array([np.nan]), ALMERIA, Collector())
    with pytest.raises(ValueError):
        tabulate_day(dt.date(2026, 1, 1), ALMERIA, Collector(), 0.0)


T0 = dt.datetime(1950, 1, 1, tzinfo=dt.timezone.utc).timestamp()
T1 = dt.datetime(2100, 12, 31, tzinfo=dt.timezone.utc).timestamp()


@settings(max_examples=40, deadline=None)
@given(lat=st.floats(-89.5, 89.5), lon=st.floats(-180, 180), t=st.floats(T0, T1),
       law=st.sampled_from(['continuous', 'eq16', 'optimum_fixed', 'horizontal', 'daily']),
       gc=st.floats(-math.pi, math.pi))
def test_property_no_nan_and_inside_mechanical_ranges(lat, lon, t, law, gc):
    c = Collector(law=law, azimuth=gc)
    tab = evaluate(t + np.arange(0.0, 7200.0, 97.0), Site.from_degrees(lat, lon), c)
    for name in ('zenith', 'azimuth', 'transversal', 'longitudinal', 'mirrors', 'mobile_structure',
                 'secondary_reflector'):
        assert np.all(np.isfinite(getattr(tab, name))), name
    assert np.all((tab.mirrors >= c.mirror_min) & (tab.mirrors <= c.mirror_max))
    assert np.all(np.abs(tab.mobile_structure) <= c.tilt_max)
    assert np.all(np.abs(tab.secondary_reflector) <= c.tilt_max)
    assert np.all((tab.azimuth >= 0) & (tab.azimuth < 2 * math.pi))
    assert set(np.unique(tab.phase)) <= {NIGHT, PRE_DAWN, TRACKING, STOWING}


@settings(max_examples=40, deadline=None)
@given(lat=st.floats(-60, 60), lon=st.floats(-180, 180), doy=st.integers(0, 365 * 150),
       tau=st.floats(600.0, 4 * 3600.0))
def test_property_transversal_antisymmetric_about_noon(lat, lon, doy, tau):
    """theta_t(noon + tau) = -theta_t(noon - tau), to the drift of the sun over the day.

    The sun's declination changes by up to 0.4 deg/day (0.13 deg between noon - 4 h and
    noon + 4 h) and the equation of time by up to 30 s/day; at |latitude| <= 60 deg that
    moves the two positions apart by < 0.2 deg (0.100003 deg found at 56 S at an equinox).
    """
    site = Site.from_degrees(lat, lon)
    ev = sun_events(dt.date(1950, 1, 1) + dt.timedelta(days=doy), site)
    tab = evaluate(np.array([ev.solar_noon - tau, ev.solar_noon + tau]), site, Collector())
    if np.all(tab.zenith < math.radians(85.0)):
        assert abs(tab.transversal[0] + tab.transversal[1]) < math.radians(0.2)


def test_evaluate_is_bit_identical_across_batches():
    """The planner node relies on it: an instant gets the same numbers in any batch."""
    t = dt.datetime(2026, 6, 21, 9, 59, 0, tzinfo=dt.timezone.utc).timestamp() + 0.3 + np.arange(121.0)
    a = evaluate(t, ALMERIA, Collector())
    b = evaluate(np.concatenate([[t[0] - 1.0], t, [t[-1] + 1.0]]), ALMERIA, Collector())
    for name in ('zenith', 'azimuth', 'transversal', 'longitudinal', 'mirrors', 'mobile_structure'):
        assert np.array_equal(getattr(a, name), getattr(b, name)[1:-1]), name
