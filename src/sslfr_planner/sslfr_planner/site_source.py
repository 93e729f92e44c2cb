"""Which site the planner plans for: GPS fix, persisted fix or parameters (pure).

Seed 000 Step 1.1 takes date, time, latitude and longitude from the GPS module at
dawn. The planner node follows that order of preference:

1. ``gps``: the latest *valid* ``gps/fix`` of this run (status >= STATUS_FIX, finite
   position in range, horizontal standard deviation within a bound when the
   covariance is known);
2. ``persisted``: the last valid fix written to disk by a previous run (a small JSON
   file, written atomically: temporary file in the same directory, fsync, rename);
3. ``parameters``: ``site.latitude_deg``, ``site.longitude_deg``, ``site.elevation``.

Latitude/longitude are degrees here (as in NavSatFix and the parameters, north and
east positive, WGS-84); elevation in metres. No rclpy import: the node passes the
NavSatFix fields in.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

from sslfr_common.files import atomic_write

#: sensor_msgs/NavSatStatus.STATUS_FIX and NavSatFix covariance types.
STATUS_FIX = 0
COVARIANCE_TYPE_UNKNOWN = 0

PERSIST_FILE = 'planner_site.json'
PERSIST_VERSION = 1

EARTH_RADIUS = 6_371_008.8  # mean Earth radius [m]


@dataclass(frozen=True)
class SiteFix:
    """A site position and where it came from.

    Attributes
    ----------
    latitude_deg, longitude_deg : float
        WGS-84 latitude and longitude [deg], north and east positive.
    elevation : float
        Altitude [m] (NavSatFix: above the WGS-84 ellipsoid).
    source : str
        ``'gps'``, ``'persisted'`` or ``'parameters'``.
    stamp : float
        When the fix was taken [s since the Unix epoch, UTC]; 0 for parameters.
    """

    latitude_deg: float
    longitude_deg: float
    elevation: float
    source: str
    stamp: float = 0.0

    def describe(self) -> str:
        """One line for logs: ``lat,lon elevation m (source)``."""
        return (f'{self.latitude_deg:.5f},{self.longitude_deg:.5f} {self.elevation:.0f} m '
                f'({self.source})')


def distance_m(a: SiteFix, b: SiteFix) -> float:
    """Great-circle (haversine) distance between two sites [m], elevations ignored."""
    p1, p2 = math.radians(a.latitude_deg), math.radians(b.latitude_deg)
    dp = p2 - p1
    dl = math.radians(b.longitude_deg - a.longitude_deg)
    h = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2 * EARTH_RADIUS * math.asin(min(1.0, math.sqrt(h)))


#: [m] altitudes a fix may carry (the ``site.elevation`` parameter's range).
ALTITUDE_RANGE = (-500.0, 9000.0)


def check_fix(status: int, latitude: float, longitude: float, altitude: float,
              covariance, covariance_type: int, max_horizontal_std: float) -> str | None:
    """Validate the fields of a ``sensor_msgs/NavSatFix``.

    Parameters
    ----------
    status : int
        ``status.status`` (STATUS_NO_FIX = -1, STATUS_FIX = 0, SBAS = 1, GBAS = 2).
    latitude, longitude : float
        [deg].
    altitude : float
        [m]; NaN (NavSatFix: unknown) is tolerated (the elevation then falls back,
        see :meth:`SiteSelector.on_fix`); else it must lie in :data:`ALTITUDE_RANGE`
        (the range of the ``site.elevation`` parameter): an infinite one is refused.
    covariance : sequence of 9 float
        ``position_covariance`` [m^2], row-major ENU.
    covariance_type : int
        ``position_covariance_type``; UNKNOWN (0) means no bound can be checked.
    max_horizontal_std : float
        Largest accepted horizontal standard deviation sqrt(max(c_EE, c_NN)) [m].

    Returns
    -------
    str or None
        None when the fix is usable, else the reason it is refused.
    """
    if status < STATUS_FIX:
        return f'status {status} < STATUS_FIX'
    if not (math.isfinite(latitude) and math.isfinite(longitude)):
        return 'non-finite position'
    if not (-90.0 <= latitude <= 90.0 and -180.0 <= longitude <= 180.0):
        return f'position out of range ({latitude}, {longitude})'
    if not math.isnan(altitude) and not ALTITUDE_RANGE[0] <= altitude <= ALTITUDE_RANGE[1]:
        return (f'altitude {altitude} m outside {ALTITUDE_RANGE[0]:g}..{ALTITUDE_RANGE[1]:g} m '
                '(NaN means unknown; infinite is refused)')
    if covariance_type != COVARIANCE_TYPE_UNKNOWN:
        try:
            c_ee, c_nn = float(covariance[0]), float(covariance[4])
        except (IndexError, TypeError, ValueError):
            return 'malformed covariance'
        if not (math.isfinite(c_ee) and math.isfinite(c_nn)) or c_ee < 0 or c_nn < 0:
            return 'invalid covariance'
        std = math.sqrt(max(c_ee, c_nn))
        if std > max_horizontal_std:
            return f'horizontal std {std:.1f} m > {max_horizontal_std:.1f} m'
    return None


def load_persisted(state_dir: str | os.PathLike) -> tuple[SiteFix | None, str | None]:
    """Read the persisted fix.

    Returns
    -------
    (SiteFix or None, str or None)
        The fix (``source='persisted'``) or None, and an error message when the file
        exists but cannot be used (corrupt, wrong version, values out of range).
        A missing file is not an error.
    """
    path = Path(state_dir) / PERSIST_FILE
    if not path.exists():
        return None, None
    try:
        data = json.loads(path.read_text())
        if data.get('version') != PERSIST_VERSION:
            return None, f'{path}: unknown version {data.get("version")!r}'
        lat = float(data['latitude_deg'])
        lon = float(data['longitude_deg'])
        ele = float(data['elevation'])
        stamp = float(data.get('stamp', 0.0))
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        return None, f'{path}: unreadable ({exc})'
    if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(ele)
            and -90 <= lat <= 90 and -180 <= lon <= 180):
        return None, f'{path}: values out of range'
    return SiteFix(lat, lon, ele, 'persisted', stamp), None


def save_persisted(state_dir: str | os.PathLike, fix: SiteFix) -> Path:
    """Write ``fix`` atomically (temp file + fsync + rename) and return the path.

    A crash or power cut during the write leaves either the old or the new file,
    never a truncated one. Raises OSError when the directory cannot be written.
    """
    directory = Path(state_dir)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / PERSIST_FILE
    payload = json.dumps({
        'version': PERSIST_VERSION, 'latitude_deg': fix.latitude_deg,
        'longitude_deg': fix.longitude_deg, 'elevation': fix.elevation,
        'stamp': fix.stamp, 'source': fix.source,
    }, indent=1)
    return atomic_write(path, payload + '\n')


class SiteSelector:
    """Keeps the three candidate sites and picks the one to plan for.

    Parameters
    ----------
    parameters : SiteFix
        Site from the node's parameters (``source='parameters'``).
    state_dir : str or path or None
        Directory of the persisted fix; None or '' disables persistence.
    max_horizontal_std : float
        See :func:`check_fix` [m].
    persist_min_distance : float
        A valid fix is written to disk when nothing is persisted yet or when it is
        farther than this from the persisted one [m] (GPS jitter does not wear the
        flash card).
    """

    def __init__(self, parameters: SiteFix, state_dir=None, max_horizontal_std: float = 500.0,
                 persist_min_distance: float = 50.0):
        self.parameters = parameters
        self.state_dir = str(state_dir) if state_dir else ''
        self.max_horizontal_std = max_horizontal_std
        self.persist_min_distance = persist_min_distance
        self.gps: SiteFix | None = None
        self.persisted: SiteFix | None = None
        self.errors: list[str] = []
        self.rejected = 0
        self.writes = 0
        if self.state_dir:
            self.persisted, err = load_persisted(self.state_dir)
            if err:
                self.errors.append(err)

    @classmethod
    def from_params(cls, cfg: dict, gps: SiteFix | None = None) -> 'SiteSelector':
        """The selector of the planner parameters ``site.*``, ``gps.*`` and ``state_dir``
        (``~`` expanded; '' disables persistence), keeping the GPS fix ``gps`` of
        this run if given."""
        state_dir = os.path.expanduser(cfg['state_dir']) if cfg['state_dir'] else ''
        params_site = SiteFix(cfg['site.latitude_deg'], cfg['site.longitude_deg'],
                              cfg['site.elevation'], 'parameters')
        sel = cls(params_site, state_dir, cfg['gps.max_horizontal_std'], cfg['gps.persist_min_distance'])
        sel.gps = gps
        return sel

    def on_fix(self, status, latitude, longitude, altitude, covariance, covariance_type,
               stamp: float) -> str | None:
        """Offer a NavSatFix; return None if accepted, else the reason it was refused.

        A NaN altitude keeps the previously known elevation (persisted or
        parameters). An accepted fix may be persisted (see ``persist_min_distance``);
        a failed write is recorded in :attr:`errors`, the fix is still used.
        """
        why = check_fix(status, latitude, longitude, altitude, covariance, covariance_type,
                        self.max_horizontal_std)
        if why is not None:
            self.rejected += 1
            return why
        known = self.gps or self.persisted or self.parameters
        ele = float(altitude) if math.isfinite(altitude) else known.elevation
        self.gps = SiteFix(float(latitude), float(longitude), ele, 'gps', float(stamp))
        if self.state_dir and (self.persisted is None
                               or distance_m(self.persisted, self.gps) > self.persist_min_distance
                               or abs(self.persisted.elevation - ele) > self.persist_min_distance):
            try:
                save_persisted(self.state_dir, self.gps)
                self.persisted = SiteFix(self.gps.latitude_deg, self.gps.longitude_deg,
                                         self.gps.elevation, 'persisted', self.gps.stamp)
                self.writes += 1
            except OSError as exc:
                self.errors.append(f'cannot persist site in {self.state_dir}: {exc}')
        return None

    def current(self) -> SiteFix:
        """The site to plan for: gps, else persisted, else parameters."""
        return self.gps or self.persisted or self.parameters
