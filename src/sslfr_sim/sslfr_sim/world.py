"""Physical models behind the simulated sensor boards (pure Python, no rclpy).

* :class:`Sky` - sun position and clear-sky beam irradiance for a site, from the
  same models as the rest of the system: the planner's NREL SPA
  (``sslfr_planner.spa``; transversal angle as seed 000 eq. 9) and
  ``sslfr_planner.analysis.beam.clear_sky_dni`` (Ineichen-Perez with the Linke turbidity
  climatology), tabulated per day at one-minute nodes and interpolated.
* :class:`GpsReceiver` - a u-blox-like receiver emitting RMC, GGA, GSA and GSV each
  second: position noise (first-order Gauss-Markov), satellites, fix loss and
  re-acquisition, and a clock offset to provoke time jumps.
* :class:`AbsorberThermal` - inlet and outlet temperatures of the absorber tube:
  a lumped heat balance heated by the power the mirror field focuses on the tube
  (seed 000 eqs. 17-24 through ``sslfr_planner.analysis.optics.transversal_capture``, so a
  mirror tracking error or stowed mirrors cut the heating), cooled by the fluid flow
  and by losses to ambient.

Units: SI, angles in radians, temperatures in degC (as the boards report them), times
in seconds since the Unix epoch (UTC).
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass

import numpy as np

from sslfr_drivers.sensors import nmea


# ----------------------------------------------------------------------- sky
@dataclass(frozen=True)
class SunState:
    """Sun at one instant. zenith (apparent), azimuth (clockwise from north),
    transversal theta_t (seed 000 eq. 9, west/afternoon positive) [rad]."""

    zenith: float
    azimuth: float
    transversal: float

    @property
    def above_horizon(self) -> bool:
        """True when the apparent zenith is below pi/2 [rad]."""
        return self.zenith < math.pi / 2


class Sky:
    """Sun and clear-sky beam irradiance at a site, with a cloud factor.

    The sun comes from the planner's NREL SPA (``sslfr_planner.spa.sun_position``,
    the ephemeris of the whole system) and the beam from
    ``sslfr_planner.analysis.beam.clear_sky_dni``; both are evaluated for a whole UTC day at
    one-minute nodes in one vectorised call (~10 ms) and interpolated linearly (the
    azimuth through its sine and cosine), so a simulator tick costs microseconds.
    Interpolation error: < 0.01 deg in zenith, 0 outside the minute around midnight
    solar time where theta_t wraps (the sun is below the horizon there).

    Parameters
    ----------
    latitude_deg, longitude_deg : float
        [deg].
    elevation : float
        [m].
    """

    #: per (site, UTC day): minute nodes of zenith, sin/cos azimuth, theta_t, DNI
    _tables: dict[tuple, dict] = {}

    def __init__(self, latitude_deg: float, longitude_deg: float, elevation: float = 0.0):
        self.latitude_deg = latitude_deg
        self.longitude_deg = longitude_deg
        self.elevation = elevation
        self.cloud_factor = 1.0   #: multiplies DNI (1 clear, 0 overcast) [-]

    def _table(self, day: int) -> dict:
        key = (self.latitude_deg, self.longitude_deg, self.elevation, day)
        tab = self._tables.get(key)
        if tab is None:
            from sslfr_planner.analysis.beam import clear_sky_dni
            from sslfr_planner.site import Site
            from sslfr_planner.spa import sun_position as spa
            t = day * 86400.0 + 60.0 * np.arange(1441)
            site = Site(math.radians(self.latitude_deg), math.radians(self.longitude_deg),
                        self.elevation)
            sp = spa(t, site)
            with np.errstate(divide='ignore', invalid='ignore'):  # night: zenith > 90 deg
                dni = clear_sky_dni(t, sp.zenith, self.latitude_deg, self.longitude_deg,
                                    self.elevation)
            tab = {'zenith': np.asarray(sp.zenith, float), 'sin_az': np.sin(sp.azimuth),
                   'cos_az': np.cos(sp.azimuth), 'tt': np.asarray(sp.transversal, float),
                   'dni': np.asarray(dni, float)}
            if len(self._tables) > 64:
                self._tables.clear()
            self._tables[key] = tab
        return tab

    def _at(self, utc: float):
        day = math.floor(utc / 86400.0)
        x = (utc - day * 86400.0) / 60.0
        i = min(int(x), 1439)
        return self._table(day), i, x - i

    def prepare(self, utc: float) -> None:
        """Build the day's table now (the simulators call it before opening their
        pty, so the first ticks do not stall on the model imports)."""
        self._at(utc)

    def sun(self, utc: float) -> SunState:
        """Sun position at ``utc`` [s since epoch]."""
        tab, i, f = self._at(utc)

        def lerp(name):
            v = tab[name]
            return float(v[i] + (v[i + 1] - v[i]) * f)
        tt0, tt1 = tab['tt'][i], tab['tt'][i + 1]
        tt = float(tt0 + (tt1 - tt0) * f) if abs(tt1 - tt0) < 1.0 else float(tt0)
        az = math.atan2(lerp('sin_az'), lerp('cos_az')) % (2 * math.pi)
        return SunState(lerp('zenith'), az, tt)

    def dni(self, utc: float) -> float:
        """Beam normal irradiance [W/m^2] (clear sky x ``cloud_factor``), >= 0."""
        tab, i, f = self._at(utc)
        v = tab['dni']
        return max(0.0, float(v[i] + (v[i + 1] - v[i]) * f) * self.cloud_factor)


# ----------------------------------------------------------------------- GPS
M_PER_DEG_LAT = 111_320.0


class GpsReceiver:
    """Simulated NMEA receiver (one epoch of sentences per call of :meth:`epoch`).

    Parameters
    ----------
    latitude_deg, longitude_deg : float
        True antenna position [deg].
    altitude : float
        Height above mean sea level [m] (GGA altitude).
    geoid_separation : float
        Geoid height above the ellipsoid [m] (GGA separation).
    noise : float
        1-sigma horizontal position noise [m] (Gauss-Markov, 30 s correlation time).
    satellites : int
        Satellites used while fixed.
    hdop : float
        Horizontal dilution of precision while fixed [-].
    ttff : float
        Time to first fix after start and after a loss ends [s].
    seed : int
        Random seed (reproducible noise).
    """

    def __init__(self, latitude_deg: float, longitude_deg: float, altitude: float = 0.0,
                 geoid_separation: float = 50.0, noise: float = 2.0, satellites: int = 8,
                 hdop: float = 1.1, ttff: float = 2.0, seed: int = 1, talker: str = 'GP'):
        self.latitude_deg = latitude_deg
        self.longitude_deg = longitude_deg
        self.altitude = altitude
        self.geoid_separation = geoid_separation
        self.noise = noise
        self.satellites = satellites
        self.hdop = hdop
        self.ttff = ttff
        self.talker = talker
        self.clock_offset = 0.0   #: added to the reported UTC [s] (wrong date/time tests)
        self.blocked = False      #: True: sky blocked, the fix is lost
        self._rng = random.Random(seed)
        self._en = [0.0, 0.0]
        self._last: float | None = None
        self._acquire_at: float | None = None

    def fixed(self, utc: float) -> bool:
        """Whether the receiver has a fix at ``utc`` (updates acquisition state)."""
        if self.blocked:
            self._acquire_at = None
            return False
        if self._acquire_at is None:
            self._acquire_at = utc + self.ttff
        return utc >= self._acquire_at

    def epoch(self, utc: float) -> bytes:
        """The sentences of one 1 Hz epoch at true time ``utc`` [s]: RMC, GGA, GSA, GSV."""
        dt = 1.0 if self._last is None else max(0.0, min(60.0, utc - self._last))
        self._last = utc
        a = math.exp(-dt / 30.0)
        s = self.noise * math.sqrt(max(0.0, 1.0 - a * a))
        self._en = [a * e + self._rng.gauss(0.0, s) for e in self._en]
        fixed = self.fixed(utc)
        rep = utc + self.clock_offset
        t = self.talker
        if not fixed:
            nsat = self._rng.randint(0, 3)
            return (nmea.format_rmc(rep, math.nan, math.nan, False, talker=t)
                    + nmea.format_gga(rep, math.nan, math.nan, 0.0, 0, nsat, 99.99, talker=t)
                    + nmea.format_gsa(1, [], 99.99, 99.99, 99.99, talker=t)
                    + self._gsv(nsat))
        lat = self.latitude_deg + self._en[1] / M_PER_DEG_LAT
        lon = self.longitude_deg + self._en[0] / (M_PER_DEG_LAT * max(0.01, math.cos(math.radians(self.latitude_deg))))
        alt = self.altitude + 1.5 * self._en[0]
        hdop = max(0.5, self.hdop + self._rng.gauss(0.0, 0.05))
        prns = [2, 5, 7, 9, 13, 15, 18, 20, 24, 28, 30, 32][:self.satellites]
        return (nmea.format_rmc(rep, lat, lon, True, talker=t)
                + nmea.format_gga(rep, lat, lon, alt, 1, self.satellites, hdop,
                                  self.geoid_separation, talker=t)
                + nmea.format_gsa(3, prns, 1.8 * hdop, hdop, 1.4 * hdop, talker=t)
                + self._gsv(self.satellites))

    def _gsv(self, n: int) -> bytes:
        n = max(0, min(4, n))
        sats = ''.join(f',{p:02d},{40 + 5 * i:02d},{(60 * i) % 360:03d},{35 + i:02d}'
                       for i, p in enumerate([2, 5, 7, 9][:n]))
        return nmea.sentence(f'{self.talker}GSV,1,1,{n:02d}{sats}')


# ------------------------------------------------------------------- thermal
@dataclass
class ThermalParameters:
    """Lumped absorber model (assumed values for the prototype of seed 000).

    Attributes
    ----------
    heat_capacity : float
        Tube + fluid inside it [J/K].
    loss_coefficient : float
        U*A, losses to ambient [W/K].
    flow_capacity : float
        m_dot * c_p of the fluid [W/K] (0 = stagnation: the tube heats until losses
        balance the focused power, far above 150 degC on a clear day).
    optical_efficiency : float
        rho * CI_m * CI_g * tau * alpha_b (seed 000 Table 3: 0.94*0.96*0.96*0.86*0.95).
    ambient : float
        Ambient and fluid inlet temperature [degC].
    cavity_half_aperture : float
        Half width of the secondary reflector's aperture [m] (assumed 0.1 m): a
        reflected beam whose centre is displaced by 2 epsilon f misses the cavity in
        proportion (1 - (2 epsilon f / w)^2).
    """

    heat_capacity: float = 6000.0
    loss_coefficient: float = 8.0
    flow_capacity: float = 20.0
    optical_efficiency: float = 0.94 * 0.96 * 0.96 * 0.86 * 0.95
    ambient: float = 25.0
    cavity_half_aperture: float = 0.1


class AbsorberThermal:
    """Inlet / outlet temperatures of the absorber tube [degC].

    Heat balance of the tube (explicit Euler, sub-stepped)::

        C dT/dt = P_abs - UA (T - T_amb) - m c_p (T - T_in)

    with T_out = T the tube/outlet temperature and T_in = T_amb + (T - T_amb) * 0.1
    (the inlet thermocouple sits at the cold end, warmed a little by conduction).
    P_abs = DNI * L_M * sum_i C_i(epsilon) * eta_opt, C_i from seed 000 eqs. 17-24
    (``sslfr_planner.analysis.optics.transversal_capture``) for the mirror tracking error
    epsilon = beta_0,ideal - beta_0,measured (eq. 17), times the cavity acceptance of
    :class:`ThermalParameters`; mirrors far from focus (e.g. the sleeping position)
    catch nothing.
    """

    def __init__(self, params: ThermalParameters | None = None, optics=None):
        self.p = params or ThermalParameters()
        self.temperature = self.p.ambient
        self.power = 0.0
        from sslfr_planner.analysis.optics import OpticalParameters
        # the field and receiver: seed 000's prototype unless given (a described
        # collector's: sslfr_planner.analysis.ideal.optical_parameters)
        self._optics = optics or OpticalParameters()

    def focused_power(self, dni: float, transversal: float, mirror_angle: float | None) -> float:
        """Power reaching the tube [W] for DNI [W/m^2], theta_t [rad] (in the frame of the
        tilted rows, ``sslfr_planner.raytrace.transversal_angle``) and the measured
        central-mirror angle beta_0 [rad] (None: perfectly tracked, beta_0 = theta_t/2)."""
        if dni <= 0.0 or not math.isfinite(dni) or abs(transversal) >= math.pi / 2:
            return 0.0
        from sslfr_planner.analysis.optics import transversal_capture
        error = 0.0 if mirror_angle is None or not math.isfinite(mirror_angle) \
            else transversal / 2.0 - mirror_angle
        # the seed's model sends every missed ray into the cavity (rho_rc); a beam moved
        # by 2 epsilon f beyond the secondary reflector's half aperture misses it too
        shift = 2.0 * abs(error) * self._optics.geometry.receiver_height / self.p.cavity_half_aperture
        if shift >= 1.0:
            return 0.0
        caught = float(transversal_capture(transversal, self._optics, error=error).sum())
        return (dni * self._optics.geometry.mirror_length * caught * self.p.optical_efficiency
                * (1.0 - shift * shift))

    def step(self, dt: float, power: float) -> None:
        """Advance by ``dt`` [s] with absorbed ``power`` [W]."""
        p = self.p
        self.power = power
        n = max(1, int(math.ceil(dt / 5.0)))
        h = dt / n
        for _ in range(n):
            t_in = self.inlet
            q = power - p.loss_coefficient * (self.temperature - p.ambient) \
                - p.flow_capacity * (self.temperature - t_in)
            self.temperature += h * q / p.heat_capacity

    @property
    def outlet(self) -> float:
        """Outlet thermocouple [degC]."""
        return self.temperature

    @property
    def inlet(self) -> float:
        """Inlet thermocouple [degC]."""
        return self.p.ambient + 0.1 * (self.temperature - self.p.ambient)


class GustyWind:
    """Wind speed at the anemometer: a mean plus turbulence (SI units, board seconds).

    An Ornstein-Uhlenbeck process around ``mean`` [m/s] with time scale ``tau`` [s]
    and standard deviation ``intensity * mean`` (turbulence intensity 0.2, the order
    of open country; its 3 s gusts over 10 min reach about 1.5 x the mean, the usual
    gust factor), clipped at 0. ``step(dt)`` advances it; ``speed`` is the value now.
    """

    def __init__(self, mean: float, rng, intensity: float = 0.2, tau: float = 3.0):
        self.mean = float(mean)
        self.intensity = float(intensity)
        self.tau = float(tau)
        self.rng = rng
        self._dev = 0.0
        self.speed = max(0.0, self.mean)

    def step(self, dt: float) -> float:
        """Advance by ``dt`` [s]; returns the wind speed [m/s]."""
        if dt > 0:
            a = math.exp(-dt / self.tau)
            sigma = self.intensity * self.mean
            self._dev = a * self._dev + sigma * math.sqrt(1.0 - a * a) * self.rng.gauss(0.0, 1.0)
        self.speed = max(0.0, self.mean + self._dev)
        return self.speed
