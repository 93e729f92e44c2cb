"""Observation site of the tracker (SI units, radians; no rclpy).

Latitude and longitude are radians inside the cores (REP-103); degrees appear only
at the edges (CLI, CSV, ``*_deg`` ROS parameters), through :meth:`Site.from_degrees`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Site:
    """A place on the WGS-84 ellipsoid and its mean atmosphere.

    Attributes
    ----------
    latitude : float
        Geodetic latitude [rad], north positive, |latitude| <= pi/2.
    longitude : float
        Longitude [rad], east positive, -pi..pi (wider values are accepted as given).
    elevation : float
        Height above the ellipsoid (the SPA's E) [m].
    pressure : float
        Annual mean local air pressure [Pa] (the SPA uses mbar = Pa/100; refraction).
    temperature : float
        Annual mean local air temperature [degC] (refraction).
    delta_t : float or None
        TT - UT [s]; None: the default model :func:`sslfr_planner.spa.delta_t_model`.
    """

    latitude: float
    longitude: float
    elevation: float = 0.0
    pressure: float = 101325.0
    temperature: float = 12.0
    delta_t: float | None = None

    def __post_init__(self):
        for name in ('latitude', 'longitude', 'elevation', 'pressure', 'temperature'):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f'site {name} must be a finite number, got {value!r}')
        if abs(self.latitude) > math.pi / 2 + 1e-12:
            raise ValueError(f'latitude must be within +/-90 deg, got {math.degrees(self.latitude):.6g} deg')
        if abs(self.longitude) > 2 * math.pi:
            raise ValueError(f'longitude must be within +/-360 deg, got {math.degrees(self.longitude):.6g} deg')
        if not -500.0 <= self.elevation <= 10000.0:
            raise ValueError(f'elevation must be within -500..10000 m, got {self.elevation} m')
        if not 1000.0 <= self.pressure <= 120000.0:
            raise ValueError(f'pressure must be within 1000..120000 Pa, got {self.pressure} Pa')
        if not -90.0 <= self.temperature <= 70.0:
            raise ValueError(f'temperature must be within -90..70 degC, got {self.temperature} degC')
        if self.delta_t is not None and (not math.isfinite(self.delta_t) or abs(self.delta_t) > 20000):
            raise ValueError(f'delta_t must be a finite number of seconds (|dT| <= 20000), got {self.delta_t}')

    @classmethod
    def from_degrees(cls, lat_deg: float, lon_deg: float, elevation: float = 0.0, **kw) -> 'Site':
        """Build a site from latitude and longitude in degrees (north, east positive).

        Other keyword arguments (pressure [Pa], temperature [degC], delta_t [s]) pass
        through unchanged. Raises ValueError for out-of-range values.
        """
        for name, value in (('latitude', lat_deg), ('longitude', lon_deg)):
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f'{name} must be a finite number of degrees, got {value!r}')
        if abs(lat_deg) > 90.0:
            raise ValueError(f'latitude must be within -90..90 deg, got {lat_deg} deg')
        if abs(lon_deg) > 360.0:
            raise ValueError(f'longitude must be within -360..360 deg, got {lon_deg} deg')
        return cls(math.radians(lat_deg), math.radians(lon_deg), float(elevation), **kw)

    @property
    def latitude_deg(self) -> float:
        """Latitude [deg], north positive."""
        return math.degrees(self.latitude)

    @property
    def longitude_deg(self) -> float:
        """Longitude [deg], east positive."""
        return math.degrees(self.longitude)
