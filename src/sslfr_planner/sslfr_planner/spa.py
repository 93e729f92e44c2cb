"""NREL Solar Position Algorithm (SPA), vectorised numpy (no rclpy).

Reda, I. and Andreas, A. (2004), "Solar position algorithm for solar radiation
applications", Solar Energy 76(5), 577-589; NREL/TP-560-34302 (rev. 2008). Stated
uncertainty +/-0.0003 deg for years -2000..6000. One function per published equation,
numbered as in the report (section 3), in degrees as the report uses them; the
radian, :class:`~sslfr_planner.site.Site` based entry point is :func:`sun_position`.

Two evaluation paths
--------------------
``exact=True``
    every equation (4)-(46) evaluated at every instant, literally as published. This
    is the reference path (worked-example test, pvlib comparison).
``exact=False`` (default, fast)
    the expensive geocentric part (the Earth periodic terms L, B, R, eqs. 9-14, and
    the nutation, eqs. 15-23; 258 cosine terms per instant) varies slowly, so it is
    evaluated exactly on a grid of nodes every :data:`NODE_STEP` seconds (aligned on
    multiples of NODE_STEP since the Unix epoch, so the result of an instant never
    depends on the batch it is in) and interpolated linearly to each instant: the
    quantities interpolated are sin(delta), cos(delta), sin(xi) (xi: equatorial
    horizontal parallax, eq. 33) and g = nu - alpha - nu0_lin, the sun's apparent
    Greenwich hour angle (eqs. 28-30) minus the part of eq. 28 linear in JD, which is
    evaluated at each instant from its own JD as the report does. With NODE_STEP =
    600 s the fast path stays within 1e-7 deg of the exact one (measured: 5e-8 deg in
    zenith and 9e-8 deg in azimuth over a day at 1 s, benchmarks/bench_ephemeris.py;
    test_spa.py asserts < 1e-6 deg against the exact path and < 1e-5 deg against
    pvlib). The topocentric
    part (eqs. 32-46) is evaluated per instant in the algebraically equivalent vector
    form of :func:`_topocentric_fast` (same geometry, fewer transcendental calls).

Conventions: zenith angle from the vertical, azimuth clockwise from north (eastward,
0..360 deg, eq. 46); times are float seconds since the Unix epoch, UTC (UT1 = UTC
assumed, |UT1-UTC| < 0.9 s); delta T = TT - UT [s]. Pressure in mbar (hPa) and
temperature in degC, as the report (the :class:`Site` API takes pascal).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import spa_tables as T

#: spacing of the exact-geocentric nodes of the fast path [s]
NODE_STEP = 600.0
#: atmospheric refraction at sunrise/sunset used by the report [deg]
ATMOS_REFRACT = 0.5667
#: apparent radius of the sun's disc used by the report [deg]
SUN_RADIUS = 0.26667

_UNIX_EPOCH_JD = 2440587.5
_J2000 = 2451545.0


# ----------------------------------------------------------------------------- delta T
def delta_t_model(unixtime):
    """Default delta T = TT - UT [s] (Espenak & Meeus 2006 polynomials, NASA).

    Piecewise polynomials in the decimal year y for 1860-2150 (the ranges the
    project needs are 1900-2100) and the long-term parabola -20 + 32 u^2,
    u = (y - 1820)/100, outside them. Observed values since 2005 differ by up to
    ~2 s (ΔT was 69.2 s in 2024; the model gives 74.6 s): 2 s of delta T moves the
    sun by 0.008 deg along its path, so pass the IERS value in ``Site.delta_t``
    where that matters.

    Parameters
    ----------
    unixtime : array_like
        UTC instants [s since 1970-01-01T00:00:00Z].

    Returns
    -------
    numpy.ndarray
        delta T [s].
    """
    ut = np.asarray(unixtime, dtype=float)
    y = 1970.0 + ut / (365.2425 * 86400.0)
    out = -20.0 + 32.0 * ((y - 1820.0) / 100.0) ** 2  # long-term parabola
    t = y - 1860.0
    out = np.where((y >= 1860) & (y < 1900), 7.62 + 0.5737 * t - 0.251754 * t**2 + 0.01680668 * t**3
                   - 0.0004473624 * t**4 + t**5 / 233174.0, out)
    t = y - 1900.0
    out = np.where((y >= 1900) & (y < 1920), -2.79 + 1.494119 * t - 0.0598939 * t**2 + 0.0061966 * t**3
                   - 0.000197 * t**4, out)
    t = y - 1920.0
    out = np.where((y >= 1920) & (y < 1941), 21.20 + 0.84493 * t - 0.076100 * t**2 + 0.0020936 * t**3, out)
    t = y - 1950.0
    out = np.where((y >= 1941) & (y < 1961), 29.07 + 0.407 * t - t**2 / 233.0 + t**3 / 2547.0, out)
    t = y - 1975.0
    out = np.where((y >= 1961) & (y < 1986), 45.45 + 1.067 * t - t**2 / 260.0 - t**3 / 718.0, out)
    t = y - 2000.0
    out = np.where((y >= 1986) & (y < 2005), 63.86 + 0.3345 * t - 0.060374 * t**2 + 0.0017275 * t**3
                   + 0.000651814 * t**4 + 0.00002373599 * t**5, out)
    out = np.where((y >= 2005) & (y < 2050), 62.92 + 0.32217 * t + 0.005589 * t**2, out)
    out = np.where((y >= 2050) & (y < 2150), -20.0 + 32.0 * ((y - 1820.0) / 100.0) ** 2
                   - 0.5628 * (2150.0 - y), out)
    return out


# ----------------------------------------------------------------- 3.1 time scales
def julian_day(unixtime):
    """Julian day JD [d] of a UTC instant (eq. 4; from Unix time: JD = t/86400 + 2440587.5)."""
    return np.asarray(unixtime, dtype=float) / 86400.0 + _UNIX_EPOCH_JD


def julian_ephemeris_day(jd, delta_t):
    """Julian ephemeris day JDE = JD + delta T/86400 [d] (eq. 5)."""
    return jd + np.asarray(delta_t, dtype=float) / 86400.0


def julian_century(jd):
    """Julian century JC = (JD - 2451545)/36525 [-] (eq. 6)."""
    return (jd - _J2000) / 36525.0


def julian_ephemeris_century(jde):
    """Julian ephemeris century JCE = (JDE - 2451545)/36525 [-] (eq. 7)."""
    return (jde - _J2000) / 36525.0


def julian_ephemeris_millennium(jce):
    """Julian ephemeris millennium JME = JCE/10 [-] (eq. 8)."""
    return jce / 10.0


# ------------------------------------------------- 3.2 heliocentric L, B, R
def periodic_term_sum(table, jme):
    """Sum of A cos(B + C JME) over a table of Earth periodic terms (eqs. 9-10).

    Parameters
    ----------
    table : numpy.ndarray, shape (n, 3)
        Rows (A, B, C) of Table A4.2.
    jme : numpy.ndarray
        Julian ephemeris millennium [-].

    Returns
    -------
    numpy.ndarray
        The sum, in the table's unit (1e-8 rad or 1e-8 AU), shape of ``jme``.
    """
    jme = np.asarray(jme, dtype=float)
    arg = table[:, 1] + table[:, 2] * jme[..., None]
    return np.cos(arg) @ table[:, 0]


def _series(tables, jme):
    jme = np.asarray(jme, dtype=float)
    total = np.zeros_like(jme)
    for power, table in reversed(list(enumerate(tables))):  # Horner in JME (eq. 11)
        total = total * jme + periodic_term_sum(table, jme)
    return total / 1e8


def heliocentric_longitude(jme):
    """Earth heliocentric longitude L [deg], limited to 0..360 (eqs. 9-12)."""
    return np.degrees(_series(T.L_TERMS, jme)) % 360.0


def heliocentric_latitude(jme):
    """Earth heliocentric latitude B [deg] (eqs. 9-12 with Table A4.2 B0-B1)."""
    return np.degrees(_series(T.B_TERMS, jme))


def heliocentric_radius_vector(jme):
    """Earth radius vector R [AU] (eqs. 9-11 with Table A4.2 R0-R4)."""
    return _series(T.R_TERMS, jme)


# ------------------------------------------------------ 3.3 geocentric
def geocentric_longitude(L):
    """Geocentric longitude Theta = L + 180 [deg], limited to 0..360 (eq. 13)."""
    return (L + 180.0) % 360.0


def geocentric_latitude(B):
    """Geocentric latitude beta = -B [deg] (eq. 14)."""
    return -B


# ------------------------------------------------------ 3.4 nutation
def mean_elongation_moon_sun(jce):
    """X0, mean elongation of the moon from the sun [deg] (eq. 15)."""
    return 297.85036 + 445267.111480 * jce - 0.0019142 * jce**2 + jce**3 / 189474.0


def mean_anomaly_sun(jce):
    """X1, mean anomaly of the sun (Earth) [deg] (eq. 16)."""
    return 357.52772 + 35999.050340 * jce - 0.0001603 * jce**2 - jce**3 / 300000.0


def mean_anomaly_moon(jce):
    """X2, mean anomaly of the moon [deg] (eq. 17)."""
    return 134.96298 + 477198.867398 * jce + 0.0086972 * jce**2 + jce**3 / 56250.0


def moon_argument_of_latitude(jce):
    """X3, moon's argument of latitude [deg] (eq. 18)."""
    return 93.27191 + 483202.017538 * jce - 0.0036825 * jce**2 + jce**3 / 327270.0


def moon_ascending_node_longitude(jce):
    """X4, longitude of the ascending node of the moon's orbit [deg] (eq. 19)."""
    return 125.04452 - 1934.136261 * jce + 0.0020708 * jce**2 + jce**3 / 450000.0


def nutation(jce):
    """Nutation in longitude and obliquity (Delta psi, Delta epsilon) [deg] (eqs. 20-23).

    Delta psi_i = (a_i + b_i JCE) sin(sum_j X_j Y_ij) (eq. 20), Delta epsilon_i =
    (c_i + d_i JCE) cos(...) (eq. 21); Delta psi = sum / 36e6 (eq. 22), same for
    Delta epsilon (eq. 23); Table A4.3 (a..d in 0.0001 arc-seconds).
    """
    jce = np.asarray(jce, dtype=float)
    x = np.stack([mean_elongation_moon_sun(jce), mean_anomaly_sun(jce), mean_anomaly_moon(jce),
                  moon_argument_of_latitude(jce), moon_ascending_node_longitude(jce)], axis=-1)
    arg = np.radians(x @ T.NUTATION_Y.T)  # (..., 63)
    abcd = T.NUTATION_ABCD
    dpsi = (np.sin(arg) * (abcd[:, 0] + abcd[:, 1] * jce[..., None])).sum(axis=-1) / 36000000.0
    deps = (np.cos(arg) * (abcd[:, 2] + abcd[:, 3] * jce[..., None])).sum(axis=-1) / 36000000.0
    return dpsi, deps


# ---------------------------------------------------- 3.5-3.10 apparent sun
def mean_ecliptic_obliquity(jme):
    """Mean obliquity of the ecliptic epsilon_0 [arc-seconds] (eq. 24), U = JME/10."""
    u = np.asarray(jme, dtype=float) / 10.0
    coeffs = (84381.448, -4680.93, -1.55, 1999.25, -51.38, -249.67, -39.05, 7.12, 27.87, 5.79, 2.45)
    out = np.zeros_like(u)
    for c in reversed(coeffs):
        out = out * u + c
    return out


def true_ecliptic_obliquity(epsilon0, deps):
    """True obliquity epsilon = epsilon_0/3600 + Delta epsilon [deg] (eq. 25)."""
    return epsilon0 / 3600.0 + deps


def aberration_correction(R):
    """Aberration correction Delta tau = -20.4898/(3600 R) [deg] (eq. 26)."""
    return -20.4898 / (3600.0 * R)


def apparent_sun_longitude(theta, dpsi, dtau):
    """Apparent sun longitude lambda = Theta + Delta psi + Delta tau [deg] (eq. 27)."""
    return theta + dpsi + dtau


def mean_sidereal_time(jd, jc):
    """Mean sidereal time at Greenwich nu_0 [deg], limited to 0..360 (eq. 28)."""
    return (280.46061837 + 360.98564736629 * (jd - _J2000) + 0.000387933 * jc**2
            - jc**3 / 38710000.0) % 360.0


def apparent_sidereal_time(nu0, dpsi, epsilon):
    """Apparent sidereal time at Greenwich nu = nu_0 + Delta psi cos(epsilon) [deg] (eq. 29)."""
    return nu0 + dpsi * np.cos(np.radians(epsilon))


def geocentric_right_ascension(lamda, epsilon, beta):
    """Geocentric sun right ascension alpha [deg], 0..360 (eq. 30)."""
    lr, er, br = np.radians(lamda), np.radians(epsilon), np.radians(beta)
    return np.degrees(np.arctan2(np.sin(lr) * np.cos(er) - np.tan(br) * np.sin(er), np.cos(lr))) % 360.0


def geocentric_declination(lamda, epsilon, beta):
    """Geocentric sun declination delta [deg] (eq. 31)."""
    lr, er, br = np.radians(lamda), np.radians(epsilon), np.radians(beta)
    return np.degrees(np.arcsin(np.sin(br) * np.cos(er) + np.cos(br) * np.sin(er) * np.sin(lr)))


# ------------------------------------------------------ 3.11-3.15 topocentric
def observer_hour_angle(nu, longitude, alpha):
    """Observer local hour angle H = nu + sigma - alpha [deg], 0..360 (eq. 32).

    ``longitude`` sigma is east positive [deg].
    """
    return (nu + longitude - alpha) % 360.0


def equatorial_horizontal_parallax(R):
    """Equatorial horizontal parallax of the sun xi = 8.794/(3600 R) [deg] (eq. 33)."""
    return 8.794 / (3600.0 * R)


def u_term(latitude):
    """u = arctan(0.99664719 tan(phi)) [rad] (eq. 34); ``latitude`` phi [deg]."""
    return np.arctan(0.99664719 * np.tan(np.radians(latitude)))


def x_term(u, latitude, elevation):
    """x = cos u + E/6378140 cos(phi) [-] (eq. 35); E elevation [m]."""
    return np.cos(u) + elevation / 6378140.0 * np.cos(np.radians(latitude))


def y_term(u, latitude, elevation):
    """y = 0.99664719 sin u + E/6378140 sin(phi) [-] (eq. 36)."""
    return 0.99664719 * np.sin(u) + elevation / 6378140.0 * np.sin(np.radians(latitude))


def parallax_right_ascension(x, xi, H, delta):
    """Parallax in the sun right ascension Delta alpha [deg] (eq. 37)."""
    xir, hr, dr = np.radians(xi), np.radians(H), np.radians(delta)
    return np.degrees(np.arctan2(-x * np.sin(xir) * np.sin(hr), np.cos(dr) - x * np.sin(xir) * np.cos(hr)))


def topocentric_right_ascension(alpha, dalpha):
    """Topocentric sun right ascension alpha' = alpha + Delta alpha [deg] (eq. 38)."""
    return alpha + dalpha


def topocentric_declination(delta, x, y, xi, dalpha, H):
    """Topocentric sun declination delta' [deg] (eq. 39)."""
    dr, xir, dar, hr = np.radians(delta), np.radians(xi), np.radians(dalpha), np.radians(H)
    return np.degrees(np.arctan2((np.sin(dr) - y * np.sin(xir)) * np.cos(dar),
                                 np.cos(dr) - x * np.sin(xir) * np.cos(hr)))


def topocentric_hour_angle(H, dalpha):
    """Topocentric local hour angle H' = H - Delta alpha [deg] (eq. 40)."""
    return H - dalpha


def topocentric_elevation_without_refraction(latitude, delta_prime, H_prime):
    """Topocentric elevation angle without refraction e_0 [deg] (eq. 41)."""
    lr, dr, hr = np.radians(latitude), np.radians(delta_prime), np.radians(H_prime)
    return np.degrees(np.arcsin(np.sin(lr) * np.sin(dr) + np.cos(lr) * np.cos(dr) * np.cos(hr)))


def refraction_correction(pressure, temperature, e0, atmos_refract=ATMOS_REFRACT):
    """Atmospheric refraction correction Delta e [deg] (eq. 42).

    Delta e = (P/1010)(283/(273 + T)) 1.02 / (60 tan(e0 + 10.3/(e0 + 5.11))),
    P [mbar], T [degC], e0 [deg]; applied (as in the report's code) only while the
    sun's upper limb can be above the horizon, e0 >= -(0.26667 + atmos_refract);
    zero otherwise (never NaN).
    """
    e0 = np.asarray(e0, dtype=float)
    up = e0 >= -(SUN_RADIUS + atmos_refract)
    safe = np.where(up, e0, 10.0)
    de = (pressure / 1010.0) * (283.0 / (273.0 + temperature)) * 1.02 / (
        60.0 * np.tan(np.radians(safe + 10.3 / (safe + 5.11))))
    return np.where(up, de, 0.0)


def topocentric_elevation(e0, de):
    """Topocentric elevation angle e = e_0 + Delta e [deg] (eq. 43)."""
    return e0 + de


def topocentric_zenith(e):
    """Topocentric zenith angle theta = 90 - e [deg] (eq. 44)."""
    return 90.0 - e


def topocentric_astronomers_azimuth(H_prime, delta_prime, latitude):
    """Topocentric astronomers' azimuth Gamma, westward from south [deg], 0..360 (eq. 45)."""
    hr, dr, lr = np.radians(H_prime), np.radians(delta_prime), np.radians(latitude)
    return np.degrees(np.arctan2(np.sin(hr), np.cos(hr) * np.sin(lr) - np.tan(dr) * np.cos(lr))) % 360.0


def topocentric_azimuth(gamma):
    """Topocentric azimuth Phi = Gamma + 180, clockwise from north [deg], 0..360 (eq. 46)."""
    return (gamma + 180.0) % 360.0


def equation_of_time(jme, alpha, dpsi, epsilon):
    """Equation of time E = M - 0.0057183 - alpha + Delta psi cos(epsilon) [min] (Appendix A.1).

    M is the sun's mean longitude (eq. A2) [deg]; E is limited to +/-20 min.
    """
    m = (280.4664567 + 360007.6982779 * jme + 0.03032028 * jme**2 + jme**3 / 49931.0
         - jme**4 / 15300.0 - jme**5 / 2000000.0)
    e = (m - 0.0057183 - alpha + dpsi * np.cos(np.radians(epsilon))) * 4.0
    return (e + 720.0) % 1440.0 - 720.0


# -------------------------------------------------------------- drivers
def geocentric(jd, delta_t):
    """All geocentric quantities of one or many instants, exactly (eqs. 5-31).

    Parameters
    ----------
    jd : array_like
        Julian day [d] (UTC ~ UT1).
    delta_t : array_like
        TT - UT [s].

    Returns
    -------
    dict of numpy.ndarray
        jde, jc, jce, jme, L, B, R [AU], theta, beta, x0..x4, dpsi, deps, epsilon0
        [arc-s], epsilon, dtau, lamda, nu0, nu, alpha, delta [deg].
    """
    jd = np.asarray(jd, dtype=float)
    out = {'jd': jd}
    out['jde'] = jde = julian_ephemeris_day(jd, delta_t)
    out['jc'] = jc = julian_century(jd)
    out['jce'] = jce = julian_ephemeris_century(jde)
    out['jme'] = jme = julian_ephemeris_millennium(jce)
    out['L'] = L = heliocentric_longitude(jme)
    out['B'] = B = heliocentric_latitude(jme)
    out['R'] = R = heliocentric_radius_vector(jme)
    out['theta'] = theta = geocentric_longitude(L)
    out['beta'] = beta = geocentric_latitude(B)
    out['x0'] = mean_elongation_moon_sun(jce)
    out['x1'] = mean_anomaly_sun(jce)
    out['x2'] = mean_anomaly_moon(jce)
    out['x3'] = moon_argument_of_latitude(jce)
    out['x4'] = moon_ascending_node_longitude(jce)
    out['dpsi'], out['deps'] = dpsi, deps = nutation(jce)
    out['epsilon0'] = eps0 = mean_ecliptic_obliquity(jme)
    out['epsilon'] = eps = true_ecliptic_obliquity(eps0, deps)
    out['dtau'] = dtau = aberration_correction(R)
    out['lamda'] = lamda = apparent_sun_longitude(theta, dpsi, dtau)
    out['nu0'] = nu0 = mean_sidereal_time(jd, jc)
    out['nu'] = apparent_sidereal_time(nu0, dpsi, eps)
    out['alpha'] = geocentric_right_ascension(lamda, eps, beta)
    out['delta'] = geocentric_declination(lamda, eps, beta)
    return out


def solar_position_exact(unixtime, latitude, longitude, elevation=0.0, pressure=1013.25,
                         temperature=12.0, delta_t=None, atmos_refract=ATMOS_REFRACT):
    """The SPA evaluated literally, every equation at every instant (eqs. 4-46).

    Parameters
    ----------
    unixtime : array_like
        UTC instants [s since the Unix epoch].
    latitude, longitude : float or array_like
        Geodetic latitude phi (north +) and longitude sigma (east +) [deg].
    elevation : float
        Observer elevation E [m].
    pressure : float
        Annual mean local pressure P [mbar].
    temperature : float
        Annual mean local temperature T [degC].
    delta_t : float, array_like or None
        TT - UT [s]; None: :func:`delta_t_model`.
    atmos_refract : float
        Refraction at sunrise/sunset [deg] (switch of eq. 42).

    Returns
    -------
    dict of numpy.ndarray
        Every intermediate value of :func:`geocentric` plus H, xi, u, x, y, dalpha,
        alpha_prime, delta_prime, H_prime, e0, de, e, zenith, gamma, azimuth [deg],
        and eot [min].
    """
    t = np.asarray(unixtime, dtype=float)
    if delta_t is None:
        delta_t = delta_t_model(t)
    out = geocentric(julian_day(t), delta_t)
    out['H'] = H = observer_hour_angle(out['nu'], longitude, out['alpha'])
    out['xi'] = xi = equatorial_horizontal_parallax(out['R'])
    out['u'] = u = u_term(latitude)
    out['x'] = x = x_term(u, latitude, elevation)
    out['y'] = y = y_term(u, latitude, elevation)
    out['dalpha'] = dalpha = parallax_right_ascension(x, xi, H, out['delta'])
    out['alpha_prime'] = topocentric_right_ascension(out['alpha'], dalpha)
    out['delta_prime'] = dp = topocentric_declination(out['delta'], x, y, xi, dalpha, H)
    out['H_prime'] = hp = topocentric_hour_angle(H, dalpha)
    out['e0'] = e0 = topocentric_elevation_without_refraction(latitude, dp, hp)
    out['de'] = de = refraction_correction(pressure, temperature, e0, atmos_refract)
    out['e'] = e = topocentric_elevation(e0, de)
    out['zenith'] = topocentric_zenith(e)
    out['gamma'] = gamma = topocentric_astronomers_azimuth(hp, dp, latitude)
    out['azimuth'] = topocentric_azimuth(gamma)
    out['eot'] = equation_of_time(out['jme'], out['alpha'], out['dpsi'], out['epsilon'])
    return out


# ------------------------------------------------------------ fast path
_TWO_PI = 2.0 * np.pi
_NODE_FIELDS = 4  # sin(delta), cos(delta), sin(xi), Greenwich hour angle of the sun


def _nu0_linear(jd):
    """The part of eq. 28 linear in JD [deg] (not reduced to 0..360)."""
    return 280.46061837 + 360.98564736629 * (jd - _J2000)


def _node_values(k, delta_t):
    """Exact geocentric values at the nodes k*NODE_STEP (eqs. 5-31, 33).

    Returns sin(delta), cos(delta), sin(xi) and g = nu - alpha - nu0_lin(JD) [rad]
    (eqs. 28-30, with nu0_lin the part of eq. 28 linear in JD), so that the local hour
    angle is H = nu0_lin(JD) + g + sigma (eq. 32). g varies slowly (alpha, nutation,
    the JC^2 and JC^3 terms of eq. 28); nu0_lin is evaluated at each instant from the
    instant's own JD, exactly as eq. 28 does (float64 JD quantisation included).
    """
    tn = k * NODE_STEP
    dt = delta_t_model(tn) if delta_t is None else np.broadcast_to(np.asarray(delta_t, float), tn.shape)
    jd = julian_day(tn)
    g = geocentric(jd, dt)
    dr = np.radians(g['delta'])
    gg = np.radians((g['nu'] - g['alpha'] - _nu0_linear(jd)) % 360.0)
    return np.sin(dr), np.cos(dr), np.sin(np.radians(equatorial_horizontal_parallax(g['R']))), gg


def _slopes(v0, v1):
    """Per-interval increments of the node quantities (hour angle wrapped to +/-pi)."""
    d = [b - a for a, b in zip(v0, v1)]
    d[3] = (d[3] + np.pi) % _TWO_PI - np.pi
    return d


class GeocentricGrid:
    """Exact geocentric nodes on a contiguous range of k*NODE_STEP (fast path).

    Parameters
    ----------
    t0, t1 : float
        UTC instants [s] the grid must cover (t0 <= t <= t1).
    delta_t : float or None
        TT - UT [s] (None: :func:`delta_t_model` at each node).
    """

    def __init__(self, t0: float, t1: float, delta_t=None):
        self.k0 = float(np.floor(t0 / NODE_STEP))
        k1 = float(np.floor(t1 / NODE_STEP)) + 2.0  # one spare node: t1 may be rounded up to a node
        self.nodes = np.arange(self.k0, k1 + 1.0)
        v = _node_values(self.nodes, delta_t)
        self.values = [x[:-1].copy() for x in v]
        self.slopes = _slopes([x[:-1] for x in v], [x[1:] for x in v])

        self._site_cache = {}

    def _interp(self, t, values, slopes):
        """v_i + f d_i, with s = t/NODE_STEP - k0, i = floor(s), f = s - i.

        s - i is exact (Sterbenz), so an instant's result does not depend on where the
        grid starts: evaluate() gives bit-identical numbers for an instant in any batch.
        """
        s = np.asarray(t, dtype=float) / NODE_STEP
        s -= self.k0
        if s.size and (s.min() < 0 or s.max() >= self.values[0].size):
            raise ValueError('instant outside the geocentric grid')
        i = s.astype(np.intp)  # s >= 0: truncation is floor
        f = s - i
        out = []
        for v, d in zip(values, slopes):
            r = d[i]
            r *= f
            r += v[i]
            out.append(r)
        return out

    def covers(self, t0: float, t1: float) -> bool:
        """Whether instants t0..t1 [s] can be interpolated on this grid."""
        return (np.floor(t0 / NODE_STEP) >= self.k0
                and np.floor(t1 / NODE_STEP) - self.k0 + 1 < self.nodes.size)

    def __call__(self, t):
        """Interpolated (sin d, cos d, sin xi, g [rad]) at ``t`` (g: see :func:`_node_values`)."""
        return self._interp(t, self.values, self.slopes)

    def site_fields(self, t, x: float, y: float, lon_deg: float):
        """Interpolated observer-combined fields at ``t`` (see :func:`_site_fields`).

        The combination is linear in the node quantities, so it is applied to the
        nodes once per site (cached) instead of to every instant.
        """
        key = (x, y, lon_deg)
        if key not in self._site_cache:
            self._site_cache[key] = (_site_fields(self.values, x, y, lon_deg), _site_fields(self.slopes, x, y, 0.0))
        values, slopes = self._site_cache[key]
        return self._interp(t, values, slopes)


def _site_fields(fields, x: float, y: float, lon_deg: float):
    """(cos d, x sin xi, sin d - y sin xi, (g + sigma)/2 [rad]) from (sin d, cos d, sin xi, g).

    x, y: the observer terms of eqs. 35-36; sigma: the longitude. With them the local
    hour angle is H = nu0_lin(JD) + g + sigma (eq. 32) and the topocentric vector of
    :func:`_topocentric_fast` is (cos d cos H - x sin xi, cos d sin H, sin d - y sin xi).
    """
    sd, cd, sx, g = fields
    return [cd, x * sx, sd - y * sx, 0.5 * g + np.radians(lon_deg) * 0.5]


def _interpolated_geocentric(t, delta_t):
    """Interpolated geocentric quantities at instants ``t`` (see :class:`GeocentricGrid`).

    Dense batches use one contiguous node range; sparse ones (e.g. random instants
    over decades) only the two nodes around each instant. Both give the same number
    for the same instant, since the nodes are absolute (k*NODE_STEP).
    """
    n = t.size
    if n == 0:
        return [t.copy() for _ in range(_NODE_FIELDS)]
    kmin, kmax = np.floor(t.min() / NODE_STEP), np.floor(t.max() / NODE_STEP)
    if np.ndim(delta_t) == 0 and kmax - kmin + 2 <= 2 * n + 2:
        return GeocentricGrid(float(t.min()), float(t.max()), delta_t)(t)
    s = t / NODE_STEP
    k = np.floor(s)
    f = s - k
    if np.ndim(delta_t) != 0:
        delta_t = np.concatenate([np.broadcast_to(np.asarray(delta_t, float), t.shape)] * 2)
    v = _node_values(np.concatenate([k, k + 1.0]), delta_t)
    v0, v1 = [x[:n] for x in v], [x[n:] for x in v]
    return [a + f * d for a, d in zip(v0, _slopes(v0, v1))]


def _observer_terms(lat_deg, elevation):
    u = u_term(lat_deg)
    return x_term(u, lat_deg, elevation), y_term(u, lat_deg, elevation)


#: instants per block of the fast path (the block's temporaries stay in the CPU cache)
CHUNK = 8192


def _topocentric_fast(t, lat_deg, lon_deg, elevation, pressure, temperature, delta_t,
                      atmos_refract=ATMOS_REFRACT, collector_azimuth=0.0, grid=None, projections=True):
    """Fast path: e0, zenith, azimuth, theta_t, theta_l [rad] at instants ``t``.

    Evaluated in blocks of :data:`CHUNK` instants (about twice as fast on long arrays:
    the ~40 temporaries of a block stay in the cache). See :func:`_topocentric_block`.
    """
    t = np.asarray(t, dtype=float)
    if t.size <= 2 * CHUNK:
        return _topocentric_block(t, lat_deg, lon_deg, elevation, pressure, temperature, delta_t,
                                  atmos_refract, collector_azimuth, grid, projections)
    if grid is None and np.ndim(delta_t) == 0:
        kmin, kmax = np.floor(t.min() / NODE_STEP), np.floor(t.max() / NODE_STEP)
        if kmax - kmin + 2 <= 2 * t.size + 2:
            grid = GeocentricGrid(float(t.min()), float(t.max()), delta_t)
    n_out = 5 if projections else 3
    outs = [np.empty(t.shape) for _ in range(n_out)]
    for i in range(0, t.size, CHUNK):
        dt_i = delta_t if np.ndim(delta_t) == 0 else np.asarray(delta_t)[i:i + CHUNK]
        _topocentric_block(t[i:i + CHUNK], lat_deg, lon_deg, elevation, pressure, temperature, dt_i,
                           atmos_refract, collector_azimuth, grid, projections,
                           out=[o[i:i + CHUNK] for o in outs])
    return tuple(outs) if projections else (*outs, None, None)


def _topocentric_block(t, lat_deg, lon_deg, elevation, pressure, temperature, delta_t,
                       atmos_refract=ATMOS_REFRACT, collector_azimuth=0.0, grid=None, projections=True,
                       out=None):
    """One block of the fast path: e0, zenith, azimuth, theta_t, theta_l [rad].

    Equations 32-46 in vector form. With H the local hour angle (eq. 32), the sun seen
    from the observer, in units of the sun's distance and in the equatorial frame
    (X to the local meridian, Y westward, Z to the pole), is
    (cos d cos H - x sin xi, cos d sin H, sin d - y sin xi): its hour angle is H'
    (eq. 40 with eq. 37) and its declination d' (eq. 39). Rotated to the horizon:
    up = sin(phi) Z + cos(phi) X, south = sin(phi) X - cos(phi) Z, west = Y, so
    e0 = atan2(up, |(south, west)|) (eq. 41) and Gamma = atan2(west, south) (eq. 45).
    sin H and cos H come from tan(H/2) (one tangent instead of two calls). Refraction
    (eq. 42) raises the vector in its vertical plane to the apparent elevation e, so
    the apparent sun vector is proportional to (horizontal components, |horizontal|
    tan e), which gives the projection angles of :mod:`sslfr_planner.geometry`.
    ``projections=False`` skips theta_t, theta_l (returned as None). ``out``: arrays
    (e0, zenith, azimuth[, theta_t, theta_l]) to write the results into.
    """
    x, y = _observer_terms(lat_deg, elevation)
    if grid is None:
        cd, xsx, Z, half_g = _site_fields(_interpolated_geocentric(t, delta_t), x, y, lon_deg)
    else:
        cd, xsx, Z, half_g = grid.site_fields(t, x, y, lon_deg)
    h = _nu0_linear(julian_day(t))          # eq. 28 from the instant's JD [deg]
    h *= np.pi / 360.0
    h += half_g                             # H/2 [rad] (eq. 32)
    th = np.tan(h)
    t2 = th * th
    den = t2 + 1.0
    np.divide(cd, den, out=den)             # cos d / (1 + tan^2(H/2))
    X = 1.0 - t2
    X *= den
    X -= xsx                                # cos d cos H - x sin xi
    Y = th
    Y *= 2.0
    Y *= den                                # cos d sin H
    # Z = sin d - y sin xi (interpolated directly)
    phi = np.radians(lat_deg)
    sphi, cphi = np.sin(phi), np.cos(phi)
    up = sphi * Z
    up += cphi * X
    south = sphi * X
    south -= cphi * Z
    hor = south * south
    hor += Y * Y
    np.sqrt(hor, out=hor)
    e0 = np.arctan2(up, hor, out=None if out is None else out[0])
    # refraction, eq. 42 (e0 in degrees inside), zero below -(0.26667 + atmos_refract) deg;
    # in radians: tan(e0 + (10.3 pi/180) / (e0 180/pi + 5.11))
    safe = np.maximum(e0, -2.0 * np.pi / 180.0)
    arg = safe * (180.0 / np.pi)
    arg += 5.11
    np.divide(10.3 * np.pi / 180.0, arg, out=arg)
    arg += safe
    de = np.tan(arg)
    np.divide(pressure / 1010.0 * 283.0 / (273.0 + temperature) * 1.02 / 60.0 * np.pi / 180.0, de, out=de)
    de *= e0 >= np.radians(-(SUN_RADIUS + atmos_refract))
    e = e0 + de                             # eq. 43
    zenith = np.subtract(np.pi / 2, e, out=None if out is None else out[1])  # eq. 44
    Y_neg = -Y
    az = np.arctan2(Y_neg, south, out=None if out is None else out[2])  # -Gamma (eq. 45)
    np.subtract(np.pi, az, out=az)          # eq. 46: Gamma + 180 deg, in [0, 2 pi)
    if not projections:
        return e0, zenith, az, None, None
    if collector_azimuth:
        cg, sg = np.cos(collector_azimuth), np.sin(collector_azimuth)
        trans = Y * cg - south * sg  # along the collector's transversal +x ("west") axis
        longi = south * cg + Y * sg  # along the collector's +p ("south") axis
    else:
        trans, longi = Y, south
    # the apparent sun vector is (trans, longi, hor tan e) up to the factor cos e > 0
    vert = np.tan(e)
    vert *= hor
    return (e0, zenith, az, np.arctan2(trans, vert, out=None if out is None else out[3]),
            np.arctan2(longi, vert, out=None if out is None else out[4]))


@dataclass
class SunAngles:
    """Topocentric sun position at an array of instants (radians).

    Attributes
    ----------
    zenith : numpy.ndarray
        Topocentric zenith angle with refraction [rad] (eq. 44).
    azimuth : numpy.ndarray
        Azimuth clockwise from north (east +), 0..2 pi [rad] (eq. 46).
    elevation_geometric : numpy.ndarray
        Topocentric elevation without refraction e_0 [rad] (eq. 41).
    transversal, longitudinal : numpy.ndarray
        Projection angles theta_t (west / afternoon +) and theta_l (toward the
        collector's south end +) [rad] (seed 000 eqs. 9-10, seed 004 eqs. 1-2) for
        the collector azimuth given to :func:`sun_position`.
    """
    zenith: np.ndarray
    azimuth: np.ndarray
    elevation_geometric: np.ndarray
    transversal: np.ndarray
    longitudinal: np.ndarray


def sun_position(t, site, exact: bool = False, collector_azimuth: float = 0.0,
                 grid: GeocentricGrid | None = None) -> SunAngles:
    """Sun position for a :class:`~sslfr_planner.site.Site` at UTC instants (radians).

    Parameters
    ----------
    t : array_like
        UTC instants [s since the Unix epoch].
    site : Site
        Latitude/longitude [rad], elevation [m], pressure [Pa], temperature [degC],
        delta T [s] (None: :func:`delta_t_model`).
    exact : bool
        True: every SPA equation at every instant (reference path); False: the
        interpolated geocentric fast path (module docstring; < 1e-7 deg apart).
    collector_azimuth : float
        Azimuth of the collector axis, clockwise from north [rad] (0: north-south).
    grid : GeocentricGrid, optional
        Precomputed nodes covering ``t`` (fast path only; built from ``site.delta_t``).

    Returns
    -------
    SunAngles
    """
    from .geometry import projection_angles  # late import: geometry imports nothing from here

    t = np.atleast_1d(np.asarray(t, dtype=float))
    lat, lon = np.degrees(site.latitude), np.degrees(site.longitude)
    p_mbar = site.pressure / 100.0
    if exact:
        r = solar_position_exact(t, lat, lon, site.elevation, p_mbar, site.temperature, site.delta_t)
        zen, az = np.radians(r['zenith']), np.radians(r['azimuth'])
        tt, tl = projection_angles(zen, az, collector_azimuth)
        return SunAngles(zen, az, np.radians(r['e0']), tt, tl)
    e0, zen, az, tt, tl = _topocentric_fast(t, lat, lon, site.elevation, p_mbar, site.temperature,
                                            site.delta_t, collector_azimuth=collector_azimuth, grid=grid)
    return SunAngles(zen, az, e0, tt, tl)


def solar_position(unixtime, latitude, longitude, elevation=0.0, pressure=1013.25, temperature=12.0,
                   delta_t=None, atmos_refract=ATMOS_REFRACT, exact=False):
    """Zenith and azimuth [deg] in the report's units (a pvlib-like entry point).

    Parameters as :func:`solar_position_exact` (latitude and longitude scalars for the
    fast path). Returns (zenith, azimuth, e0) [deg].
    """
    t = np.atleast_1d(np.asarray(unixtime, dtype=float))
    if exact:
        r = solar_position_exact(t, latitude, longitude, elevation, pressure, temperature, delta_t,
                                 atmos_refract)
        return r['zenith'], r['azimuth'], r['e0']
    e0, zen, az, _, _ = _topocentric_fast(t, float(latitude), float(longitude), elevation, pressure,
                                          temperature, delta_t, atmos_refract, projections=False)
    return np.degrees(zen), np.degrees(az), np.degrees(e0)
