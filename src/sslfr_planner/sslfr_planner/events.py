"""Sun events: sunrise, solar noon (transit), sunset; polar day and polar night.

Definitions (numpy, no rclpy):

* sunrise / sunset: the instants when the sun's upper limb, with the standard
  refraction, touches the horizon: the topocentric elevation WITHOUT refraction e_0
  (SPA eq. 41) crosses h0 = -(0.26667 + 0.5667) deg = -0.83337 deg, the same
  threshold below which the SPA switches refraction off (eq. 42).
* solar noon: the transit, local hour angle H = 0 (SPA eq. 32).
* the day: :func:`sun_events` takes a calendar date and returns the events of the
  local solar day whose mean noon is 12:00 - longitude/15 h UTC on that date (for
  |longitude| < 180 deg that noon lies inside the UTC day [00:00, 24:00) but for up
  to the equation of time, 16.5 min). Sunrise is the last upward crossing in the 12 h
  before the transit, sunset the first downward crossing in the 12 h after it; in
  the far east or west the sunrise or sunset can fall on the neighbouring UTC date.
* polar day / polar night: no crossing in the 24 h around the transit; the sun is
  above (below) h0 at noon: ``day_type`` says so and sunrise/sunset are None
  (no invented event). On the rare transition days near the polar circles a
  'normal' day can lack one of the two events (None).

Crossings are searched on a grid aligned on multiples of :data:`spa.NODE_STEP` since
the Unix epoch and refined by regula falsi (Illinois) to 1 ms, with the SPA fast
path; a grazing sunrise+sunset pair less than one grid step apart (sun above h0 for
less than 10 min) is not detected. Times are float seconds since the Unix epoch (UTC).
"""
from __future__ import annotations

import datetime
import math
from dataclasses import dataclass

import numpy as np

from . import spa
from .site import Site

#: elevation threshold of sunrise and sunset, e_0 [deg]
H0_DEG = -(spa.SUN_RADIUS + spa.ATMOS_REFRACT)
#: search grid step [s] (equal to the SPA node step so the grid nodes are exact)
SCAN_STEP = spa.NODE_STEP

DAY_TYPES = ('normal', 'polar_day', 'polar_night')


@dataclass(frozen=True)
class SunEvents:
    """Events of one local solar day. Times are Unix seconds (UTC), None when absent.

    Attributes
    ----------
    sunrise : float or None
    solar_noon : float
    sunset : float or None
    day_type : str
        'normal' | 'polar_day' | 'polar_night'.
    """
    sunrise: float | None
    solar_noon: float
    sunset: float | None
    day_type: str


def _e0(t, site: Site, grid: spa.GeocentricGrid):
    """Topocentric elevation without refraction e_0 [deg] (fast path on ``grid``)."""
    e0, *_ = spa._topocentric_fast(np.atleast_1d(np.asarray(t, dtype=float)), math.degrees(site.latitude),
                                   math.degrees(site.longitude), site.elevation, site.pressure / 100.0,
                                   site.temperature, site.delta_t, grid=grid, projections=False)
    return np.degrees(e0)


def crossings(t0: float, t1: float, site: Site, grid: spa.GeocentricGrid | None = None):
    """All sunrise/sunset crossings of e_0 = h0 in [t0, t1] (extended to the grid).

    Parameters
    ----------
    t0, t1 : float
        Window [s since the Unix epoch, UTC].
    site : Site
    grid : spa.GeocentricGrid, optional
        Must cover the aligned window; built if None.

    Returns
    -------
    times : numpy.ndarray
        Crossing instants, sorted [s].
    rising : numpy.ndarray of bool
        True for a sunrise (upward), False for a sunset.
    up_at_start : bool
        Whether the sun is above h0 at the first grid node (floor(t0/step)*step).
    """
    k0 = math.floor(t0 / SCAN_STEP)
    k1 = math.floor(t1 / SCAN_STEP) + 1
    if grid is None:
        grid = spa.GeocentricGrid(k0 * SCAN_STEP, k1 * SCAN_STEP, site.delta_t)
    tn = np.arange(k0, k1 + 1, dtype=float) * SCAN_STEP
    f = _e0(tn, site, grid) - H0_DEG
    up = f > 0.0
    idx = np.nonzero(up[1:] != up[:-1])[0]
    a, b = tn[idx], tn[idx + 1]
    fa, fb = f[idx], f[idx + 1]
    side = 0 * fa
    for _ in range(60):  # Illinois regula falsi, vectorised over the brackets
        if a.size == 0 or np.max(b - a) < 1e-3:
            break
        c = (a * fb - b * fa) / (fb - fa)
        c = np.where((c <= a) | (c >= b), 0.5 * (a + b), c)
        fc = _e0(c, site, grid) - H0_DEG
        left = np.sign(fc) == np.sign(fa)
        # replace the endpoint with the same sign; halve the kept one if it stays twice
        a, fa, b, fb = (np.where(left, c, a), np.where(left, fc, fa),
                        np.where(left, b, c), np.where(left, fb, fc))
        fb = np.where(left & (side == 1), fb / 2.0, fb)
        fa = np.where(~left & (side == -1), fa / 2.0, fa)
        side = np.where(left, 1, -1)
    times = 0.5 * (a + b)
    return times, ~up[idx], bool(up[0])


def hour_angle(t, site: Site, grid: spa.GeocentricGrid | None = None):
    """Local (geocentric) hour angle H, wrapped to -180..180 [deg] (SPA eq. 32)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if grid is None:
        grid = spa.GeocentricGrid(float(t.min()), float(t.max()), site.delta_t)
    g = grid(t)[3]
    h = spa._nu0_linear(spa.julian_day(t)) + np.degrees(g) + math.degrees(site.longitude)
    return (h + 180.0) % 360.0 - 180.0


def solar_transit(t_guess: float, site: Site, grid: spa.GeocentricGrid | None = None) -> float:
    """The transit (H = 0) nearest to ``t_guess`` [s, UTC], to < 1 ms (Newton on H)."""
    if grid is None or not grid.covers(t_guess - 2 * 3600.0, t_guess + 2 * 3600.0):
        grid = spa.GeocentricGrid(t_guess - 4 * 3600.0, t_guess + 4 * 3600.0, site.delta_t)
    t = float(t_guess)
    for _ in range(6):
        dt = float(hour_angle(t, site, grid)[0]) * 240.0  # H turns 360 deg per solar day
        t -= dt
        if abs(dt) < 1e-4:
            break
    return t


def local_mean_noon(day: datetime.date, site: Site) -> float:
    """12:00 - longitude/15 h UTC on ``day``: the mean noon at the site [s]."""
    midnight = datetime.datetime(day.year, day.month, day.day, tzinfo=datetime.timezone.utc).timestamp()
    return midnight + 43200.0 - math.degrees(site.longitude) * 240.0


def sun_events(day: datetime.date, site: Site) -> SunEvents:
    """Sunrise, solar noon and sunset of ``day`` at ``site`` (module docstring).

    Parameters
    ----------
    day : datetime.date
        The date (local solar day anchored at the mean noon of the site on that date).
    site : Site

    Returns
    -------
    SunEvents
        Times in Unix seconds (UTC); sunrise/sunset None on polar days and nights.
    """
    if not isinstance(day, datetime.date):
        raise TypeError(f'day must be a datetime.date, got {type(day).__name__}')
    anchor = local_mean_noon(day, site)
    grid = spa.GeocentricGrid(anchor - 13.5 * 3600.0, anchor + 13.5 * 3600.0, site.delta_t)
    noon = solar_transit(anchor, site, grid)
    return events_around(noon, site, grid)


def events_around(noon: float, site: Site, grid: spa.GeocentricGrid | None = None) -> SunEvents:
    """Events of the solar day whose transit is ``noon`` [s] (see :func:`sun_events`)."""
    times, rising, _ = crossings(noon - 43200.0, noon + 43200.0, site, grid)
    return events_from_crossings(noon, times, rising, site, grid)


def events_from_crossings(noon: float, times, rising, site: Site,
                          grid: spa.GeocentricGrid | None = None) -> SunEvents:
    """SunEvents of the transit ``noon`` from a crossing list covering noon +/- 12 h.

    ``times``/``rising`` as returned by :func:`crossings` (any window that contains
    [noon - 12 h, noon + 12 h] gives the same events: the search grid is absolute).
    """
    before = times[(times <= noon) & (times >= noon - 43200.0) & rising]
    after = times[(times > noon) & (times <= noon + 43200.0) & ~rising]
    inside = times[(times >= noon - 43200.0) & (times <= noon + 43200.0)]
    if inside.size == 0:
        if grid is None:
            grid = spa.GeocentricGrid(noon - 1.0, noon + 1.0, site.delta_t)
        above = float(_e0(noon, site, grid)[0]) > H0_DEG
        return SunEvents(None, float(noon), None, 'polar_day' if above else 'polar_night')
    return SunEvents(float(before[-1]) if before.size else None, float(noon),
                     float(after[0]) if after.size else None, 'normal')
