"""Per-instant tracker table: sun, incidence angles, phase and axis commands.

:func:`evaluate` gives, for any array of UTC instants, the sun (SPA fast path), the
projection angles, the day-cycle phase of seed 000 section 4 and what each axis is
commanded to in that phase; :func:`tabulate_day` is the same on a whole UTC day grid
(the seed's per-second "database", section 4.1). Pure numpy, deterministic: an
instant gets the same numbers whatever batch it is evaluated in, to the last bits of
numpy's vectorised math (< 1e-12 rad; the SPA nodes and the sunrise/sunset search
grid are aligned on absolute multiples of 600 s, so the same nodes serve it).

Day cycle (phase codes = sslfr_interfaces/TrackerPhase):

* TRACKING (2): the sun is up (e_0 above h0, :mod:`events`). mobile_structure /
  secondary_reflector = the collector's longitudinal law (:mod:`laws`); mirrors =
  beta_0 = theta_t'/2, seed 000 eq. 13 with the transversal angle measured in the
  plane perpendicular to the tilted rows (:func:`raytrace.central_mirror_tilt`;
  theta_t/2 when the rows are horizontal), or the common drive of the collector
  description's mirror law (:mod:`mirror_laws`: seed 004 eq. 5, seed 003 eqs. 5-6);
  all clipped to the mechanical ranges.
  With ``collector.tracking_step`` > 0 the commands are those of the middle of the
  current step interval (kept inside [sunrise, sunset]): seed 003's 15-min steps.
* PRE_DAWN (1): less than ``pre_dawn_lead`` before the next sunrise: the initial
  position, i.e. the TRACKING commands at the sunrise instant (seed 000 section 4.2;
  evaluated :data:`RISE_EPSILON` after it, clear of the refraction switch).
* STOWING (3): less than ``stow_duration`` after the last sunset: mirrors to the
  sleeping position (section 4.4); longitudinal axes as at NIGHT.
* NIGHT (0): mirrors sleeping (+pi/2); the longitudinal axes at their rest position
  under the moving laws ('continuous', 'eq16'), at their (fixed / day's) value under
  the other laws.

If a night is shorter than pre_dawn_lead + stow_duration, PRE_DAWN wins.
Polar day: TRACKING all day; polar night: NIGHT all day.
"""
from __future__ import annotations

import datetime
import math
from dataclasses import dataclass

import numpy as np

from sslfr_common.contract import JOINTS, Phase

from . import laws, prototype, raytrace, spa
from .collector import MOVING_LAWS, Collector
from .description import FIXED_TILT
from .events import SCAN_STEP, SunEvents, crossings, events_around, events_from_crossings, solar_transit
from .site import Site

#: the PRE_DAWN initial position is the TRACKING command this long after sunrise [s]
RISE_EPSILON = 0.01


@dataclass
class TrackingTable:
    """Per-instant table (numpy arrays of equal length, one element per instant).

    Attributes
    ----------
    t : numpy.ndarray
        UTC instants [s since the Unix epoch].
    phase : numpy.ndarray of uint8
        TrackerPhase code (NIGHT=0, PRE_DAWN=1, TRACKING=2, STOWING=3).
    zenith, azimuth : numpy.ndarray
        Topocentric sun zenith (with refraction) and azimuth clockwise from north [rad].
    transversal, longitudinal : numpy.ndarray
        theta_t (afternoon +) and theta_l (+p, south end +) [rad].
    mirrors, mobile_structure, secondary_reflector : numpy.ndarray
        Commanded axis angles beta_0, beta_M, beta_a [rad].
    events : SunEvents
        Events of the solar day of the table (tabulate_day) or of the middle instant.
    """
    t: np.ndarray
    phase: np.ndarray
    zenith: np.ndarray
    azimuth: np.ndarray
    transversal: np.ndarray
    longitudinal: np.ndarray
    mirrors: np.ndarray
    mobile_structure: np.ndarray
    secondary_reflector: np.ndarray
    events: SunEvents

    def __len__(self) -> int:
        return int(self.t.size)


def _local_day_index(t, site: Site):
    """Integer local-mean-solar date of each instant (days since the epoch)."""
    return np.floor((np.asarray(t, dtype=float) + math.degrees(site.longitude) * 240.0) / 86400.0)


def _declination_at_noons(t, site: Site, collector: Collector):
    """Declination at the solar noon of each instant's local date [rad] ('daily' law)."""
    days = _local_day_index(t, site)
    dmin, dmax = float(days.min()), float(days.max())
    if dmax - dmin < 16:  # a few days: no sort needed
        uniq = np.arange(dmin, dmax + 1.0)
        inv = (days - dmin).astype(np.intp)
    else:
        uniq, inv = np.unique(days, return_inverse=True)
    decl = np.empty(uniq.size)
    for n, d in enumerate(uniq):
        anchor = d * 86400.0 + 43200.0 - math.degrees(site.longitude) * 240.0
        noon = solar_transit(anchor, site)
        dt = spa.delta_t_model(noon) if site.delta_t is None else site.delta_t
        decl[n] = math.radians(float(spa.geocentric(spa.julian_day(np.array([noon])), dt)['delta'][0]))
    return decl[inv.reshape(-1)]


def _commands(zenith, azimuth, t, site: Site, c: Collector):
    """TRACKING commands (beta_0, beta_M, beta_a) [rad] from the sun at instants t.

    beta_0 = theta_t' / 2 (seed 000 eq. 13 in the frame of the tilted rows,
    :func:`sslfr_planner.raytrace.central_mirror_tilt`): the mirrors turn about the
    rows, so with the structure tilted by beta_M they follow the sun's angle in the
    plane perpendicular to the tilted rows; for beta_M = 0 it is theta_t / 2.
    """
    sun = raytrace.sun_vector(zenith, azimuth, c.azimuth)
    bm, ba = _longitudinal(zenith, azimuth, t, site, c, sun)
    if c.mirror_law == 'half_transversal':
        drive = raytrace.central_mirror_tilt(sun, bm)
    else:   # the description's common-drive law (seed 004 eq. 5, seed 003 eqs. 5-6)
        drive, _ = prototype.commanded_lines(c.description, raytrace.transversal_angle(sun, bm))
    mirrors = np.clip(drive, c.mirror_min, c.mirror_max)
    return mirrors, bm, ba


def _longitudinal(zenith, azimuth, t, site: Site, c: Collector, sun=None):
    """(beta_M, beta_a) [rad] of the collector's law at instants ``t`` (clipped to tilt_max).

    A described collector without a secondary_reflector movement keeps its receiver at
    :data:`~sslfr_planner.description.FIXED_TILT` (horizontal) whatever the law.

    ``zenith`` and ``azimuth`` [rad] are the sun's at ``t``; ``sun`` its unit vector in
    the collector frame if already computed.
    """
    n = np.shape(t)
    if c.law == 'continuous':
        if sun is None:
            sun = raytrace.sun_vector(zenith, azimuth, c.azimuth)
        bm, ba = laws.continuous(sun, c.geometry)
    elif c.law == 'eq16':
        bm, ba = laws.eq16(zenith, site.latitude, c.azimuth)
    elif c.law == 'optimum_fixed':
        m, a = laws.optimum_fixed(site.latitude, c.azimuth)
        bm, ba = np.full(n, m), np.full(n, a)
    elif c.law == 'horizontal':
        bm, ba = np.zeros(n), np.zeros(n)
    else:  # daily
        bm, ba = laws.daily(site.latitude, _declination_at_noons(t, site, c), c.azimuth)
    if c.description is not None and c.description.receiver_fixed:
        ba = np.full(n, FIXED_TILT)     # a receiver the collector does not move (docs/collectors.md)
    return np.clip(bm, -c.tilt_max, c.tilt_max), np.clip(ba, -c.tilt_max, c.tilt_max)


def _resting(t, site: Site, c: Collector):
    """Longitudinal commands (beta_M, beta_a) at NIGHT / STOWING [rad] (module docstring)."""
    if c.law in MOVING_LAWS:
        return np.full(np.shape(t), c.structure_rest), np.full(np.shape(t), c.reflector_rest)
    return _longitudinal(np.zeros(np.shape(t)), np.zeros(np.shape(t)), t, site, c)


#: public names of the law helpers (used by the planner node and the analysis tools)
tracking_commands = _commands
longitudinal_commands = _longitudinal
resting_commands = _resting


def evaluate(t, site: Site, collector: Collector, events: SunEvents | None = None) -> TrackingTable:
    """The per-instant table at UTC instants ``t`` (module docstring for the phases).

    Parameters
    ----------
    t : array_like
        UTC instants [s since the Unix epoch], any order, any spacing.
    site : Site
    collector : Collector
    events : SunEvents, optional
        Stored in the result as its ``events`` (e.g. the planner's events of the
        day); computed for the local date of the middle instant if None. The phases
        are always derived from the sunrise/sunset crossings around the instants
        themselves (same algorithm as :func:`events.sun_events`), so they are
        right across midnight and day boundaries.

    Returns
    -------
    TrackingTable
    """
    t = np.atleast_1d(np.asarray(t, dtype=float)).ravel()
    if t.size == 0:
        raise ValueError('evaluate needs at least one instant')
    if not np.all(np.isfinite(t)):
        raise ValueError('instants must be finite numbers of seconds')
    if t.size > 1 and not np.all(t[1:] >= t[:-1]):  # evaluate in time order, return in the given order
        order = np.argsort(t, kind='stable')
        tab = evaluate(t[order], site, collector, events)
        back = np.empty_like(order)
        back[order] = np.arange(order.size)
        cols = {name: getattr(tab, name)[back] for name in _COLUMNS}
        return TrackingTable(events=tab.events, **cols)
    c = collector
    lo = float(t[0]) - max(c.stow_duration, c.tracking_step) - 2 * SCAN_STEP
    hi = float(t[-1]) + max(c.pre_dawn_lead, c.tracking_step) + 2 * SCAN_STEP
    if (hi - lo) / spa.NODE_STEP > 2 * t.size + 300:  # sparse instants over a long span
        return _evaluate_sparse(t, site, c, events)
    grid = spa.GeocentricGrid(lo, hi, site.delta_t)
    sun = spa.sun_position(t, site, collector_azimuth=c.azimuth, grid=grid)

    # --- day cycle: segments of t between consecutive sunrise/sunset crossings
    ct, rising, up0 = crossings(lo, hi, site, grid)
    b = np.searchsorted(t, ct, side='left')          # first instant at/after each crossing
    starts = np.concatenate([[0], b])
    ends = np.concatenate([b, [t.size]])
    phase = np.full(t.size, Phase.NIGHT, dtype=np.uint8)
    mirrors = np.full(t.size, c.sleeping)
    bm, ba = _resting(t, site, c)
    track_slices, pre_dawn = [], []
    for j in range(ct.size + 1):
        i0, i1 = int(starts[j]), int(ends[j])
        if i1 <= i0:
            continue
        if up0 ^ (j % 2 == 1):
            phase[i0:i1] = Phase.TRACKING
            track_slices.append((j, i0, i1))
            continue
        if j > 0 and not rising[j - 1] and c.stow_duration > 0:      # after a sunset
            k = min(int(np.searchsorted(t, ct[j - 1] + c.stow_duration, side='left')), i1)
            phase[i0:k] = Phase.STOWING
        if j < ct.size and rising[j] and c.pre_dawn_lead > 0:         # before a sunrise
            k = max(int(np.searchsorted(t, ct[j] - c.pre_dawn_lead, side='left')), i0)
            if k < i1:
                phase[k:i1] = Phase.PRE_DAWN
                pre_dawn.append((j, k, i1))

    # --- commands while TRACKING
    for j, i0, i1 in track_slices:
        if c.tracking_step > 0:
            tt = t[i0:i1]
            sample = np.floor(tt / c.tracking_step) * c.tracking_step + c.tracking_step / 2.0
            lo_j = ct[j - 1] + RISE_EPSILON if j > 0 else -np.inf
            hi_j = ct[j] if j < ct.size else np.inf
            sample = np.clip(sample, lo_j, hi_j)
            us, inv = np.unique(sample, return_inverse=True)
            s_sun = spa.sun_position(us, site, collector_azimuth=c.azimuth, grid=grid)
            m, b1, b2 = _commands(s_sun.zenith, s_sun.azimuth, us, site, c)
            inv = inv.reshape(-1)
            mirrors[i0:i1], bm[i0:i1], ba[i0:i1] = m[inv], b1[inv], b2[inv]
        else:
            m, b1, b2 = _commands(sun.zenith[i0:i1], sun.azimuth[i0:i1], t[i0:i1], site, c)
            mirrors[i0:i1], bm[i0:i1], ba[i0:i1] = m, b1, b2
    # --- PRE_DAWN: the commands of the sunrise instant (10 ms after the crossing: e_0 is
    # then 4e-5 deg above h0, clear of the refraction switch of eq. 42)
    if pre_dawn:
        rises = np.array([ct[j] for j, _, _ in pre_dawn]) + RISE_EPSILON
        r_sun = spa.sun_position(rises, site, collector_azimuth=c.azimuth, grid=grid)
        m, b1, b2 = _commands(r_sun.zenith, r_sun.azimuth, rises, site, c)
        for n, (_, i0, i1) in enumerate(pre_dawn):
            mirrors[i0:i1], bm[i0:i1], ba[i0:i1] = m[n], b1[n], b2[n]

    if events is None:  # the local day of the middle instant (= sun_events of that date)
        mid = float(t[t.size // 2])
        day = _local_day_index(mid, site)
        noon = solar_transit(float(day) * 86400.0 + 43200.0 - math.degrees(site.longitude) * 240.0, site, grid)
        if lo <= noon - 43200.0 and noon + 43200.0 <= hi:
            events = events_from_crossings(noon, ct, rising, site, grid)
        else:
            events = events_around(noon, site)
    return TrackingTable(t, phase, sun.zenith, sun.azimuth, sun.transversal, sun.longitudinal,
                    mirrors, bm, ba, events)


_COLUMNS = ('t', 'phase', 'zenith', 'azimuth', 'transversal', 'longitudinal', *JOINTS)


def _evaluate_sparse(t, site: Site, c: Collector, events):
    """evaluate() for instants spread over a long span: one dense evaluation per instant."""
    parts = [evaluate(np.array([x]), site, c, events) for x in t]
    cat = {name: np.concatenate([getattr(p, name) for p in parts]) for name in _COLUMNS}
    return TrackingTable(events=parts[len(parts) // 2].events, **cat)


def day_grid(day: datetime.date, step: float = 1.0) -> np.ndarray:
    """Instants of the UTC day [00:00, 24:00) of ``day`` every ``step`` seconds [s]."""
    if not (isinstance(step, (int, float)) and math.isfinite(step) and 0 < step <= 86400):
        raise ValueError(f'step must be in (0, 86400] s, got {step!r}')
    start = datetime.datetime(day.year, day.month, day.day, tzinfo=datetime.timezone.utc).timestamp()
    n = int(math.ceil(86400.0 / step - 1e-9))
    return start + np.arange(n) * float(step)


def tabulate_day(day: datetime.date, site: Site, collector: Collector, step: float = 1.0) -> TrackingTable:
    """The whole UTC day of ``day`` every ``step`` seconds: ``evaluate(day_grid(day, step))``.

    ``events`` of the result are those of ``day`` (:func:`events.sun_events`; for
    |longitude| < 180 deg the middle instant's local date is ``day``).
    """
    t = day_grid(day, step)
    if abs(math.degrees(site.longitude)) < 179.0:
        return evaluate(t, site, collector)
    from .events import sun_events
    return evaluate(t, site, collector, sun_events(day, site))
