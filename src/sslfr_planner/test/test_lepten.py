"""LEPTEN lines (seed 004 eqs. 3-5) and seed 004 Table 1."""
import math

import numpy as np
import pytest

from sslfr_planner import lepten

# seed 004 Table 1: angular pace a and offset b [deg] of the ten mirror lines
TABLE1_A = [0.4966, 0.4963, 0.4961, 0.4959, 0.4958, 0.4958, 0.4959, 0.4961, 0.4963, 0.4966]
TABLE1_B = [15.8311, 12.8113, 9.4542, 5.8066, 1.9593, -1.9594, -5.8066, -9.4543, -12.8113, -15.8312]
H, R = lepten.SEED004_HEIGHT, lepten.SEED004_RADIUS


@pytest.fixture(scope='module')
def positions():
    """Derivation of the line positions from Table 1 (the seed does not list them).

    b is the offset of the least-squares line theta_m = a theta_T + b fitted to the exact
    solution of eqs. 3-4 over theta_T in [-80, 80] deg; it decreases monotonically with
    the axis position x, so each published b (4 decimals) fixes one x. The x found are
    an evenly spaced field (pitch 0.5097 m), an independent sign that the model and the
    fit are the seed's.
    """
    return np.array([lepten.position_from_offset(math.radians(b), H, R) for b in TABLE1_B])


def test_positions_are_an_even_field(positions):
    pitch = np.diff(positions)
    assert np.all(pitch > 0)
    assert np.ptp(pitch) < 1e-4
    assert abs(pitch.mean() - 0.5097) < 1e-3
    assert abs(positions[:5].sum() + positions[5:].sum()) < 1e-3  # symmetric about the receiver


def test_table1_reproduced(positions):
    for x, a, b in zip(positions, TABLE1_A, TABLE1_B):
        fit = lepten.fit_linear(x, H, R)
        assert abs(math.degrees(fit.b) - b) < 5e-5             # b to the 4 printed decimals
        assert abs(fit.a - a) < 1e-4                           # a to 1e-4 (8 of 10 to the digit)
        assert math.degrees(fit.max_error) < 0.03              # linearisation error of each line
    # with theta_T in [-75, 75] deg every a matches to the printed digit
    pos75 = [lepten.position_from_offset(math.radians(b), H, R, (math.radians(-75), math.radians(75)))
             for b in TABLE1_B]
    got = [round(lepten.fit_linear(x, H, R, (math.radians(-75), math.radians(75))).a, 4) for x in pos75]
    assert got == TABLE1_A


def test_common_pace_is_the_mean_of_a(positions):
    a = [lepten.fit_linear(x, H, R).a for x in positions]
    assert round(float(np.mean(a)), 4) == 0.4962  # seed 004: the common pace 0.4962
    err = lepten.common_drive_errors(positions, 0.4962)
    assert np.all(np.degrees(err) < 0.2)


def test_exact_solution_satisfies_eqs_3_4():
    tt = np.radians(np.linspace(-80, 80, 161))
    for x in (-2.3, -0.25, 0.0, 1.0):
        tm = lepten.exact_mirror_angle(tt, x, H, R)
        tr = lepten.reflected_angle(tm, x, H, R)
        np.testing.assert_allclose(2 * tm - tr, tt, atol=1e-12)


def test_zero_radius_gives_half_pace():
    for x in (-2.0, 0.3, 1.7):
        fit = lepten.fit_linear(x, H, 0.0)
        assert abs(fit.a - 0.5) < 1e-12 and fit.max_error < 1e-12
        assert math.isclose(fit.b, math.atan2(-x, H) / 2, abs_tol=1e-12)


def test_bad_geometry_rejected():
    with pytest.raises(ValueError):
        lepten.exact_mirror_angle(0.0, 0.0, 1.0, 0.6)
    with pytest.raises(ValueError):
        lepten.fit_linear(0.0, H, R, (0.5, -0.5))
