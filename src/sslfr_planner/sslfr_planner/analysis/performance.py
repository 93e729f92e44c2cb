"""Performance analysis of an SSLFR (pure numpy, no rclpy): what the seeds judge a
tracker by.

* :func:`error_table`: power loss per mirror and in total caused by a tracking error
  (seed 000 section 5.2, eqs. 17-24; the table behind its Figs. 22-24).
* :func:`annual_energy`: energy absorbed over a year (seed 000 eq. 25) for a
  longitudinal law, with the installation area (eqs. 27-28, seed 001 eqs. 21-25),
  the energy-to-area ratio (eq. 26), the end-loss efficiency and, with costs, the
  LCOE (eq. 29).
* :func:`tilt_search`: seed 001's brute-force search of the EAR over the two
  longitudinal tilts in [0, latitude].
* :func:`day_energy`: the energy of a recorded day from the angles actually held.

Every power comes from the 3-D trace (:mod:`sslfr_planner.raytrace` through
:mod:`.optics`); the axes follow the planner's own laws and mirror command
(:mod:`sslfr_planner.tracking_table`), so the analysis judges exactly what the tracker
commands. Sun positions: the project's NREL SPA; beam irradiance: :mod:`.beam`.
Units: SI and radians; energies in Wh unless a name says otherwise.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from datetime import date, datetime, timezone

import numpy as np

from .. import raytrace
from ..collector import LAWS, Collector, FieldGeometry
from . import optics
from .optics import OpticalParameters

#: power models of :func:`annual_energy`
MODELS = ('trace', 'eq18', 'seed001')
#: instants traced at once by :func:`annual_energy` (memory ~ 0.3 GB)
_YEAR_CHUNK = 8192


@dataclass(frozen=True)
class AnalysisSite:
    """Where the collector is: latitude/longitude [deg] (north/east +), elevation [m]."""

    latitude_deg: float
    longitude_deg: float
    elevation: float = 0.0
    collector_azimuth: float = 0.0  # [rad], azimuth of the collector axis (seed 004 eqs. 1-2)

    def __post_init__(self):
        if not -90.0 <= self.latitude_deg <= 90.0:
            raise ValueError(f'latitude {self.latitude_deg} deg outside [-90, 90]')
        if not -180.0 <= self.longitude_deg <= 180.0:
            raise ValueError(f'longitude {self.longitude_deg} deg outside [-180, 180]')


@dataclass(frozen=True)
class Costs:
    """Cost inputs of seed 000 eq. 29 (currency: whatever the user uses, e.g. EUR).

    direct_capital: DC, paid in year 1 [currency]; indirect_capital: IC, year 1;
    om_fraction: yearly O&M as a fraction of DC (seed 000: 0.005) [-];
    fuel: yearly fuel cost [currency]; lifetime: m [years]; discount_rate: r [-].
    """

    direct_capital: float
    indirect_capital: float = 0.0
    om_fraction: float = 0.005
    fuel: float = 0.0
    lifetime: int = 25
    discount_rate: float = 0.03

    def yearly(self) -> np.ndarray:
        """DC_i + IC_i + M_i + F_i for i = 1..m [currency]."""
        c = np.full(self.lifetime, self.direct_capital * self.om_fraction + self.fuel)
        c[0] += self.direct_capital + self.indirect_capital
        return c


# --- sun positions and laws ------------------------------------------------------------

def _site(site: AnalysisSite):
    from ..site import Site
    return Site.from_degrees(site.latitude_deg, site.longitude_deg, site.elevation)


def sun_positions(t, site: AnalysisSite):
    """Topocentric apparent zenith and azimuth (clockwise from north) [rad] at UTC ``t`` [s].

    The project's NREL SPA (:func:`sslfr_planner.spa.sun_position`, fast path).
    """
    from ..spa import sun_position

    pos = sun_position(np.asarray(t, dtype=float), _site(site))
    return pos.zenith, pos.azimuth


def commands(law: str, zenith, azimuth, t, site: AnalysisSite, geometry: FieldGeometry | None = None,
             receiver_fixed: bool = False):
    """The tracker's TRACKING commands (beta_0, beta_M, beta_a) [rad] and the sun vector.

    The planner's own code (:func:`sslfr_planner.tracking_table.tracking_commands`): the
    longitudinal law (``continuous``, ``eq16``, ``optimum_fixed``, ``daily``,
    ``horizontal``) and the mirrors' command in the tilted rows' frame.
    ``receiver_fixed``: the collector does not move its receiver
    (:attr:`sslfr_planner.description.Description.receiver_fixed`): beta_a is the fixed tilt.
    Returns (beta_0, beta_M, beta_a, sun (..., 3)).
    """
    from ..tracking_table import tracking_commands

    if law not in LAWS:
        raise ValueError(f'unknown law {law!r}; expected one of {", ".join(LAWS)}')
    c = Collector(law=law, azimuth=site.collector_azimuth, geometry=geometry or FieldGeometry())
    z = np.asarray(zenith, dtype=float)
    a = np.asarray(azimuth, dtype=float)
    b0, bm, ba = tracking_commands(z, a, np.asarray(t, dtype=float), _site(site), c)
    if receiver_fixed:
        from ..description import FIXED_TILT
        ba = np.full(np.shape(ba), FIXED_TILT)
    return b0, bm, ba, raytrace.sun_vector(z, a, site.collector_azimuth)


# --- seed 000 section 5.2: tracking error ------------------------------------------------

@dataclass
class ErrorRow:
    """One line of the tracking-error table: a day, an hour (solar time), an error."""

    day: date
    hour: float                  # solar time [h]
    error: float                 # tracking error epsilon [rad]
    transversal: float           # theta_t' at that instant (tilted rows' frame) [rad]
    loss_per_mirror: np.ndarray  # (Q_i - Q_i^e) / Q_i * 100 [%], order of FieldGeometry.mirror_labels
    loss_total: float            # (Q - Q^e) / Q * 100 [%] (seed 000 eq. 24)


def solar_time_instant(day: date, hour: float, site: AnalysisSite) -> float:
    """UTC instant [s] of the local apparent solar time ``hour`` [h] on ``day``.

    Solar noon is the sun's transit from the SPA (:func:`sslfr_planner.events.solar_transit`);
    the seed's 9:00/12:00/15:00 (Figs. 21-24) are solar hours, 15 deg of hour angle each.
    """
    from ..events import local_mean_noon, solar_transit

    s = _site(site)
    return solar_transit(local_mean_noon(day, s), s) + 3600.0 * (hour - 12.0)


def error_table(site: AnalysisSite, params: OpticalParameters, errors, days, hours, law: str = 'eq16',
                receiver_fixed: bool = False):
    """Power loss caused by tracking errors (seed 000 eqs. 17-24, Figs. 22-24).

    The collector follows ``law`` (seed 000's tracker: eq. 16; ``receiver_fixed``: its
    receiver does not move, :func:`commands`); the central mirror is
    held epsilon below its ideal tilt (eq. 17, every mirror the same: one drive). As in
    the seed's transversal study, l_abs and eta_opt are held constant: the tube is
    endless, so the loss of mirror i is (Q_i - Q_i^e) / Q_i from the 3-D trace.

    Parameters
    ----------
    errors : sequence of float
        Tracking errors epsilon [rad].
    days : sequence of datetime.date
    hours : sequence of float
        Local solar hours [h].

    Returns
    -------
    list of ErrorRow
        Rows with the sun below the horizon are skipped.
    """
    rows = []
    errs = np.asarray(errors, dtype=float)
    for day in days:
        for hour in hours:
            t = solar_time_instant(day, hour, site)
            zen, azi = sun_positions(np.array([t]), site)
            if zen[0] >= np.pi / 2:
                continue
            b0, bm, ba, sun = commands(law, zen, azi, np.array([t]), site, params.geometry, receiver_fixed)
            tilts = np.concatenate([b0, b0[0] - errs])
            q = optics.power(1.0, sun[0], tilts, bm[0], ba[0], params, per_mirror=True, endless=True)
            ideal, real = q[0], q[1:]
            tt = float(raytrace.transversal_angle(sun[0], bm[0]))
            for k, err in enumerate(errs):
                rows.append(ErrorRow(day, hour, float(err), tt, 100.0 * (ideal - real[k]) / ideal,
                                     float(100.0 * (ideal.sum() - real[k].sum()) / ideal.sum())))
    return rows


# --- seed 000 eqs. 25-29 and seed 001: a year ----------------------------------------------

@dataclass
class YearResult:
    """Annual figures of one longitudinal law at one site."""

    law: str
    energy_wh: float            # E (seed 000 eq. 25) [Wh]
    area_m2: float              # A (eq. 27) [m^2]
    tube: tuple[float, float]   # (L_a^r, L_a^l) used [m]
    model: str                  # 'trace', 'eq18' or 'seed001'
    endless_wh: float = 0.0     # E with an endless tube (no end losses) [Wh]
    daily_wh: np.ndarray = field(repr=False, default=None)  # energy per day [Wh]
    lcoe: float | None = None   # [currency/kWh]

    @property
    def ear(self) -> float:
        """Energy-to-area ratio E/A [Wh/m^2] (seed 000 eq. 26)."""
        return self.energy_wh / self.area_m2

    @property
    def end_loss_efficiency(self) -> float:
        """Energy with the tube's ends / energy with an endless tube [-] (seed 000 eq. 1, energy-weighted)."""
        return self.energy_wh / self.endless_wh if self.endless_wh > 0 else float('nan')


def year_instants(year: int, step: float = 600.0) -> np.ndarray:
    """UTC instants [s] covering ``year`` at ``step`` seconds, the first at 00:00 + step/2."""
    start = datetime(year, 1, 1, tzinfo=timezone.utc).timestamp()
    end = datetime(year + 1, 1, 1, tzinfo=timezone.utc).timestamp()
    return np.arange(start + step / 2.0, end, step)


@dataclass
class YearSky:
    """The sun and the beam irradiance over a year, computed once, reused per law."""

    t: np.ndarray
    zenith: np.ndarray
    azimuth: np.ndarray
    dni: np.ndarray
    step: float

    @classmethod
    def compute(cls, site: AnalysisSite, year: int = 2023, step: float = 600.0, dni=None):
        """Sun and DNI for ``year`` at ``step`` [s]; only instants with the sun up are kept.

        ``dni``: None for clear sky, or a callable ``dni(t) -> W/m^2`` (measured data).
        """
        from .beam import clear_sky_dni

        t = year_instants(year, step)
        zen, azi = sun_positions(t, site)
        up = zen < np.pi / 2
        t, zen, azi = t[up], zen[up], azi[up]
        if dni is None:
            d = clear_sky_dni(t, zen, site.latitude_deg, site.longitude_deg, site.elevation)
        else:
            d = np.asarray(dni(t), dtype=float)
        return cls(t, zen, azi, d, step)


def annual_energy(sky: YearSky, site: AnalysisSite, params: OpticalParameters, law: str,
                  model: str = 'trace', costs: Costs | None = None) -> YearResult:
    """Energy absorbed over the year by an SSLFR following ``law`` (seed 000 eq. 25) [Wh].

    ``model``: 'trace' (3-D incidence angle), 'eq18' (seed 000 eq. 18 with theta_i in
    the plane perpendicular to the rows, as the seed evaluates it) or 'seed001' (annex
    eq. 20). The tube is ``params.geometry``'s. The installation area is the largest
    footprint over the year's tilts (the installation must leave room for every
    position: for the moving laws that is the flattest position of the year).
    """
    if model not in MODELS:
        raise ValueError(f"unknown model {model!r}: one of {', '.join(MODELS)}")
    b0, bm, ba, sun = commands(law, sky.zenith, sky.azimuth, sky.t, site, params.geometry)
    q = np.zeros(sky.t.size)
    q_endless = np.zeros(sky.t.size) if model != 'seed001' else None
    for k in range(0, sky.t.size, _YEAR_CHUNK):   # bounded memory whatever the step
        sl = slice(k, k + _YEAR_CHUNK)
        if model == 'seed001':
            q[sl] = optics.power_seed001(sky.dni[sl], sun[sl], b0[sl], bm[sl], ba[sl], params)
            continue
        incidence = '3d' if model == 'trace' else 'transversal'
        tr = optics.trace(sun[sl], b0[sl], bm[sl], ba[sl], params)
        half_open = params.cavity_aperture / 2.0
        bounds = [np.minimum(tr.tube_half, half_open), half_open]
        weight = (sky.dni[sl, None] * optics.optical_yield(params)
                  * optics.incidence_factor(tr, sun[sl], bm[sl], incidence))
        rho = params.cavity_reflectivity
        d, e = raytrace.mirror_area_hitting(tr, bounds)
        q[sl] = np.sum(weight * (d + rho * (e - d)), axis=-1)
        d, e = raytrace.mirror_area_hitting(tr, bounds, tube=(-np.inf, np.inf))
        q_endless[sl] = np.sum(weight * (d + rho * (e - d)), axis=-1)
    energy = q * sky.step / 3600.0
    days = ((sky.t - sky.t[0] // 86400 * 86400) // 86400).astype(int)
    daily = np.bincount(days, weights=energy)
    area = float(np.max(optics.installation_area(np.abs(bm), np.abs(ba), params.geometry)))
    endless = float(q_endless.sum() * sky.step / 3600.0) if q_endless is not None else 0.0
    result = YearResult(law, float(energy.sum()), area, params.geometry.tube, model, endless, daily)
    if costs is not None:
        kwh = np.full(costs.lifetime, result.energy_wh / 1000.0)
        result.lcoe = optics.lcoe(costs.yearly(), kwh, costs.discount_rate)
    return result


# --- seed 001: the tube's placement and the tilt search --------------------------------------

def _tube_profile(sky: YearSky, site: AnalysisSite, params: OpticalParameters, reflected, beta_a: float,
                  density, resolution: float):
    """Energy landing on each ``resolution``-long stretch of an unbounded tube [Wh].

    Each mirror at each instant spreads its seed 001 eq. 20 power per metre of lit tube
    (``density``, W/m) uniformly over the segment its rays reach (3-D trace).
    Returns (bin centres along the tube [m], energy per bin [Wh]).
    """
    g = params.geometry
    tr = raytrace.trace(None, None, None, beta_a, g, reflected=reflected)
    lo, hi = tr.hit_segment()
    reach = 4.0 * g.mirror_length + 2.0 * g.receiver_height
    valid = tr.valid & np.isfinite(lo) & np.isfinite(hi) & (density > 0)
    lo = np.clip(lo[valid], -reach, reach)
    hi = np.clip(hi[valid], -reach, reach)
    per_metre = density[valid] * sky.step / 3600.0  # Wh per metre of lit tube
    nbins = int(round(2 * reach / resolution))
    edges_lo = np.clip(((lo + reach) / resolution).astype(int), 0, nbins)
    edges_hi = np.clip(((hi + reach) / resolution).astype(int), 0, nbins)
    diff = np.bincount(edges_lo, weights=per_metre * resolution, minlength=nbins + 1)
    diff -= np.bincount(edges_hi, weights=per_metre * resolution, minlength=nbins + 1)
    energy = np.cumsum(diff)[:nbins]
    centres = -reach + resolution * (np.arange(nbins) + 0.5)
    return centres, energy


def _seed001_rays(sky: YearSky, site: AnalysisSite, params: OpticalParameters, beta_m: float):
    """Rays of the year for a fixed structure tilt and seed 001's power per metre of lit tube.

    Returns (rays, density [W/m] per instant and mirror): DNI eta_opt IAM_i l_ci,i.
    """
    g = params.geometry
    sun = raytrace.sun_vector(sky.zenith, sky.azimuth, site.collector_azimuth)
    b0 = raytrace.central_mirror_tilt(sun, beta_m)
    reflected = raytrace.rays(sun, b0, beta_m, g)
    tr = raytrace.trace(None, None, None, beta_m, g, reflected=reflected)
    density = sky.dni[:, None] * optics.optical_yield(params) * tr.cos_incidence * optics.arc_illuminated(tr, params)
    return reflected, np.where(tr.valid, density, 0.0)


def best_tube_position(sky: YearSky, site: AnalysisSite, params: OpticalParameters,
                       beta_m: float, beta_a: float, tube_length: float | None = None,
                       resolution: float = 0.01, prepared=None):
    """Tube placement (L_a^r, L_a^l) of a given length maximising the year's energy [m].

    Replaces the optimisation algorithm of seed 001 ref. [12] (not available): the
    tube slides along its axis in ``resolution`` steps; the seed 001 model scores each
    placement; among placements within 0.1 % of the best energy the one needing the
    smallest installation area wins. Returns ((L_a^r, L_a^l), energy [Wh]).
    """
    g = params.geometry
    length = tube_length if tube_length is not None else g.tube_left - g.tube_right
    reflected, density = prepared if prepared is not None else _seed001_rays(sky, site, params, beta_m)
    centres, energy = _tube_profile(sky, site, params, reflected, beta_a, density, resolution)
    window = max(1, int(round(length / resolution)))
    csum = np.concatenate([[0.0], np.cumsum(energy)])
    totals = csum[window:] - csum[:-window]            # energy of a tube starting at bin k
    starts = centres[:totals.size] - resolution / 2.0
    near = np.flatnonzero(totals >= 0.999 * totals.max())
    rights = starts[near]
    areas = optics.installation_area(abs(beta_m), abs(beta_a), g, tube=(rights, rights + length))
    k = near[int(np.argmin(areas))]
    return (float(starts[k]), float(starts[k] + length)), float(totals[k])


@dataclass
class TiltSearch:
    """Seed 001's brute force: EAR over (beta_M, beta_a) in [0, latitude]^2."""

    beta_m: np.ndarray        # grid [rad]
    beta_a: np.ndarray        # grid [rad]
    ear: np.ndarray           # [Wh/m^2], shape (len(beta_m), len(beta_a)); NaN where A > max_area
    energy: np.ndarray        # [Wh]
    area: np.ndarray          # [m^2]
    tubes: np.ndarray         # (..., 2) placements (L_a^r, L_a^l) [m]

    @property
    def optimum(self) -> tuple[float, float]:
        """(beta_M, beta_a) of the largest EAR [rad]."""
        i, j = np.unravel_index(np.nanargmax(self.ear), self.ear.shape)
        return float(self.beta_m[i]), float(self.beta_a[j])


def tilt_search(sky: YearSky, site: AnalysisSite, params: OpticalParameters, grid: int = 11,
                max_area: float = 10.0, tube_length: float | None = None) -> TiltSearch:
    """Brute-force EAR over beta_M, beta_a in [0, |latitude|] (seed 001 section 4).

    Each pair gets its best tube placement (:func:`best_tube_position`, seed 001's
    model on the 3-D trace), its area (seed 001 eqs. 21-25) and EAR = E / A; pairs
    needing more than ``max_area`` m^2 are excluded as in the seed (10 m^2). Southern
    sites tilt toward the north.
    """
    if grid < 2:
        raise ValueError('grid must be >= 2')
    lat = abs(np.radians(site.latitude_deg))
    sign = 1.0 if site.latitude_deg >= 0 else -1.0
    bms = np.linspace(0.0, lat, grid)
    bas = np.linspace(0.0, lat, grid)
    ear = np.full((grid, grid), np.nan)
    energy = np.zeros((grid, grid))
    area = np.zeros((grid, grid))
    tubes = np.zeros((grid, grid, 2))
    for i, bm in enumerate(bms):
        prepared = _seed001_rays(sky, site, params, sign * bm)
        for j, ba in enumerate(bas):
            tube, e = best_tube_position(sky, site, params, sign * bm, sign * ba, tube_length, prepared=prepared)
            a = float(optics.installation_area(bm, ba, params.geometry, tube=tube))
            energy[i, j], area[i, j], tubes[i, j] = e, a, tube
            if a <= max_area:
                ear[i, j] = e / a
    return TiltSearch(bms, bas, ear, energy, area, tubes)


def day_energy(t, dni, zenith, azimuth, mirrors, beta_m, beta_a, params: OpticalParameters,
               collector_azimuth: float = 0.0) -> float:
    """Energy absorbed over recorded samples [Wh] (seed 000 eqs. 18, 20 and 25 on the 3-D trace).

    For a recorded day: ``mirrors`` is the central mirror's tilt actually held [rad]
    (west positive, the ``mirrors`` joint; its difference from the ideal command is the
    tracking error of every mirror, seed 000 eq. 17), ``beta_m`` and ``beta_a`` the
    longitudinal tilts held [rad]. Pass the ideal angles to get the ideal energy, the
    measured ones to get the achieved energy. Trapezoidal rule over ``t`` [s].
    """
    t = np.asarray(t, dtype=float)
    if t.size < 2:
        return 0.0
    z = np.asarray(zenith, dtype=float)
    sun = raytrace.sun_vector(z, azimuth, collector_azimuth)
    q = optics.power(np.where(z < np.pi / 2, np.asarray(dni, dtype=float), 0.0), sun,
                     np.asarray(mirrors, dtype=float), np.asarray(beta_m, dtype=float),
                     np.asarray(beta_a, dtype=float), params)
    q = np.nan_to_num(q, nan=0.0)
    return float(np.sum((q[1:] + q[:-1]) / 2.0 * np.diff(t)) / 3600.0)


def with_tube(params: OpticalParameters, tube) -> OpticalParameters:
    """``params`` with the absorber tube placed at (L_a^r, L_a^l) [m]."""
    return replace(params, geometry=optics.placed(params.geometry, tube))
