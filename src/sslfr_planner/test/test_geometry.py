"""Projection angles and mirror tilts (seed 000 eqs. 9-15, seed 003 eqs. 5-6, seed 004 eqs. 1-2)."""
import math

import numpy as np
from hypothesis import given, settings, strategies as st

from sslfr_planner import geometry as g

angles = st.floats(0.0, math.radians(89.0))
azimuths = st.floats(0.0, 2 * math.pi, exclude_max=True)


@settings(max_examples=80, deadline=None)
@given(z=angles, az=azimuths, gc=st.floats(-math.pi / 4, math.pi / 4))
def test_projection_angles_are_seed004_eqs_1_2(z, az, gc):
    tt, tl = g.projection_angles(z, az, gc)
    # seed 004: azimuths from north, WEST positive -> gamma_s = -az, gamma_col = -gc
    gs, gcol = -az, float(g.collector_azimuth_from_seed004(gc))
    assert math.isclose(tt, math.atan(math.tan(z) * math.sin(gs - gcol)), abs_tol=1e-12)
    assert math.isclose(-tl, math.atan(math.tan(z) * math.cos(gs - gcol)), abs_tol=1e-12)


@settings(max_examples=80, deadline=None)
@given(z=angles, az=azimuths)
def test_projection_angles_are_seed000_eqs_9_10(z, az):
    alpha_s = math.pi / 2 - z
    gamma_s = az - math.pi  # seed 000: from south, west positive
    tt, tl = g.projection_angles(z, az)
    if alpha_s > 1e-6:
        assert math.isclose(tt, math.atan(math.sin(gamma_s) / math.tan(alpha_s)), abs_tol=1e-12)
        assert math.isclose(tl, math.atan(math.cos(gamma_s) / math.tan(alpha_s)), abs_tol=1e-12)


def test_worked_numbers_of_the_conventions_doc():
    # docs/conventions.md: sun at zenith 60 deg, azimuth 240 deg (south-west, afternoon)
    tt, tl = g.projection_angles(math.radians(60.0), math.radians(240.0))
    assert math.degrees(tt) == np.float64(math.degrees(tt))
    assert round(math.degrees(tt), 2) == 56.31 and round(math.degrees(tl), 2) == 40.89
    assert round(math.degrees(g.central_mirror_tilt(tt)), 2) == 28.15
    # morning, sun in the south-east: negative transversal angle
    tt_m, _ = g.projection_angles(math.radians(60.0), math.radians(120.0))
    assert math.isclose(tt_m, -tt, abs_tol=1e-12)


def test_mirror_tilts_seed000_left_right_and_central():
    x = g.mirror_positions(12, 0.06, 0.024)
    assert x.size == 25 and math.isclose(x[-1], 12 * 0.084) and x[12] == 0.0
    tt = np.radians([-60.0, 0.0, 35.0])
    b = g.mirror_tilts(tt, x, 1.5, 0.0486)
    alpha = np.arctan(np.abs(x) / (1.5 + 0.0486 / 2))  # seed 000 eq. 14
    np.testing.assert_allclose(b[:, 12], tt / 2)  # eq. 13
    right = x > 0
    np.testing.assert_allclose(b[:, right], (tt[:, None] - alpha[right]) / 2)   # eq. 11 (our signs)
    np.testing.assert_allclose(b[:, ~right & (x < 0)], (tt[:, None] + alpha[x < 0]) / 2)  # eq. 12
    # every mirror moves at half the transversal rate (one drive is enough)
    np.testing.assert_allclose(np.diff(b, axis=0), np.diff(tt)[:, None] / 2 * np.ones((1, 25)))


def test_mirror_tilts_agree_with_the_optics_module():
    from sslfr_planner.analysis import optics
    p = optics.OpticalParameters()
    tt = np.radians(np.linspace(-80, 80, 33))
    geo = p.geometry
    x = g.mirror_positions(geo.n_per_side, geo.mirror_width, geo.gap)
    np.testing.assert_allclose(g.mirror_tilts(tt, x, geo.receiver_height, geo.tube_diameter),
                               optics.ideal_tilts(tt, p), atol=1e-15)


def test_seed003_tilts_are_the_same_law():
    d = np.array([-0.3, -0.15, 0.0, 0.15, 0.3])  # seed 003: 0.15 m between centres, F = 0.75 m
    tt = np.radians(np.linspace(-70, 70, 15))
    np.testing.assert_allclose(g.mirror_tilts_seed003(tt, d, 0.75), g.mirror_tilts(tt, d, 0.75, 0.0), atol=1e-15)


@settings(max_examples=60, deadline=None)
@given(z=angles, az=azimuths)
def test_transversal_antisymmetric_in_azimuth(z, az):
    """Mirror image about the meridian: theta_t(180 + a) = -theta_t(180 - a), theta_l unchanged."""
    t1, l1 = g.projection_angles(z, az)
    t2, l2 = g.projection_angles(z, 2 * math.pi - az)
    assert math.isclose(t1, -t2, abs_tol=1e-12) and math.isclose(l1, l2, abs_tol=1e-12)
