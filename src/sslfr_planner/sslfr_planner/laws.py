"""Longitudinal laws: tilt of the mobile structure beta_M and secondary reflector beta_a.

Signs (docs/conventions.md): beta_M and beta_a are measured from the horizontal,
positive when they lower the collector's +p end (the SOUTH end of a north-south
collector), i.e. positive when the rows / the tube face the south. A law "signed
toward the sun" is positive when the sun is on the +p side (theta_l > 0): in the
northern hemisphere outside the tropics that is always the case at noon; in the
southern hemisphere the tilts come out negative (rows face north); in the tropics the
sign follows the sun. All angles radians; magnitudes are clipped to the collector's
tilt_max by :mod:`sslfr_planner.daytable`, not here.
"""
from __future__ import annotations

import numpy as np


def _side(x):
    """+1 where x >= 0, -1 elsewhere (the sun's side; a tie goes to +p)."""
    side = (np.asarray(x, dtype=float) >= 0.0).astype(float)
    side *= 2.0
    side -= 1.0
    return side


def continuous(zenith, longitudinal):
    """Seed 000 eq. 16: beta_M = beta_a = theta_z / 2, signed toward the sun [rad].

    Parameters
    ----------
    zenith : array_like
        Sun zenith angle theta_z [rad].
    longitudinal : array_like
        Longitudinal incidence angle theta_l [rad] (+p positive); only its sign is
        used: the rows face the side the sun is on. When the sun crosses the
        transversal (east-west) vertical plane, theta_l changes sign and so does the
        law: the seed's law is discontinuous there (a jump of theta_z between +/-
        theta_z/2); in the northern hemisphere beyond the tropics this happens only in
        the summer mornings and evenings, when the sun rises north of east.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        beta_M, beta_a [rad].
    """
    b = _side(longitudinal)
    b *= np.asarray(zenith, dtype=float)
    b *= 0.5
    return b, b.copy()


def optimum_fixed(latitude, collector_azimuth=0.0):
    """Seed 001 eqs. 16 and 19: beta_M = |latitude|/2, beta_a = |latitude| [rad].

    Signed toward the equator, where the sun is at noon outside the tropics (positive
    in the northern hemisphere for a north-south collector; the sign flips when the
    collector's +p end points north, |collector_azimuth| > pi/2).
    """
    lat = float(latitude)
    s = np.sign(lat) * (1.0 if np.cos(collector_azimuth) >= 0 else -1.0)
    return s * abs(lat) / 2.0, s * abs(lat)


def horizontal():
    """Classic large-scale LFR: rows and tube horizontal, beta_M = beta_a = 0 [rad]."""
    return 0.0, 0.0


def daily(latitude, declination_noon, collector_azimuth=0.0):
    """Once-a-day law: latitude corrected by the declination (seed 000 section 1) [rad].

    beta_M = beta_a = (phi - delta_noon)/2: the 'continuous' law (seed 000 eq. 16)
    frozen at solar noon, when the zenith angle is |phi - delta| and the sun is on the
    +p side if phi > delta. ``declination_noon`` is the sun's declination at that
    day's solar noon [rad]. Sign flips with the collector's +p end as in
    :func:`optimum_fixed`.
    """
    s = 1.0 if np.cos(collector_azimuth) >= 0 else -1.0
    b = s * (float(latitude) - np.asarray(declination_noon, dtype=float)) / 2.0
    return b, b.copy() if isinstance(b, np.ndarray) else b
