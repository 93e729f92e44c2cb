"""The page's live view and day plots (pure Python: message objects are read by
attribute, never imported here, so the tests feed the real generated classes).

:class:`LiveState` keeps the latest message of every topic the page shows, as plain
JSON-ready values (SI units and radians, NaN as ``None``, times as Unix seconds of ROS
time), each with the wall time it arrived; :meth:`LiveState.snapshot` is what the page
receives. A ``version`` counter tells the server whether anything changed.

:class:`DayBuffer` is the node's own buffer behind the day plots: one sample per
``period`` of ROS time (axes measured / setpoint, the mirrors' ideal drive angle for
the transversal angle of ``tracker/sun``: the collector's law once its description is
known (:func:`.collector.ideal_drive`), theta_t / 2 before (seed 000 eq. 11), absorber
temperatures, beam irradiance), cleared at local mean solar midnight (UTC - longitude / 15 h, the
planner's day), so a reload of the page shows the day so far.

Each axis' accuracy alarm (:class:`sslfr_common.accuracy.AccuracyAlarm`, the
driver's own filter) is fed every ``axes/<axis>/status`` the page receives, with the
driver's thresholds read from its parameters (``<axis>.accuracy_*`` in ``info``), so
the page shows the level, the filtered error and the estimated optical loss the
driver's ``diagnostics`` show, without subscribing to ``diagnostics``.

:func:`clear_hint` says how to clear each safety reason: the hint of the rule that
gives it (:mod:`sslfr_safety.rules`).
"""
from __future__ import annotations

import math
import threading
import time
from collections import deque
from typing import Any, Callable

from sslfr_common.contract import JOINTS, WIND
from sslfr_common.timeconv import to_sec
from sslfr_common import accuracy as accuracy_mod
from sslfr_safety.rules import hint_for

LEVELS = ('OK', 'WARN', 'STOW', 'ESTOP')
LINK_STATES = ('LINK_DOWN', 'LINK_CONNECTING', 'LINK_UP', 'LINK_FAULT')
GPS_STATUS = {-1: 'NO_FIX', 0: 'FIX', 1: 'SBAS_FIX', 2: 'GBAS_FIX'}
TEMPERATURES = ('inlet', 'outlet')


def num(x: Any, nd: int = 6) -> float | None:
    """A finite float rounded to ``nd`` decimals, else None (JSON has no NaN)."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return round(v, nd) if math.isfinite(v) else None


def seconds_or_none(t) -> float | None:
    """builtin_interfaces/Time -> Unix seconds, None for the zero time (absent)."""
    s = None if t is None else to_sec(t)
    return s if s != 0 else None


# ------------------------------------------------------------------ safety hints
#: Said about a reason no safety rule gives (a newer supervisor, a foreign node).
UNKNOWN_HINT = 'See the safety node\'s log and docs/operator.md; Safety reset clears latched faults.'


def clear_hint(reason: str) -> str:
    """How an operator clears ``reason`` (a ``safety/state`` reason): the hint of the
    safety rule that gives this text (sslfr_safety.rules, the one source)."""
    return hint_for(reason) or UNKNOWN_HINT


# ------------------------------------------------------------------ message -> dict
def phase_dict(m) -> dict:
    return {'phase': int(m.phase), 'name': m.phase_name, 'mode': m.mode, 'reason': m.reason,
            'day_type': int(m.day_type), 'sunrise': seconds_or_none(m.sunrise),
            'noon': seconds_or_none(m.solar_noon), 'sunset': seconds_or_none(m.sunset),
            'stamp': seconds_or_none(m.header.stamp),
            'site': {'latitude': num(m.latitude), 'longitude': num(m.longitude),
                     'altitude': num(m.altitude, 2), 'source': m.site_source}}


def wind_release(release_in: float) -> dict | None:
    """A wind stow's release (``SafetyState.wind_release_in`` [s]): None without a wind
    stow (NaN); ``calm`` False while the wind is not yet calm (inf), else the time left."""
    v = float(release_in)
    if math.isnan(v):
        return None
    return {'calm': math.isfinite(v), 'release_in': num(v, 1)}


def safety_dict(m) -> dict:
    level = int(m.level)
    return {'level': level, 'name': LEVELS[level] if 0 <= level < len(LEVELS) else f'level {level}',
            'stow_required': bool(m.stow_required),
            'reasons': [{'text': r, 'hint': clear_hint(r)} for r in m.reasons],
            'stopped_axes': list(m.stopped_axes), 'since': seconds_or_none(m.since), 'sequence': int(m.sequence),
            'wind_stow': bool(m.wind_stow), 'wind_release': wind_release(m.wind_release_in)}


def wind_dict(m) -> dict:
    return {'speed': num(m.speed, 2), 'gust': num(m.gust, 2), 'mean': num(m.mean, 2), 'window': num(m.window, 0),
            'stamp': seconds_or_none(m.header.stamp)}


def thermal_dict(m) -> dict:
    """``absorber/thermal_power``: flow [m^3/s] and [L/h] (for people), power [W],
    efficiency [-] (None: not computed)."""
    return {'volume_flow': num(m.volume_flow, 9), 'lph': num(m.volume_flow * 3.6e6, 1), 'power': num(m.power, 1),
            'efficiency': num(m.efficiency, 4), 'beam': num(m.beam, 0), 'aperture': num(m.aperture, 3),
            'stamp': seconds_or_none(m.header.stamp)}


def axis_dict(m) -> dict:
    link = int(m.link_state)
    return {'axis': m.axis, 'state': m.state, 'commanded': num(m.commanded), 'setpoint': num(m.setpoint),
            'measured': num(m.measured), 'error': num(m.error), 'steps': int(m.steps),
            'moving': bool(m.moving), 'homed': bool(m.homed), 'limit_bits': int(m.limit_bits),
            'fault_bits': int(m.fault_bits), 'link_state': link,
            'link': LINK_STATES[link] if 0 <= link < len(LINK_STATES) else f'link {link}',
            'frames_lost': int(m.frames_lost), 'frames_bad': int(m.frames_bad),
            'board_info': m.board_info, 'stamp': seconds_or_none(m.header.stamp)}


def sun_dict(m) -> dict:
    return {'zenith': num(m.zenith), 'azimuth': num(m.azimuth), 'transversal': num(m.transversal),
            'longitudinal': num(m.longitudinal),
            'elevation': num(math.pi / 2 - m.zenith) if math.isfinite(m.zenith) else None,
            'above_horizon': bool(m.above_horizon), 'algorithm': m.algorithm, 'stamp': seconds_or_none(m.header.stamp)}


def temperature_dict(m) -> dict:
    return {'value': num(m.temperature, 2), 'variance': num(m.variance, 3), 'stamp': seconds_or_none(m.header.stamp)}


def beam_dict(m) -> dict:
    return {'beam': num(m.beam, 2), 'illuminance': num(m.illuminance, 1), 'saturated': bool(m.saturated),
            'stamp': seconds_or_none(m.header.stamp)}


def fix_dict(m) -> dict:
    cov_type = int(m.position_covariance_type)
    cov = list(m.position_covariance)
    hstd = math.sqrt(max(cov[0], cov[4])) if cov_type and len(cov) == 9 and min(cov[0], cov[4]) >= 0 else None
    status = int(m.status.status)
    return {'status': status, 'name': GPS_STATUS.get(status, f'status {status}'), 'service': int(m.status.service),
            'latitude': num(m.latitude, 7), 'longitude': num(m.longitude, 7), 'altitude': num(m.altitude, 2),
            'horizontal_std': num(hstd, 2), 'stamp': seconds_or_none(m.header.stamp)}


# ------------------------------------------------------------------ the live state
class LiveState:
    """Latest message of every shown topic; thread-safe (ROS thread writes, web reads).

    The callbacks only keep a reference to the message and its arrival time (cheap at
    the graph's ~45 msg/s); messages are turned into JSON-ready dicts only when read
    (:meth:`get`, :meth:`snapshot`), i.e. when a page is open or a plot sample is due.
    """

    #: key -> converter of its messages
    CONVERT: dict[str, Callable] = {'phase': phase_dict, 'safety': safety_dict, 'sun': sun_dict,
                                    'beam': beam_dict, 'gps': fix_dict, 'axes': axis_dict,
                                    'temperatures': temperature_dict, WIND.name: wind_dict, 'thermal': thermal_dict}
    NESTED = ('axes', 'temperatures')

    def __init__(self, axes: tuple[str, ...] = JOINTS, wall: Callable[[], float] = time.time):
        self.axes, self.wall = tuple(axes), wall
        self._lock = threading.Lock()
        self._msgs: dict[str, Any] = {}          # 'phase' or 'axes/mirrors' -> message
        self._arrived: dict[str, float] = {}
        self.version = 0
        self.info: dict[str, Any] = {}          # remote parameters (limits, geometry), static-ish
        self.accuracy = {a: accuracy_mod.AccuracyAlarm(a) for a in self.axes}

    def _set(self, key: str, msg: Any) -> None:
        now = self.wall()
        with self._lock:
            self._msgs[key] = msg
            self._arrived[key] = now
            self.version += 1

    def on_phase(self, m) -> None:
        self._set('phase', m)

    def on_safety(self, m) -> None:
        self._set('safety', m)

    def on_axis(self, m) -> None:
        if m.axis in self.axes:
            self._set(f'axes/{m.axis}', m)
            with self._lock:
                phase = self._msgs.get('phase')
                self.accuracy[m.axis].sample(to_sec(m.header.stamp),
                                             accuracy_mod.tracking(m.state, None if phase is None else phase.phase),
                                             m.setpoint, m.measured)

    def on_sun(self, m) -> None:
        self._set('sun', m)

    def on_temperature(self, name: str, m) -> None:
        self._set(f'temperatures/{name}', m)

    def on_beam(self, m) -> None:
        self._set('beam', m)

    def on_fix(self, m) -> None:
        self._set('gps', m)

    def on_wind(self, m) -> None:
        self._set(WIND.name, m)

    def on_thermal(self, m) -> None:
        self._set('thermal', m)

    def set_info(self, key: str, value: Any) -> None:
        with self._lock:
            if self.info.get(key) != value:
                self.info[key] = value
                self.version += 1
                axis, _, name = key.partition('.')
                if axis in self.accuracy and name.startswith('accuracy.'):   # the driver's thresholds
                    p = {spec.name: self.info.get(f'{axis}.{spec.name}', spec.default)
                         for spec in accuracy_mod.PARAM_SPECS}
                    if not accuracy_mod.cross_check(p):
                        self.accuracy[axis].configure(accuracy_mod.AccuracyConfig.from_params(p))

    def get(self, key: str, sub: str | None = None) -> Any:
        """The latest message of ``key`` (``sub``: axis or sensor name) as a dict, or None."""
        with self._lock:
            msg = self._msgs.get(f'{key}/{sub}' if sub else key)
        return None if msg is None else self.CONVERT[key](msg)

    def snapshot(self, ros_time: float | None = None) -> dict:
        """Everything the page shows, with each value's age [s wall] in ``ages``."""
        with self._lock:
            now = self.wall()
            msgs = dict(self._msgs)
            out: dict[str, Any] = {'ages': {k: round(now - t, 3) for k, t in self._arrived.items()},
                                   'info': dict(self.info), 'server_time': now, 'ros_time': ros_time,
                                   'version': self.version,
                                   'accuracy': {a: {'message': alarm.text(), **alarm.values()}
                                                for a, alarm in self.accuracy.items()}}
        for key in self.NESTED:
            out[key] = {}
        for key, msg in msgs.items():
            top, _, sub = key.partition('/')
            if sub:
                out[top][sub] = self.CONVERT[top](msg)
            else:
                out[top] = self.CONVERT[top](msg)
        return out


# ------------------------------------------------------------------ day buffer
#: Columns of the day buffer (all [rad] for angles, [degC], [W/m^2]).
COLUMNS = tuple(f'{a}_{k}' for a in JOINTS for k in ('measured', 'setpoint')) + (
    'mirrors_ideal', 'inlet', 'outlet', 'beam')


def solar_day(t: float, longitude_deg: float | None) -> int:
    """Index of the local mean solar day of Unix time ``t`` (UTC + longitude/15 h)."""
    return math.floor((t + (longitude_deg or 0.0) / 15.0 * 3600.0) / 86400.0)


class DayBuffer:
    """One sample per ``period`` [s ROS time] of the columns in :data:`COLUMNS`."""

    def __init__(self, period: float = 30.0):
        if not period > 0:
            raise ValueError('period must be > 0')
        self.period = float(period)
        #: theta_t [rad] -> the mirrors' ideal drive angle [rad]; None: theta_t / 2 (seed 000 eq. 11)
        self.ideal: Callable[[float], float] | None = None
        self.maxlen = int(math.ceil(86400.0 / self.period)) + 2
        self._lock = threading.Lock()
        self.t: deque = deque(maxlen=self.maxlen)
        self.cols = {c: deque(maxlen=self.maxlen) for c in COLUMNS}
        self.day: int | None = None
        self.version = 0

    def maybe_sample(self, t: float, state: LiveState) -> bool:
        """Append a sample taken from ``state`` if ``t`` [s ROS time] is at least one
        period after the last one (a new solar day clears the buffer; time going back
        by more than a period, e.g. a replay restarted, clears it too). True if sampled."""
        if not math.isfinite(t) or t <= 0:
            return False
        if self.t and 0.0 <= t - self.t[-1] < self.period:      # the usual case: nothing to do
            return False
        phase = state.get('phase') or {}
        lon = (phase.get('site') or {}).get('longitude')
        day = solar_day(t, lon)
        with self._lock:
            if self.day is not None and (day != self.day or (self.t and t < self.t[-1] - self.period)):
                self.t.clear()
                for q in self.cols.values():
                    q.clear()
            self.day = day
            if self.t and t - self.t[-1] < self.period:
                return False
            row = self._row(state)
            self.t.append(round(t, 3))
            for c in COLUMNS:
                self.cols[c].append(row.get(c))
            self.version += 1
            return True

    def _row(self, state: LiveState) -> dict:
        row: dict[str, Any] = {}
        for axis in JOINTS:
            a = state.get('axes', axis) or {}
            row[f'{axis}_measured'] = a.get('measured')
            row[f'{axis}_setpoint'] = a.get('setpoint')
        sun = state.get('sun') or {}
        if sun.get('above_horizon') and sun.get('transversal') is not None:
            tt = sun['transversal']
            row['mirrors_ideal'] = round(self.ideal(tt) if self.ideal is not None else tt / 2.0, 6)
        for name in TEMPERATURES:
            row[name] = (state.get('temperatures', name) or {}).get('value')
        row['beam'] = (state.get('beam') or {}).get('beam')
        return row

    def to_json(self) -> dict:
        with self._lock:
            return {'period': self.period, 'day': self.day, 't': list(self.t),
                    'columns': {c: list(q) for c, q in self.cols.items()}, 'version': self.version}
