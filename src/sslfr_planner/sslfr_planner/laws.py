"""Longitudinal laws: tilt of the mobile structure beta_M and secondary reflector beta_a.

Signs (docs/conventions.md): beta_M and beta_a are measured from the horizontal,
positive when they lower the collector's +p end (the SOUTH end of a north-south
collector), i.e. positive when the rows / the tube face the south. All angles radians;
magnitudes are clipped to the collector's tilt_max by :mod:`sslfr_planner.tracking_table`,
not here. docs/optics.md compares the laws' annual energy, area, EAR and LCOE
(``sslfr analyse year``) and explains the default (``continuous``).

* :func:`continuous`: the tilt that centres the reflected rays on the tube at every
  instant (3-D trace, :mod:`sslfr_planner.raytrace`); smooth, no jumps.
* :func:`eq16`: seed 000 eq. 16 as published, beta_M = beta_a = theta_z / 2 inside the
  axes' 0..90 deg range (the rows face the equator).
* :func:`optimum_fixed`: seed 001 eqs. 16 and 19 (fixed).
* :func:`daily`: once a day, latitude corrected by the declination (seed 000 section 1).
* :func:`horizontal`: the classic large-scale LFR (no longitudinal movement).

:func:`eq16`, :func:`optimum_fixed` and :func:`daily` set the rows' tilt beta_M for the
rows' sake (the reflected rays leave at 2 beta_M - theta_z from the vertical in the
longitudinal plane, seed 001 eq. 3, whatever beta_a): a collector without a secondary
reflector movement follows their beta_M under a fixed receiver. :func:`continuous`
assumes the tube tilts with the rows (docs/collectors.md, "Longitudinal movements").
"""
from __future__ import annotations

import functools

import numpy as np

from .collector import FieldGeometry

#: Newton iterations of :func:`continuous` from the central mirror's closed form (error < 1e-10 rad)
_NEWTON = 3


def _equator_side(latitude, collector_azimuth=0.0) -> float:
    """+1 when the equator lies on the collector's +p side, -1 otherwise (latitude 0: +1)."""
    lat_sign = 1.0 if float(latitude) >= 0.0 else -1.0
    return lat_sign * (1.0 if np.cos(collector_azimuth) >= 0 else -1.0)


def eq16(zenith, latitude, collector_azimuth=0.0):
    """Seed 000 eq. 16 as published: beta_M = beta_a = theta_z / 2 [rad].

    The seed gives both axes a range of 0 to 90 deg (section 4) and eq. 16 has no
    sign: the rows and the tube always face the same end, the equator's (south in
    the northern hemisphere; the sign flips in the southern hemisphere and when the
    collector's +p end points north, as :func:`optimum_fixed`). theta_z/2 is
    continuous in time, so the law never jumps; when the sun is on the pole's side
    (summer mornings and evenings, the tropics) the rows still face the equator.

    Parameters
    ----------
    zenith : array_like
        Sun zenith angle theta_z [rad].
    latitude : float
        Site latitude [rad].
    collector_azimuth : float
        Azimuth of the collector axis [rad].

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        beta_M, beta_a [rad].
    """
    b = _equator_side(latitude, collector_azimuth) * np.clip(np.asarray(zenith, dtype=float), 0.0, np.pi) / 2.0
    return b, b.copy()


_TABLE_NODES = 2048


@functools.lru_cache(maxsize=16)
def _path_table(geometry: FieldGeometry):
    """Mean in-plane path from the mirrors to the tube vs c = cos(beta): (lbar, dlbar/dc) at c = k / 2048.

    lbar(c) = mean_i sqrt(x_i^2 + (h c)^2) [m] tabulated at 2049 nodes of c in [0, 1]
    (linear interpolation error < 1e-9 m).
    """
    c = np.linspace(0.0, 1.0, _TABLE_NODES + 1)
    x = geometry.mirror_positions()
    h = geometry.aim_height
    paths = np.sqrt(x[None, :] ** 2 + (h * c[:, None]) ** 2)
    lbar = paths.mean(axis=1)
    dl = (h * h * c[:, None] / np.where(paths > 0.0, paths, 1.0)).mean(axis=1)
    return np.append(lbar, lbar[-1]), np.append(dl, dl[-1])


def _lookup(table, c):
    """Linear interpolation of a :func:`_path_table` column at c in [0, 1] (uniform nodes)."""
    x = np.clip(c, 0.0, 1.0) * _TABLE_NODES
    i = x.astype(np.intp)
    f = x - i
    lo = table[i]
    return lo + f * (table[i + 1] - lo)


def continuous(sun, geometry: FieldGeometry):
    """Tilt beta_M = beta_a that centres the reflected rays on the tube [rad].

    From the 3-D trace (:mod:`sslfr_planner.raytrace`, docs/optics.md): with the tube
    parallel to the rows (beta_a = beta_M = b) a ray reflected by mirror i toward the
    tube's axis lands at u_i = h sin b - tan(theta_perp) l_i along the tube, where
    sin(theta_perp) = v . r = v_p cos b - v_z sin b is the sun's angle to the plane
    perpendicular to the rows and l_i = sqrt(x_i^2 + (h cos b)^2) the mirror's path to
    the axis in that plane (h = f + D/2). The law is the b for which the mean of u_i
    over the mirrors is zero: the lit band of every row is then centred on the
    tube, the mean longitudinal displacement of the rays is zero and the end losses
    of a tube as long as the rows are least. For the central mirror alone the
    solution is closed: tan b = v_p / (1 + v_z) = tan(theta_z / 2) cos(gamma), gamma
    the sun's azimuth from the +p end; at solar noon that is seed 000 eq. 16 /
    seed 001's "reflected rays vertical" (mu = 0). The mirrors' mean is solved by
    Newton's method from that start. b is a smooth function of the sun vector: it
    never jumps (it passes through 0 when the sun crosses the plane perpendicular to
    the rows, and faces the pole when the sun is on the pole's side).

    Parameters
    ----------
    sun : array_like, (..., 3)
        Unit vector toward the sun in the collector frame
        (:func:`sslfr_planner.raytrace.sun_vector`).
    geometry : FieldGeometry

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        beta_M, beta_a [rad] (equal).
    """
    v = np.asarray(sun, dtype=float)
    vp, vz = v[..., 1], v[..., 2]
    h = geometry.aim_height
    b = np.arctan2(vp, np.maximum(1.0 + vz, 1e-9))
    lbar, dl = _path_table(geometry)
    for _ in range(_NEWTON):
        cb, sb = np.cos(b), np.sin(b)
        sigma = np.clip(vp * cb - vz * sb, -0.999999, 0.999999)
        root = np.sqrt(1.0 - sigma * sigma)
        g = sigma / root
        ell = _lookup(lbar, cb)
        f = g * ell - h * sb
        dsigma = -vp * sb - vz * cb
        dell = -_lookup(dl, cb) * sb
        df = dsigma / (root * root * root) * ell + g * dell - h * cb
        b = b - f / np.where(np.abs(df) > 1e-12, df, -1e-12)
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

    beta_M = beta_a = (phi - delta_noon)/2: seed 000 eq. 16 frozen at solar noon, when
    the zenith angle is |phi - delta| and the sun is on the +p side if phi > delta.
    ``declination_noon`` is the sun's declination at that day's solar noon [rad]. Sign
    flips with the collector's +p end as in :func:`optimum_fixed`. The value changes
    at local mean midnight, never while tracking.
    """
    s = 1.0 if np.cos(collector_azimuth) >= 0 else -1.0
    b = s * (float(latitude) - np.asarray(declination_noon, dtype=float)) / 2.0
    return b, b.copy() if isinstance(b, np.ndarray) else b
