"""Performance analysis of an SSLFR (pure numpy, no rclpy): what the seeds judge a
tracker by.

* :func:`error_table`: power loss per mirror and in total caused by a tracking error
  (seed 000 section 5.2, eqs. 17-24; the table behind its Figs. 22-24).
* :func:`annual_energy`: energy absorbed over a year (seed 000 eq. 25) for a
  longitudinal law, with the installation area (eqs. 27-28, seed 001 eqs. 21-25),
  the energy-to-area ratio (eq. 26) and, with costs, the LCOE (eq. 29).
* :func:`tilt_search`: seed 001's brute-force search of the EAR over the two
  longitudinal tilts in [0, latitude].

Sun positions come from the project's NREL SPA (sslfr_planner.spa via
:func:`sun_positions`), beam irradiance from sslfr_planner.beam. Units: SI and
radians; energies in Wh unless a name says otherwise.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from datetime import date, datetime, timezone

import numpy as np

from . import optics
from .optics import OpticalParameters

#: The longitudinal laws the analysis knows (seed 000 eq. 16, seed 001, classic LFR).
LAWS = ('continuous', 'optimum_fixed', 'horizontal', 'daily')


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
    from .site import Site
    return Site.from_degrees(site.latitude_deg, site.longitude_deg, site.elevation)


def sun_positions(t, site: AnalysisSite):
    """Topocentric apparent zenith and azimuth (clockwise from north) [rad] at UTC ``t`` [s].

    The project's NREL SPA (:func:`sslfr_planner.spa.sun_position`, fast path).
    """
    from .spa import sun_position

    pos = sun_position(np.asarray(t, dtype=float), _site(site))
    return pos.zenith, pos.azimuth


def longitudinal_tilts(law: str, zenith, azimuth, t, site: AnalysisSite):
    """Tilts (beta_M, beta_a) of the mobile structure and the reflector [rad].

    The planner's own laws (:mod:`sslfr_planner.laws` through the day table), so the
    analysis judges exactly what the tracker commands: ``continuous`` (seed 000
    eq. 16), ``optimum_fixed`` (seed 001 eqs. 16, 19), ``horizontal``, ``daily``.
    Signs as docs/conventions.md (positive faces the south end).
    """
    from .collector import Collector
    from .daytable import longitudinal_commands

    if law not in LAWS:
        raise ValueError(f'unknown law {law!r}; expected one of {", ".join(LAWS)}')
    _, tl = optics.projection_angles(zenith, azimuth, site.collector_azimuth)
    collector = Collector(law=law, azimuth=site.collector_azimuth)
    return longitudinal_commands(np.asarray(zenith, dtype=float), tl, np.asarray(t, dtype=float), _site(site), collector)


# --- seed 000 section 5.2: tracking error ------------------------------------------------

@dataclass
class ErrorRow:
    """One line of the tracking-error table: a day, an hour (solar time), an error."""

    day: date
    hour: float                  # solar time [h]
    error: float                 # tracking error epsilon [rad]
    transversal: float           # theta_t at that instant [rad]
    loss_per_mirror: np.ndarray  # (Q_i - Q_i^e) / Q_i * 100 [%], order of optics.mirror_labels
    loss_total: float            # (Q - Q^e) / Q * 100 [%] (seed 000 eq. 24)


def solar_time_instant(day: date, hour: float, site: AnalysisSite) -> float:
    """UTC instant [s] of the local apparent solar time ``hour`` [h] on ``day``.

    Solar noon is the sun's transit from the SPA (:func:`sslfr_planner.events.solar_transit`);
    the seed's 9:00/12:00/15:00 (Figs. 21-24) are solar hours, 15 deg of hour angle each.
    """
    from .events import local_mean_noon, solar_transit

    s = _site(site)
    return solar_transit(local_mean_noon(day, s), s) + 3600.0 * (hour - 12.0)


def error_table(site: AnalysisSite, params: OpticalParameters, errors, days, hours):
    """Power loss caused by tracking errors (seed 000 eqs. 17-24, Figs. 22-24).

    As in the seed's transversal study, l_abs, DNI and eta_opt's angle dependence are
    held constant, so the loss of mirror i is (C_i - C_i^e) / C_i with C the caught
    beam width of :func:`sslfr_planner.optics.transversal_capture`.

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
    eta = optics.optical_yield(params)
    rows = []
    for day in days:
        for hour in hours:
            t = solar_time_instant(day, hour, site)
            zen, azi = sun_positions(np.array([t]), site)
            if zen[0] >= np.pi / 2:
                continue
            tt, _ = optics.projection_angles(zen, azi, site.collector_azimuth)
            ideal = eta * optics.transversal_capture(tt, params)[0]
            for err in errors:
                real = eta * optics.transversal_capture(tt, params, error=err)[0]
                rows.append(ErrorRow(day, hour, float(err), float(tt[0]),
                                     100.0 * (ideal - real) / ideal,
                                     float(100.0 * (ideal.sum() - real.sum()) / ideal.sum())))
    return rows


# --- seed 000 eqs. 25-29 and seed 001: a year ----------------------------------------------

@dataclass
class YearResult:
    """Annual figures of one longitudinal law at one site."""

    law: str
    energy_wh: float            # E (seed 000 eq. 25) [Wh]
    area_m2: float              # A (eq. 27) [m^2]
    tube: tuple[float, float]   # (L_a^r, L_a^l) used [m]
    model: str                  # 'seed000' or 'seed001'
    daily_wh: np.ndarray = field(repr=False, default=None)  # energy per day [Wh]
    lcoe: float | None = None   # [currency/kWh]

    @property
    def ear(self) -> float:
        """Energy-to-area ratio E/A [Wh/m^2] (seed 000 eq. 26)."""
        return self.energy_wh / self.area_m2


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
                  model: str = 'seed000', costs: Costs | None = None) -> YearResult:
    """Energy absorbed over the year by an SSLFR following ``law`` (seed 000 eq. 25) [Wh].

    ``model`` selects the power model: 'seed000' (eq. 18) or 'seed001' (annex eq. 20).
    The installation area is the largest footprint over the year's tilts (the
    installation must leave room for every position: for ``continuous`` that is the
    flat position at sunrise).
    """
    bm, ba = longitudinal_tilts(law, sky.zenith, sky.azimuth, sky.t, site)
    if model == 'seed000':
        q = optics.power_seed000(sky.dni, sky.zenith, sky.azimuth, bm, ba, params,
                                 collector_azimuth=site.collector_azimuth)
    elif model == 'seed001':
        q = optics.power_seed001(sky.dni, sky.zenith, sky.azimuth, bm, ba, params,
                                 collector_azimuth=site.collector_azimuth)
    else:
        raise ValueError(f"unknown model {model!r}: 'seed000' or 'seed001'")
    energy = q * sky.step / 3600.0
    days = ((sky.t - sky.t[0] // 86400 * 86400) // 86400).astype(int)
    daily = np.bincount(days, weights=energy)
    area = float(np.max(optics.installation_area(np.abs(bm), np.abs(ba), params)))
    result = YearResult(law, float(energy.sum()), area, (params.tube_right, params.tube_left), model, daily)
    if costs is not None:
        kwh = np.full(costs.lifetime, result.energy_wh / 1000.0)
        result.lcoe = optics.lcoe(costs.yearly(), kwh, costs.discount_rate)
    return result


def _tube_profile(sky: YearSky, site: AnalysisSite, params: OpticalParameters, beta_m: float,
                  beta_a: float, density, resolution: float):
    """Energy landing on each ``resolution``-long stretch of an unbounded tube [Wh].

    Each instant spreads DNI * T(t) (W per metre of illuminated tube, seed 001 eq. 20
    without l_a) uniformly over the segment its rays hit (:func:`optics.tube_hit_position`).
    Returns (bin centres along the tube [m], energy per bin [Wh]).
    """
    _, tl = optics.projection_angles(sky.zenith, sky.azimuth, site.collector_azimuth)
    mu = optics.longitudinal_reflection_angle(tl, beta_m)
    half = params.mirror_length / 2.0
    with np.errstate(divide='ignore', invalid='ignore'):
        u1 = optics.tube_hit_position(-half, mu, beta_m, beta_a, params)
        u2 = optics.tube_hit_position(half, mu, beta_m, beta_a, params)
    reach = 4.0 * params.mirror_length + 2.0 * params.receiver_height
    valid = (np.cos(mu - beta_a) > 1e-9) & np.isfinite(u1) & np.isfinite(u2) & (density > 0)
    lo = np.clip(np.minimum(u1, u2)[valid], -reach, reach)
    hi = np.clip(np.maximum(u1, u2)[valid], -reach, reach)
    per_metre = density[valid] * sky.step / 3600.0  # Wh per metre of illuminated tube
    nbins = int(round(2 * reach / resolution))
    edges_lo = np.clip(((lo + reach) / resolution).astype(int), 0, nbins)
    edges_hi = np.clip(((hi + reach) / resolution).astype(int), 0, nbins)
    diff = np.zeros(nbins + 1)
    np.add.at(diff, edges_lo, per_metre * resolution)
    np.add.at(diff, edges_hi, -per_metre * resolution)
    energy = np.cumsum(diff)[:nbins]
    centres = -reach + resolution * (np.arange(nbins) + 0.5)
    return centres, energy


def _transversal_density(sky: YearSky, site: AnalysisSite, params: OpticalParameters, beta_m: float):
    """DNI * sum_i eta_i IAM_i l_ci: seed 001 eq. 20 per metre of illuminated tube [W/m]."""
    tt, _ = optics.projection_angles(sky.zenith, sky.azimuth, site.collector_azimuth)
    iam = optics.incidence_cosines(sky.zenith, sky.azimuth, beta_m, params, site.collector_azimuth)
    arc = optics.arc_illuminated(tt, params)
    return sky.dni * np.sum(optics.optical_yield(params) * iam * arc, axis=-1)


def best_tube_position(sky: YearSky, site: AnalysisSite, params: OpticalParameters,
                       beta_m: float, beta_a: float, tube_length: float | None = None,
                       resolution: float = 0.01, density=None):
    """Tube placement (L_a^r, L_a^l) of a given length maximising the year's energy [m].

    Replaces the optimisation algorithm of seed 001 ref. [12] (not available): the
    tube slides along its axis in ``resolution`` steps; the seed 001 model scores each
    placement; among placements within 0.1 % of the best energy the one needing the
    smallest installation area wins. Returns ((L_a^r, L_a^l), energy [Wh]).
    """
    length = tube_length if tube_length is not None else params.tube_left - params.tube_right
    if density is None:
        density = _transversal_density(sky, site, params, beta_m)
    centres, energy = _tube_profile(sky, site, params, beta_m, beta_a, density, resolution)
    window = max(1, int(round(length / resolution)))
    csum = np.concatenate([[0.0], np.cumsum(energy)])
    totals = csum[window:] - csum[:-window]            # energy of a tube starting at bin k
    starts = centres[:totals.size] - resolution / 2.0
    near = np.flatnonzero(totals >= 0.999 * totals.max())
    rights = starts[near]
    lefts = rights + length
    areas = optics.installation_area(abs(beta_m), abs(beta_a), params,
                                     tube=(rights, lefts))
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

    Each pair gets its best tube placement (:func:`best_tube_position`), its area
    (seed 001 eqs. 21-25) and EAR = E / A; pairs needing more than ``max_area`` m^2
    are excluded as in the seed (10 m^2). Southern sites tilt toward the north.
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
        density = _transversal_density(sky, site, params, sign * bm)
        for j, ba in enumerate(bas):
            tube, e = best_tube_position(sky, site, params, sign * bm, sign * ba, tube_length,
                                         density=density)
            a = float(optics.installation_area(bm, ba, params, tube=tube))
            energy[i, j], area[i, j], tubes[i, j] = e, a, tube
            if a <= max_area:
                ear[i, j] = e / a
    return TiltSearch(bms, bas, ear, energy, area, tubes)


def day_energy(t, dni, zenith, azimuth, mirrors, beta_m, beta_a, params: OpticalParameters,
               collector_azimuth: float = 0.0) -> float:
    """Energy absorbed over recorded samples [Wh] (seed 000 eqs. 18, 20 and 25).

    For a recorded day: ``mirrors`` is the central mirror's tilt actually held [rad]
    (west positive, as the ``mirrors`` joint), so the tracking error of every mirror
    is epsilon = theta_t / 2 - mirrors (all mirrors share one drive, seed 000 section
    2.4.1); ``beta_m`` and ``beta_a`` are the longitudinal tilts held [rad] in the optics
    frame. Pass the ideal angles to get the ideal energy, the measured ones to get the
    achieved energy. The power is integrated with the trapezoidal rule over ``t`` [s].
    """
    t = np.asarray(t, dtype=float)
    if t.size < 2:
        return 0.0
    z = np.asarray(zenith, dtype=float)
    tt, tl = optics.projection_angles(z, azimuth, collector_azimuth)
    error = tt / 2.0 - np.asarray(mirrors, dtype=float)
    cap = optics.transversal_capture(tt, params, error=error)
    l_abs = optics.illuminated_length(tl, np.asarray(beta_m, dtype=float), np.asarray(beta_a, dtype=float), params)
    q = np.asarray(dni, dtype=float) * np.where(z < np.pi / 2, l_abs, 0.0) * np.sum(
        optics.optical_yield(params) * cap, axis=-1)
    q = np.nan_to_num(q, nan=0.0)
    return float(np.sum((q[1:] + q[:-1]) / 2.0 * np.diff(t)) / 3600.0)
