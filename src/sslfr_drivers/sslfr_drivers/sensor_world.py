"""Physical models behind the simulated sensor boards (pure Python, no rclpy).

* :class:`Sky` - sun position and clear-sky beam irradiance for a site.
  Sun position: seed 000 eqs. 2-6 (daily angle, declination, hour angle, altitude,
  azimuth) with solar time from UTC, longitude and Spencer's (1971) equation of time
  (the same Fourier family as eq. 3); transversal angle: seed 000 eq. 9. Accuracy is a
  few tenths of a degree, adequate for the simulators only (the planner uses SPA).
  Beam irradiance: ``sslfr_planner.beam.clear_sky_dni`` (Ineichen-Perez with the
  Linke turbidity climatology, the model the planner's analysis uses), computed for
  a whole day at a time at one-minute steps, cached and linearly interpolated.
* :class:`GpsReceiver` - a u-blox-like receiver emitting RMC, GGA, GSA and GSV each
  second: position noise (first-order Gauss-Markov), satellites, fix loss and
  re-acquisition, and a clock offset to provoke time jumps.
* :class:`AbsorberThermal` - inlet and outlet temperatures of the absorber tube:
  a lumped heat balance heated by the power the mirror field focuses on the tube
  (seed 000 eqs. 17-24 through ``sslfr_planner.optics.transversal_capture``, so a
  mirror tracking error or stowed mirrors cut the heating), cooled by the fluid flow
  and by losses to ambient.

Units: SI, angles in radians, temperatures in degC (as the boards report them), times
in seconds since the Unix epoch (UTC).
"""
from __future__ import annotations

import datetime as _dt
import math
import random
from dataclasses import dataclass

import numpy as np

from . import nmea


# ----------------------------------------------------------------------- sky
@dataclass(frozen=True)
class SunState:
    """Sun at one instant. zenith, azimuth (clockwise from north), transversal
    (seed 000 eq. 9, west/afternoon positive) [rad]."""

    zenith: float
    azimuth: float
    transversal: float

    @property
    def above_horizon(self) -> bool:
        return self.zenith < math.pi / 2


def sun_position(utc: float, latitude_deg: float, longitude_deg: float) -> SunState:
    """Approximate sun position (seed 000 eqs. 2-6 and 9).

    Parameters
    ----------
    utc : float
        [s since the Unix epoch].
    latitude_deg, longitude_deg : float
        Site [deg], north / east positive.

    Returns
    -------
    SunState
        zenith = pi/2 - alpha_S (eq. 5); azimuth from north = pi + gamma_S (eq. 6 gives
        gamma_S from south, west positive); transversal theta_t = atan(sin gamma_S /
        tan alpha_S) (eq. 9), NaN-free (the sun below the horizon still gets a value).
    """
    t = _dt.datetime.fromtimestamp(utc, tz=_dt.timezone.utc)
    nd = t.timetuple().tm_yday
    g = (nd - 1) * 2.0 * math.pi / 365.0                                     # eq. 2
    decl = (0.006918 - 0.399912 * math.cos(g) + 0.070257 * math.sin(g)       # eq. 3
            - 0.006758 * math.cos(2 * g) + 0.000907 * math.sin(2 * g)
            - 0.002697 * math.cos(3 * g) + 0.001480 * math.sin(3 * g))
    eot_min = 229.18 * (0.000075 + 0.001868 * math.cos(g) - 0.032077 * math.sin(g)
                        - 0.014615 * math.cos(2 * g) - 0.040849 * math.sin(2 * g))
    hours = t.hour + t.minute / 60.0 + (t.second + t.microsecond * 1e-6) / 3600.0
    ts = hours + longitude_deg / 15.0 + eot_min / 60.0                       # solar time
    omega = (ts - 12.0) * math.pi / 12.0                                     # eq. 4
    lat = math.radians(latitude_deg)
    sin_alt = math.sin(decl) * math.sin(lat) + math.cos(decl) * math.cos(lat) * math.cos(omega)
    alt = math.asin(max(-1.0, min(1.0, sin_alt)))                            # eq. 5
    den = math.cos(alt) * math.cos(lat)
    c = (math.sin(alt) * math.sin(lat) - math.sin(decl)) / den if abs(den) > 1e-12 else 1.0
    omega_w = math.remainder(omega, 2 * math.pi)
    gamma = math.copysign(1.0, omega_w) * math.acos(max(-1.0, min(1.0, c)))  # eq. 6
    tt = math.atan2(math.sin(gamma), math.tan(alt)) if alt > 1e-9 else math.copysign(math.pi / 2, gamma)
    if tt > math.pi / 2:                                                     # eq. 9 branch
        tt -= math.pi
    elif tt < -math.pi / 2:
        tt += math.pi
    return SunState(math.pi / 2 - alt, (math.pi + gamma) % (2 * math.pi), tt)


class Sky:
    """Sun and clear-sky beam irradiance at a site, with a cloud factor.

    Parameters
    ----------
    latitude_deg, longitude_deg : float
        [deg].
    elevation : float
        [m].
    """

    def __init__(self, latitude_deg: float, longitude_deg: float, elevation: float = 0.0):
        self.latitude_deg = latitude_deg
        self.longitude_deg = longitude_deg
        self.elevation = elevation
        self.cloud_factor = 1.0   #: multiplies DNI (1 clear, 0 overcast) [-]

    #: clear-sky DNI per (site, minute), shared by every Sky of the process [W/m^2]
    _cache: dict[tuple, float] = {}

    def sun(self, utc: float) -> SunState:
        """Sun position at ``utc`` (:func:`sun_position`)."""
        return sun_position(utc, self.latitude_deg, self.longitude_deg)

    def _dni_minute(self, minute: int) -> float:
        key = (self.latitude_deg, self.longitude_deg, self.elevation, minute)
        v = self._cache.get(key)
        if v is None:
            # one vectorised model call for the whole UTC day (1441 minutes): a cache
            # miss costs ~10 ms once per simulated day, not once per simulated minute
            from sslfr_planner.beam import clear_sky_dni
            day0 = (minute // 1440) * 1440
            minutes = range(day0, day0 + 1441)
            ts = [m_ * 60.0 for m_ in minutes]
            zen = [self.sun(t).zenith for t in ts]
            with np.errstate(divide='ignore', invalid='ignore'):  # night: zenith > 90 deg
                dni = clear_sky_dni(ts, zen, self.latitude_deg, self.longitude_deg, self.elevation)
            if len(self._cache) > 20000:
                self._cache.clear()
            for m_, d in zip(minutes, dni):
                self._cache[(self.latitude_deg, self.longitude_deg, self.elevation, m_)] = float(d)
            v = self._cache[key]
        return v

    def prepare(self, utc: float) -> None:
        """Load the irradiance model and fill the cache for the day of ``utc`` now
        (the simulators call it before opening their pty, so no tick stalls later)."""
        self.dni(utc)

    def dni(self, utc: float) -> float:
        """Beam normal irradiance [W/m^2] (clear sky x ``cloud_factor``), >= 0."""
        m = math.floor(utc / 60.0)
        a, b = self._dni_minute(m), self._dni_minute(m + 1)
        frac = utc / 60.0 - m
        return max(0.0, (a + (b - a) * frac) * self.cloud_factor)


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
    (``sslfr_planner.optics.transversal_capture``) for the mirror tracking error
    epsilon = beta_0,ideal - beta_0,measured (eq. 17), times the cavity acceptance of
    :class:`ThermalParameters`; mirrors far from focus (e.g. the sleeping position)
    catch nothing.
    """

    def __init__(self, params: ThermalParameters | None = None):
        self.p = params or ThermalParameters()
        self.temperature = self.p.ambient
        self.power = 0.0
        from sslfr_planner.optics import OpticalParameters
        self._optics = OpticalParameters()

    def focused_power(self, dni: float, transversal: float, mirror_angle: float | None) -> float:
        """Power reaching the tube [W] for DNI [W/m^2], theta_t [rad] and the measured
        central-mirror angle beta_0 [rad] (None: perfectly tracked, beta_0 = theta_t/2)."""
        if dni <= 0.0 or not math.isfinite(dni) or abs(transversal) >= math.pi / 2:
            return 0.0
        from sslfr_planner.optics import transversal_capture
        error = 0.0 if mirror_angle is None or not math.isfinite(mirror_angle) \
            else transversal / 2.0 - mirror_angle
        # the seed's model sends every missed ray into the cavity (rho_rc); a beam moved
        # by 2 epsilon f beyond the secondary reflector's half aperture misses it too
        shift = 2.0 * abs(error) * self._optics.receiver_height / self.p.cavity_half_aperture
        if shift >= 1.0:
            return 0.0
        caught = float(transversal_capture(transversal, self._optics, error=error).sum())
        return (dni * self._optics.mirror_length * caught * self.p.optical_efficiency
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
