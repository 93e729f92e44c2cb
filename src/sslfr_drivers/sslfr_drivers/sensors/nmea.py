"""NMEA 0183 stream handling for the GPS board (pure Python, no rclpy).

The GPS PCB of seed 000 section 3.5.2 (a u-blox NEO-6M "GY-GPS6MV2" behind an
Arduino Mini Pro) delivers NMEA 0183 sentences, either as raw bytes on its own serial
port or wrapped in board-protocol chunks behind the XBee link. Either way the bytes
arrive here in arbitrary chunks: :class:`NmeaStream` reassembles sentences, checks
them, parses them with pynmeagps and turns GGA + GSA + RMC into

* :class:`FixRecord` - one per GGA sentence: position, status and service following
  the conventions of ROS ``nmea_navsat_driver`` (quality 0 -> STATUS_NO_FIX, 1 -> FIX,
  2 -> SBAS_FIX, 4/5/9 -> GBAS_FIX; altitude above the WGS-84 ellipsoid = MSL altitude +
  geoid separation), and a diagonal position covariance from the dilutions of
  precision and a receiver error model (:class:`ReceiverErrorModel`). A no-fix GGA is a
  no-fix record: latitude, longitude and altitude are NaN, never a stale position.
* :class:`TimeRecord` - one per RMC sentence that carries both a date and a time: the
  UTC instant as float seconds since the Unix epoch (date + time of day, never the time
  of day alone), with the RMC validity flag and a time-jump flag.

Everything the stream drops is counted in :class:`NmeaCounters` (bad checksums,
truncated sentences, garbage bytes, sentences pynmeagps could not parse).

Units: latitude / longitude [deg] (as sensor_msgs/NavSatFix), altitude [m],
covariance [m^2], times [s since the Unix epoch, UTC].
"""
from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass, field

from pynmeagps import NMEAReader
from pynmeagps.exceptions import NMEAMessageError, NMEAParseError, NMEATypeError

# sensor_msgs/NavSatStatus and NavSatFix constants (duplicated so this core stays
# free of ROS imports; the node asserts they match the message definitions).
STATUS_NO_FIX = -1
STATUS_FIX = 0
STATUS_SBAS_FIX = 1
STATUS_GBAS_FIX = 2
SERVICE_GPS = 1
COVARIANCE_TYPE_UNKNOWN = 0
COVARIANCE_TYPE_APPROXIMATED = 1

#: Longest sentence accepted [characters between '$' and CR LF inclusive]. NMEA 0183
#: allows 82; u-blox proprietary sentences are longer, so be a little lenient.
MAX_SENTENCE = 120


@dataclass(frozen=True)
class ReceiverErrorModel:
    """User-equivalent range error (UERE) model turning DOPs into covariance.

    sigma_east = sigma_north = hdop * uere_h, sigma_up = vdop * uere_v (or
    2 * hdop * uere_v when no GSA has given a VDOP, as nmea_navsat_driver does).
    The per-quality UERE [m] defaults are nmea_navsat_driver's ``epe_quality*``
    values (quality 1: 4.0 m, 2: 0.1 m, 4: 0.02 m, 5: 4.0 m, 9: 3.0 m) scaled by
    ``uere_scale``.

    Attributes
    ----------
    uere : dict[int, float]
        GGA quality indicator -> UERE [m].
    uere_scale : float
        Multiplier applied to every UERE [-].
    vertical_factor : float
        uere_v / uere_h [-] (vertical errors of GPS are larger).
    """

    uere: dict = field(default_factory=lambda: {1: 4.0, 2: 0.1, 4: 0.02, 5: 4.0, 9: 3.0})
    uere_scale: float = 1.0
    vertical_factor: float = 1.0

    def covariance(self, quality: int, hdop: float, vdop: float | None) -> list[float]:
        """Row-major 3x3 ENU position covariance [m^2] for a fix.

        Parameters
        ----------
        quality : int
            GGA quality indicator (1 GPS, 2 DGPS/SBAS, 4 RTK fixed, 5 RTK float, 9 WAAS).
        hdop : float
            Horizontal dilution of precision [-].
        vdop : float or None
            Vertical dilution of precision [-] from GSA, None if unknown.

        Returns
        -------
        list of 9 float
            diag(sigma_e^2, sigma_n^2, sigma_u^2), off-diagonals zero.
        """
        uere = self.uere.get(quality, self.uere.get(1, 4.0)) * self.uere_scale
        sh = hdop * uere
        sv = (vdop if vdop is not None and vdop > 0 else 2.0 * hdop) * uere * self.vertical_factor
        return [sh * sh, 0.0, 0.0, 0.0, sh * sh, 0.0, 0.0, 0.0, sv * sv]


_QUALITY_STATUS = {1: STATUS_FIX, 2: STATUS_SBAS_FIX, 4: STATUS_GBAS_FIX,
                   5: STATUS_GBAS_FIX, 9: STATUS_GBAS_FIX}


@dataclass
class FixRecord:
    """One position fix (or explicit no-fix) from a GGA sentence.

    Attributes
    ----------
    received : float
        Receive time of the sentence's last byte [s], in the caller's clock.
    utc : float
        UTC of the fix [s since epoch] if a date is known from RMC, else NaN.
    status : int
        NavSatStatus status (STATUS_NO_FIX = -1 .. STATUS_GBAS_FIX = 2).
    service : int
        NavSatStatus service bit mask (SERVICE_GPS).
    latitude, longitude : float
        [deg], north / east positive; NaN for no fix.
    altitude : float
        Height above the WGS-84 ellipsoid [m] (MSL altitude + geoid separation); NaN
        for no fix or when the receiver gave no altitude.
    covariance : list of 9 float
        ENU position covariance [m^2], row major.
    covariance_type : int
        COVARIANCE_TYPE_APPROXIMATED for fixes, COVARIANCE_TYPE_UNKNOWN for no fix.
    quality, satellites : int
        GGA quality indicator and satellites used.
    hdop, vdop : float
        Dilutions of precision [-] (vdop NaN until a GSA arrived).
    nav_mode : int
        GSA fix mode (1 none, 2 2-D, 3 3-D), 0 if no GSA seen yet.
    """

    received: float
    utc: float
    status: int
    service: int
    latitude: float
    longitude: float
    altitude: float
    covariance: list
    covariance_type: int
    quality: int
    satellites: int
    hdop: float
    vdop: float
    nav_mode: int

    @property
    def has_fix(self) -> bool:
        """True when the record carries a position."""
        return self.status >= STATUS_FIX


@dataclass
class TimeRecord:
    """UTC from an RMC sentence (date + time of day).

    Attributes
    ----------
    received : float
        Receive time of the sentence's last byte [s], caller's clock.
    utc : float
        The receiver's UTC [s since the Unix epoch].
    valid : bool
        RMC status 'A' (the receiver has a fix and trusts its clock).
    jump : float
        Step of (utc - received) against the previous RMC [s]; 0.0 for the first one.
        A large value means the receiver's clock (or ours) jumped.
    """

    received: float
    utc: float
    valid: bool
    jump: float = 0.0


@dataclass
class NmeaCounters:
    """What the stream saw and dropped (all counts since creation)."""

    sentences: int = 0          #: sentences with a good checksum
    parsed: int = 0             #: ... that pynmeagps parsed
    bad_checksum: int = 0       #: checksum present but wrong
    truncated: int = 0          #: interrupted by a new '$', too long, or no '*hh'
    garbage_bytes: int = 0      #: bytes outside any sentence (not CR/LF/space)
    parse_errors: int = 0       #: good checksum but pynmeagps refused the content
    unsupported: int = 0        #: parsed sentence types this module ignores
    fixes: int = 0              #: FixRecords produced (including no-fix records)
    no_fix: int = 0             #: ... of which no-fix
    times: int = 0              #: TimeRecords produced
    time_jumps: int = 0         #: TimeRecords whose |jump| exceeded the threshold

    def as_dict(self) -> dict[str, int]:
        """The counters as a plain dict (for diagnostics)."""
        return dict(self.__dict__)


def checksum(body: str | bytes) -> int:
    """XOR of the characters between '$' and '*' (NMEA 0183 checksum)."""
    if isinstance(body, str):
        body = body.encode('ascii', 'replace')
    value = 0
    for b in body:
        value ^= b
    return value


def _utc_seconds(date: _dt.date, tod: _dt.time) -> float:
    return _dt.datetime.combine(date, tod, tzinfo=_dt.timezone.utc).timestamp()


def _num(value, default=math.nan) -> float:
    if value is None or value == '':
        return default
    try:
        return float(value)
    except (TypeError, ValueError):
        return default


class NmeaStream:
    """Stateful NMEA 0183 decoder fed with arbitrary byte chunks.

    Parameters
    ----------
    error_model : ReceiverErrorModel, optional
        Converts HDOP/VDOP to covariance.
    time_jump_threshold : float
        |step| of (receiver UTC - receive time) between consecutive RMCs above which a
        TimeRecord is flagged as a jump [s].

    Examples
    --------
    >>> s = NmeaStream()
    >>> recs = s.feed(b'$GPRMC,120000.00,A,3650.0000,N,00224.0000,W,0.0,0.0,210326,,,A*')
    >>> recs   # sentence not complete yet
    []
    """

    def __init__(self, error_model: ReceiverErrorModel | None = None,
                 time_jump_threshold: float = 2.0):
        self.error_model = error_model or ReceiverErrorModel()
        self.time_jump_threshold = float(time_jump_threshold)
        self.counters = NmeaCounters()
        self._buf = bytearray()
        self._in_sentence = False
        self._date: _dt.date | None = None
        self._vdop: float | None = None
        self._nav_mode = 0
        self._last_offset: float | None = None
        self._last_rmc_utc: float | None = None

    # -- byte level -------------------------------------------------------------
    def feed(self, data: bytes, received: float = math.nan) -> list:
        """Consume a chunk of bytes; return the records completed by it.

        Parameters
        ----------
        data : bytes
            Any chunk of the receiver's byte stream (may split sentences anywhere).
        received : float
            Time the chunk arrived [s] (any clock; copied into the records).

        Returns
        -------
        list of FixRecord and TimeRecord, in stream order.
        """
        out: list = []
        for byte in bytes(data):
            if byte in (0x24, 0x21):  # '$' or '!': start of a sentence
                if self._in_sentence and self._buf:
                    self.counters.truncated += 1
                self._buf = bytearray((byte,))
                self._in_sentence = True
            elif byte in (0x0A, 0x0D):  # LF / CR ends a sentence
                if self._in_sentence:
                    self._in_sentence = False
                    rec = self._sentence(bytes(self._buf), received)
                    self._buf.clear()
                    if rec is not None:
                        out.append(rec)
            elif self._in_sentence:
                if 0x20 <= byte < 0x7F:
                    self._buf.append(byte)
                    if len(self._buf) > MAX_SENTENCE:
                        self.counters.truncated += 1
                        self._buf.clear()
                        self._in_sentence = False
                else:  # binary noise inside a sentence: the sentence is lost
                    self.counters.truncated += 1
                    self.counters.garbage_bytes += 1
                    self._buf.clear()
                    self._in_sentence = False
            elif byte not in (0x20, 0x09, 0x00):
                self.counters.garbage_bytes += 1
        return out

    def _sentence(self, raw: bytes, received: float):
        star = raw.rfind(b'*')
        if star < 0 or len(raw) - star != 3 or star < 6:
            self.counters.truncated += 1
            return None
        try:
            given = int(raw[star + 1:], 16)
        except ValueError:
            self.counters.truncated += 1
            return None
        if given != checksum(raw[1:star]):
            self.counters.bad_checksum += 1
            return None
        self.counters.sentences += 1
        try:
            msg = NMEAReader.parse(raw + b'\r\n', validate=1)
        except (NMEAParseError, NMEAMessageError, NMEATypeError, ValueError, TypeError,
                IndexError, KeyError, AttributeError):
            self.counters.parse_errors += 1
            return None
        if msg is None:
            self.counters.parse_errors += 1
            return None
        self.counters.parsed += 1
        try:
            return self._message(msg, received)
        except (ValueError, TypeError, AttributeError, OverflowError):
            self.counters.parse_errors += 1
            return None

    # -- sentence level ---------------------------------------------------------
    def _message(self, msg, received: float):
        mid = getattr(msg, 'msgID', '')
        if mid == 'GGA':
            return self._gga(msg, received)
        if mid == 'RMC':
            return self._rmc(msg, received)
        if mid == 'GSA':
            vdop = _num(getattr(msg, 'VDOP', ''))
            self._vdop = vdop if math.isfinite(vdop) and vdop > 0 else None
            mode = getattr(msg, 'navMode', 0)
            self._nav_mode = int(mode) if mode not in ('', None) else 0
            return None
        self.counters.unsupported += 1
        return None

    def _gga(self, msg, received: float) -> FixRecord:
        quality = getattr(msg, 'quality', 0)
        quality = int(quality) if quality not in ('', None) else 0
        sats = getattr(msg, 'numSV', 0)
        sats = int(sats) if sats not in ('', None) else 0
        hdop = _num(getattr(msg, 'HDOP', ''))
        lat = _num(getattr(msg, 'lat', ''))
        lon = _num(getattr(msg, 'lon', ''))
        tod = getattr(msg, 'time', '')
        utc = math.nan
        if isinstance(tod, _dt.time) and self._date is not None:
            utc = _utc_seconds(self._date, tod)
            if self._last_rmc_utc is not None and abs(utc - self._last_rmc_utc) > 43200.0:
                # GGA after midnight, date still from the previous day's RMC (or before)
                utc -= math.copysign(86400.0, utc - self._last_rmc_utc)
        status = _QUALITY_STATUS.get(quality, STATUS_NO_FIX)
        if (status == STATUS_NO_FIX or not math.isfinite(lat) or not math.isfinite(lon)
                or not math.isfinite(hdop)):
            self.counters.fixes += 1
            self.counters.no_fix += 1
            return FixRecord(received, utc, STATUS_NO_FIX, SERVICE_GPS, math.nan, math.nan,
                             math.nan, [0.0] * 9, COVARIANCE_TYPE_UNKNOWN, quality, sats,
                             hdop, math.nan, self._nav_mode)
        alt = _num(getattr(msg, 'alt', ''))
        sep = _num(getattr(msg, 'sep', ''), 0.0)
        altitude = alt + sep if math.isfinite(alt) else math.nan
        vdop = self._vdop
        cov = self.error_model.covariance(quality, hdop, vdop)
        if self._nav_mode == 2:  # 2-D fix: the altitude is not measured
            altitude = math.nan if not math.isfinite(alt) else altitude
            cov[8] = max(cov[8], 1.0e6)
        self.counters.fixes += 1
        return FixRecord(received, utc, status, SERVICE_GPS, lat, lon, altitude, cov,
                         COVARIANCE_TYPE_APPROXIMATED, quality, sats, hdop,
                         vdop if vdop is not None else math.nan, self._nav_mode)

    def _rmc(self, msg, received: float):
        date = getattr(msg, 'date', '')
        tod = getattr(msg, 'time', '')
        if not isinstance(date, _dt.date) or not isinstance(tod, _dt.time):
            return None  # no date or no time: not a time reference
        self._date = date
        utc = _utc_seconds(date, tod)
        self._last_rmc_utc = utc
        jump = 0.0
        if math.isfinite(received):
            offset = utc - received
            if self._last_offset is not None:
                jump = offset - self._last_offset
            self._last_offset = offset
        if abs(jump) > self.time_jump_threshold:
            self.counters.time_jumps += 1
        self.counters.times += 1
        return TimeRecord(received, utc, getattr(msg, 'status', 'V') == 'A', jump)


# -- sentence formatting (used by the simulated GPS board) ------------------------
def _ddmm(value: float, degree_digits: int) -> tuple[str, bool]:
    neg = value < 0
    value = abs(value)
    deg = int(value)
    minutes = (value - deg) * 60.0
    if round(minutes, 5) >= 60.0:
        deg += 1
        minutes = 0.0
    return f'{deg:0{degree_digits}d}{minutes:08.5f}', neg


def sentence(body: str) -> bytes:
    """Wrap ``body`` (without '$') as ``$body*hh\\r\\n`` with its checksum."""
    return f'${body}*{checksum(body):02X}\r\n'.encode('ascii')


def _hms(utc: float) -> str:
    t = _dt.datetime.fromtimestamp(utc, tz=_dt.timezone.utc)
    return t.strftime('%H%M%S') + f'.{t.microsecond // 10000:02d}'


def format_gga(utc: float, lat: float, lon: float, alt_msl: float, quality: int,
               satellites: int, hdop: float, geoid_sep: float = 0.0,
               talker: str = 'GP') -> bytes:
    """A GGA sentence. lat/lon [deg] (NaN or quality 0 -> empty fields), alt [m MSL]."""
    if quality == 0 or not (math.isfinite(lat) and math.isfinite(lon)):
        return sentence(f'{talker}GGA,{_hms(utc)},,,,,0,{satellites:02d},99.99,,,,,,')
    la, south = _ddmm(lat, 2)
    lo, west = _ddmm(lon, 3)
    return sentence(f'{talker}GGA,{_hms(utc)},{la},{"S" if south else "N"},{lo},'
                    f'{"W" if west else "E"},{quality},{satellites:02d},{hdop:.2f},'
                    f'{alt_msl:.1f},M,{geoid_sep:.1f},M,,')


def format_rmc(utc: float, lat: float, lon: float, valid: bool, speed_knots: float = 0.0,
               course_deg: float = 0.0, talker: str = 'GP') -> bytes:
    """An RMC sentence carrying date and time; empty position when not ``valid``."""
    t = _dt.datetime.fromtimestamp(utc, tz=_dt.timezone.utc)
    date = t.strftime('%d%m%y')
    if not valid or not (math.isfinite(lat) and math.isfinite(lon)):
        return sentence(f'{talker}RMC,{_hms(utc)},V,,,,,,,{date},,,N')
    la, south = _ddmm(lat, 2)
    lo, west = _ddmm(lon, 3)
    return sentence(f'{talker}RMC,{_hms(utc)},A,{la},{"S" if south else "N"},{lo},'
                    f'{"W" if west else "E"},{speed_knots:.3f},{course_deg:.2f},{date},,,A')


def format_gsa(mode: int, prns: list[int], pdop: float, hdop: float, vdop: float,
               talker: str = 'GP') -> bytes:
    """A GSA sentence (mode 1 no fix, 2 2-D, 3 3-D; up to 12 satellite PRNs)."""
    ids = [f'{p:02d}' for p in prns[:12]] + [''] * (12 - min(12, len(prns)))
    if mode == 1:
        return sentence(f'{talker}GSA,A,1,' + ','.join([''] * 12) + ',99.99,99.99,99.99')
    return sentence(f'{talker}GSA,A,{mode},' + ','.join(ids) + f',{pdop:.2f},{hdop:.2f},{vdop:.2f}')
