"""Performance analysis against the seeds (seed 000 section 5, seed 001) on the 3-D trace.
Sun positions: the project's SPA; beam irradiance: the clear-sky model (stated)."""
from __future__ import annotations

from datetime import date

import numpy as np
import pytest

from sslfr_planner.analysis import optics, performance
from sslfr_planner.analysis.cli import SEED_COSTS, SEED_TUBES
from sslfr_planner.analysis.optics import OpticalParameters
from sslfr_planner.analysis.performance import AnalysisSite, Costs, YearSky
from sslfr_planner.collector import FieldGeometry

P = OpticalParameters()
ALMERIA = AnalysisSite(36 + 50 / 60 + 7 / 3600, -(2 + 24 / 60 + 8 / 3600), 22.0)
DAYS = [date(2024, 3, 21), date(2024, 6, 21), date(2024, 9, 21), date(2024, 12, 21)]
HOURS = [9.0, 12.0, 15.0]


def test_labels_positions_and_yield_seed000_eqs_14_15_19():
    g = P.geometry
    x = g.mirror_positions()
    assert x.size == 25 and x[12] == 0.0 and x[-1] == pytest.approx(12 * (0.06 + 0.024))
    assert np.abs(g.receiver_angles())[-1] == pytest.approx(np.arctan(12 * 0.084 / (1.5 + 0.0486 / 2)))
    assert g.mirror_labels()[0] == '12L' and g.mirror_labels()[12] == 'C'
    eta = optics.optical_yield(P)
    assert eta[12] == pytest.approx(0.94 * 0.96 * 0.96 * 0.87 * 0.95)
    # the outer mirrors' alpha_i of eq. 14 is 33.5 deg (docs/optics.md), tau = 0.85 beyond 20 deg
    assert np.degrees(np.abs(g.receiver_angles())).max() == pytest.approx(33.48, abs=0.01)
    assert eta[0] == pytest.approx(0.94 * 0.96 * 0.96 * 0.85 * 0.95)


def test_area_of_the_classic_configuration_seed000_section_5_4():
    """A = W L with the seed's tube (-2.037..-0.037 m): EAR = 8.17 MWh / A = 1.30 MWh/m2."""
    g = FieldGeometry(tube_right=-2.037, tube_left=-0.037)
    assert g.field_width() == pytest.approx(2.076)
    area = float(optics.installation_area(0.0, 0.0, g))
    assert area == pytest.approx(6.305, abs=1e-3)
    assert 8.17 / area == pytest.approx(1.30, abs=0.005)


def test_lcoe_closed_form_seed000_eq29():
    c = Costs(direct_capital=1000.0, om_fraction=0.01, lifetime=2, discount_rate=0.1)
    value = optics.lcoe(c.yearly(), np.array([100.0, 100.0]), 0.1)
    assert value == pytest.approx((1010 / 1.1 + 10 / 1.21) / (100 / 1.1 + 100 / 1.21))
    with pytest.raises(ValueError):
        optics.lcoe([1.0], [0.0], 0.03)


def test_bad_parameters_refused():
    with pytest.raises(ValueError, match='reflectivity'):
        OpticalParameters(reflectivity=1.2)
    with pytest.raises(ValueError, match='tube_left'):
        FieldGeometry(tube_left=-1.0, tube_right=1.0)
    with pytest.raises(ValueError, match='mirror_aim'):
        OpticalParameters(mirror_aim='sideways')
    with pytest.raises(ValueError, match='cavity_aperture'):
        OpticalParameters(cavity_aperture=0.01)


# --- seed 000 section 5.2: tracking error ---------------------------------------------------

@pytest.fixture(scope='module')
def error_rows():
    return performance.error_table(ALMERIA, P, np.radians([0.03, 0.06, 0.12, 0.24, 0.36]), DAYS, HOURS)


def test_tracking_error_conclusions_of_seed000(error_rows):
    assert len(error_rows) == 4 * 3 * 5
    small = [r for r in error_rows if np.degrees(r.error) <= 0.06 + 1e-9]
    # below 1 % for errors <= 0.06 deg at all four days and three hours, per mirror too
    assert max(r.loss_total for r in small) < 1.0
    assert max(float(np.max(r.loss_per_mirror)) for r in small) < 1.0
    big = [r for r in error_rows if abs(np.degrees(r.error) - 0.36) < 1e-9]
    assert max(r.loss_total for r in big) > 3.0
    # the seed: about 2.6 % lost at 12:00 and 3.5 % at 9:00 / 15:00 for 0.36 deg
    assert all(2.0 < r.loss_total < 3.2 for r in big if r.hour == 12.0)
    assert all(2.5 < r.loss_total < 4.0 for r in big if r.hour != 12.0)
    for day in DAYS:
        for hour in HOURS:
            totals = [r.loss_total for r in error_rows if r.day == day and r.hour == hour]
            assert np.all(np.diff(totals) > -1e-9), (day, hour, totals)


def test_loss_grows_away_from_centre_and_from_noon(error_rows):
    for r in error_rows:
        if abs(np.degrees(r.error) - 0.36) > 1e-9:
            continue
        loss = r.loss_per_mirror
        outer = np.mean(np.r_[loss[:3], loss[-3:]])
        centre = np.mean(loss[11:14])
        assert outer > centre, (r.day, r.hour)
    for day in DAYS:
        at = {r.hour: r.loss_total for r in error_rows if r.day == day and abs(np.degrees(r.error) - 0.36) < 1e-9}
        assert at[9.0] > at[12.0] and at[15.0] > at[12.0], (day, at)


# --- seed 001: optimum tilts ----------------------------------------------------------------

CITIES = {  # seed 001 Table 3
    'Almeria': (36 + 50 / 60 + 7 / 3600, -(2 + 24 / 60 + 8 / 3600), 22),
    'Rome': (41 + 53 / 60 + 30 / 3600, 12 + 30 / 60 + 40 / 3600, 52),
    'Budapest': (47 + 29 / 60 + 52 / 3600, 19 + 2 / 60 + 23 / 3600, 111),
    'Berlin': (52 + 31 / 60 + 27 / 3600, 13 + 24 / 60 + 37 / 3600, 37),
    'Helsinki': (60 + 10 / 60 + 10 / 3600, 24 + 56 / 60 + 7 / 3600, 26),
}


@pytest.mark.parametrize('city', list(CITIES))
def test_brute_force_optimum_is_half_latitude_and_latitude_seed001(city):
    lat, lon, elev = CITIES[city]
    site = AnalysisSite(lat, lon, elev)
    sky = YearSky.compute(site, 2023, 1800.0)
    grid = 11
    res = performance.tilt_search(sky, site, P, grid=grid)
    bm, ba = res.optimum
    step = np.radians(lat) / (grid - 1)
    assert abs(bm - np.radians(lat) / 2) <= step + 1e-9, (city, np.degrees(bm))
    assert abs(ba - np.radians(lat)) <= step + 1e-9, (city, np.degrees(ba))


# --- seed 000 sections 5.3-5.5: three movements vs horizontal in Almeria -------------------

@pytest.fixture(scope='module')
def almeria_sky():
    return YearSky.compute(ALMERIA, 2023, 600.0)


def _pair(sky, model):
    three = performance.annual_energy(sky, ALMERIA, performance.with_tube(P, SEED_TUBES['tilting']), 'eq16',
                                      model=model, costs=Costs(SEED_COSTS['three_movements']))
    flat = performance.annual_energy(sky, ALMERIA, performance.with_tube(P, SEED_TUBES['horizontal']), 'horizontal',
                                     model=model, costs=Costs(SEED_COSTS['one_movement']))
    return three, flat


def test_seed000_ratios_reproduced(almeria_sky):
    """Seed 000 sections 5.3-5.5 with eq. 16 and the paper's tubes, under clear sky (Ineichen-Perez,
    pvlib's Linke turbidity climatology), seed 000 eq. 18's incidence angle in the plane of the
    mirrors' rotation ('eq18'): energy +16.64 % +-3 points, EAR +78.46 % +-8, LCOE -4.62 % +-2."""
    three, flat = _pair(almeria_sky, 'eq18')
    energy = 100 * (three.energy_wh / flat.energy_wh - 1)
    ear = 100 * (three.ear / flat.ear - 1)
    lcoe = 100 * (three.lcoe / flat.lcoe - 1)
    assert abs(energy - 16.64) <= 3.0, energy
    assert abs(ear - 78.46) <= 8.0, ear
    assert abs(lcoe + 4.62) <= 2.0, lcoe
    assert flat.area_m2 == pytest.approx(6.305, abs=0.01)
    # the horizontal LFR's end-loss efficiency: seed 000's introduction says about 70 %
    assert 0.6 < flat.end_loss_efficiency < 0.75


def test_physical_model_keeps_the_seeds_conclusion(almeria_sky):
    """With the 3-D incidence angle (the cosine loss of the sun's longitudinal angle included)
    the three-movement tracker still wins, by more (docs/optics.md gives the figures)."""
    three, flat = _pair(almeria_sky, 'trace')
    assert three.energy_wh > 1.15 * flat.energy_wh and three.ear > 1.6 * flat.ear and three.lcoe < flat.lcoe


def test_day_energy_counts_the_tracking_error(almeria_sky):
    sky = almeria_sky
    day = (sky.t >= sky.t[0] + 170 * 86400) & (sky.t < sky.t[0] + 171 * 86400)
    t, z, a, dni = sky.t[day], sky.zenith[day], sky.azimuth[day], sky.dni[day]
    b0, bm, ba, _ = performance.commands('continuous', z, a, t, ALMERIA)
    ideal = performance.day_energy(t, dni, z, a, b0, bm, ba, P)
    off = performance.day_energy(t, dni, z, a, b0 - np.radians(0.36), bm, ba, P)
    assert ideal > 0 and 0.9 * ideal < off < ideal
