"""Low-accuracy solar position formulas used by the seeds themselves (radians out).

Kept for comparison with the SPA (benchmarks/bench_ephemeris.py prints how far they
are): the planner never uses them.

* seed 000 eqs. 2-8 (Spencer's declination series, hour angle from solar time,
  altitude, azimuth, sunrise/sunset hour angle). Eq. 4 is printed with a stray
  "180/pi" factor: omega = 15 (T_S - 12) is already in degrees and is used as such.
* seed 003 eqs. 1-2 (Cooper's declination, omega = 15 (N_h - 12)); seed 003 gives only
  the incidence (zenith) angle, eq. 3; the azimuth here uses seed 000 eq. 6.

Neither seed says how solar time is obtained from clock time: here
T_S = UTC + longitude/15 h + E, with E Spencer's (1971) equation of time (same paper
as eq. 3's declination), or E = 0 with ``equation_of_time=False`` (local mean time).
Day number n_d counts from 1 on 1 January of the UTC date.
"""
from __future__ import annotations

import numpy as np


def _day_number_and_hours(t):
    t = np.asarray(t, dtype=float)
    days = np.floor(t / 86400.0)
    d64 = days.astype('int64').astype('datetime64[D]')
    year_start = d64.astype('datetime64[Y]').astype('datetime64[D]')
    nd = (d64 - year_start).astype(float) + 1.0
    return nd, (t - days * 86400.0) / 3600.0


def daily_angle(nd):
    """Gamma = (n_d - 1) 2 pi / 365 [rad] (seed 000 eq. 2)."""
    return (np.asarray(nd, dtype=float) - 1.0) * 2.0 * np.pi / 365.0


def declination_spencer(gamma):
    """Declination [rad] (seed 000 eq. 3, Spencer 1971) from the daily angle [rad]."""
    g = np.asarray(gamma, dtype=float)
    return (0.006918 - 0.399912 * np.cos(g) + 0.070257 * np.sin(g) - 0.006758 * np.cos(2 * g)
            + 0.000907 * np.sin(2 * g) - 0.002697 * np.cos(3 * g) + 0.001480 * np.sin(3 * g))


def equation_of_time_spencer(gamma):
    """Equation of time [h] (Spencer 1971), an assumption the seeds leave open."""
    g = np.asarray(gamma, dtype=float)
    e = 229.18 * (0.000075 + 0.001868 * np.cos(g) - 0.032077 * np.sin(g) - 0.014615 * np.cos(2 * g)
                  - 0.040849 * np.sin(2 * g))
    return e / 60.0


def declination_cooper(nd):
    """Declination [rad] = 23.45 deg sin(360 (284 + N_d)/365) (seed 003 eq. 1)."""
    return np.radians(23.45) * np.sin(2.0 * np.pi * (284.0 + np.asarray(nd, dtype=float)) / 365.0)


def hour_angle(solar_time_h):
    """omega = 15 (T_S - 12) deg, returned in [rad] (seed 000 eq. 4, seed 003 eq. 2)."""
    return np.radians(15.0 * (np.asarray(solar_time_h, dtype=float) - 12.0))


def altitude(decl, lat, omega):
    """Solar altitude alpha_S [rad] (seed 000 eq. 5; seed 003 eqs. 3-4)."""
    return np.arcsin(np.clip(np.sin(decl) * np.sin(lat) + np.cos(decl) * np.cos(lat) * np.cos(omega),
                             -1.0, 1.0))


def azimuth_from_south(alt, decl, lat, omega):
    """gamma_S = sign(omega) arccos((sin a sin phi - sin d)/(cos a cos phi)) [rad] (seed 000 eq. 6).

    From south, west (afternoon) positive. Undefined at the poles and with the sun
    at the zenith; there it returns 0.
    """
    den = np.cos(alt) * np.cos(lat)
    ok = np.abs(den) > 1e-12
    ratio = np.where(ok, (np.sin(alt) * np.sin(lat) - np.sin(decl)) / np.where(ok, den, 1.0), 1.0)
    return np.where(omega >= 0, 1.0, -1.0) * np.arccos(np.clip(ratio, -1.0, 1.0))


def sunset_hour_angle(decl, lat):
    """omega_s = arccos(-tan d tan phi) [rad] (seed 000 eqs. 7-8); 0 polar night, pi polar day."""
    return np.arccos(np.clip(-np.tan(decl) * np.tan(lat), -1.0, 1.0))


def _solar_time(t, lon, nd, hours, equation_of_time):
    ts = hours + np.degrees(lon) / 15.0
    if equation_of_time:
        ts = ts + equation_of_time_spencer(daily_angle(nd))
    return ts


def seed000_position(t, latitude: float, longitude: float, equation_of_time: bool = True):
    """Sun (zenith, azimuth clockwise from north) [rad] by seed 000 eqs. 2-6.

    Parameters
    ----------
    t : array_like
        UTC instants [s since the Unix epoch].
    latitude, longitude : float
        [rad], north and east positive.
    equation_of_time : bool
        Apply Spencer's equation of time to get solar time (module docstring).
    """
    nd, hours = _day_number_and_hours(t)
    decl = declination_spencer(daily_angle(nd))
    omega = hour_angle(_solar_time(t, longitude, nd, hours, equation_of_time))
    alt = altitude(decl, latitude, omega)
    gs = azimuth_from_south(alt, decl, latitude, np.sin(omega))
    return np.pi / 2 - alt, (np.pi + gs) % (2 * np.pi)


def seed003_position(t, latitude: float, longitude: float, equation_of_time: bool = True):
    """Sun (zenith, azimuth clockwise from north) [rad] by seed 003 eqs. 1-3 (+ seed 000 eq. 6)."""
    nd, hours = _day_number_and_hours(t)
    decl = declination_cooper(nd)
    omega = hour_angle(_solar_time(t, longitude, nd, hours, equation_of_time))
    alt = altitude(decl, latitude, omega)
    gs = azimuth_from_south(alt, decl, latitude, np.sin(omega))
    return np.pi / 2 - alt, (np.pi + gs) % (2 * np.pi)


MODELS = ('seed000', 'seed003')


def sun_position(t, site, model: str = 'seed000', equation_of_time: bool = True, collector_azimuth: float = 0.0):
    """The seeds' sun position as a :class:`sslfr_planner.spa.SunAngles` (radians).

    Same interface as :func:`sslfr_planner.spa.sun_position`, so callers (the
    benchmark, analysis tools) can swap the SPA for ``model`` = 'seed000' (eqs. 2-6)
    or 'seed003' (eqs. 1-3). Refraction and parallax are not modelled:
    ``elevation_geometric`` is 90 deg - zenith.
    """
    from .geometry import projection_angles
    from .spa import SunAngles
    fns = {'seed000': seed000_position, 'seed003': seed003_position}
    if model not in fns:
        raise ValueError(f'model must be one of {", ".join(MODELS)}; got {model!r}')
    t = np.atleast_1d(np.asarray(t, dtype=float))
    zen, az = fns[model](t, site.latitude, site.longitude, equation_of_time)
    tt, tl = projection_angles(zen, az, collector_azimuth)
    return SunAngles(zen, az, np.pi / 2 - zen, tt, tl)
