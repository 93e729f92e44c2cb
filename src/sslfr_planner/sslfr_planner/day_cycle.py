"""The automatic day cycle: day schedules on top of the ephemeris core (pure numpy, no rclpy).

Seed 000 Step 1.2: at the start of the (local solar) day the system computes sunrise,
sunset and, for each second of the day, the sun, the incidence angles and the tilt of
the mirrors, the mobile structure and the secondary reflector, "tabulated in a
database"; Steps 2-4 follow that table; Step 5 starts again at 0:00. This module
builds that table with :func:`sslfr_planner.tracking_table.evaluate` (the ephemeris core:
NREL SPA, seed 000 eqs. 9-16) for the local solar day [D, D + 1) of the site, where
day D starts at 0:00 local mean solar time (UTC - longitude / 15 h), and answers the
node's questions: the automatic phase and the setpoints at an instant, a rolling
horizon of setpoints with rates, the sun now.

Optional tracking window (seed 003: the Arduino tracker follows the sun from 7:00 to
17:00 local clock time in 15-minute steps): with ``collector.tracking_start`` /
``tracking_end`` set, TRACKING is [max(sunrise, start), min(sunset, end)) of the
day, PRE_DAWN is the ``pre_dawn_lead`` before it (axes at the first tracking
position) and STOWING the ``stow_duration`` after it; the rest of the day is NIGHT.
Without a window the core's table is used unchanged.

Times: float seconds since the Unix epoch (UTC). Angles: radians.
"""
from __future__ import annotations

import datetime
import math
from dataclasses import dataclass

import numpy as np

from sslfr_common.contract import JOINT_LIMITS, JOINTS, Phase

from . import tracking_table, spa
from .collector import Collector, FieldGeometry
from .tracking_table import TrackingTable, evaluate
from .events import H0_DEG, SunEvents, sun_events
from .site import Site
from .site_source import SiteFix
from .trajectory import Horizon

#: One-sided setpoint slope above which a change between two points is treated as a
#: step (phase change, seed 003 15-min step), not as motion: its rate is reported as
#: 0 and the driver's own speed limit shapes the move [rad/s]. The sun moves the
#: axes at < 2e-4 rad/s except within a few degrees of the poles.
STEP_RATE = 0.01

_EPOCH = datetime.date(1970, 1, 1)


def make_site(cfg: dict, fix: SiteFix) -> Site:
    """Core :class:`Site` from a site fix [deg, m] and the site.* parameters."""
    return Site.from_degrees(fix.latitude_deg, fix.longitude_deg, fix.elevation,
                             pressure=float(cfg['site.pressure']),
                             temperature=float(cfg['site.temperature']),
                             delta_t=None if cfg['site.delta_t_model'] else float(cfg['site.delta_t']))


def make_collector(cfg: dict, description=None) -> Collector:
    """Core :class:`Collector` from the collector.* parameters (SI, radians).

    ``description`` (:class:`sslfr_planner.description.Description`): the collector it
    describes wins over the parameters (``sslfr up`` refuses a site config whose values
    contradict it; a value left out would otherwise be seed 000's default): its field
    geometry (:func:`sslfr_planner.prototype.field_geometry`), axis azimuth and
    longitudinal law ('horizontal' without longitudinal movements), seed 003's step
    (``law_params.step_s``); the mirrors follow its law, within its mirror range (kept
    inside the contract's kinematic limits) and sleeping at its sleep position.
    """
    geometry = FieldGeometry(n_per_side=int(cfg['collector.n_per_side']),
                             mirror_width=float(cfg['collector.mirror_width']),
                             gap=float(cfg['collector.gap']),
                             receiver_height=float(cfg['collector.receiver_height']),
                             tube_diameter=float(cfg['collector.tube_diameter']),
                             central_mirror=bool(cfg['collector.central_mirror']))
    extra = {'geometry': geometry, 'azimuth': float(cfg['collector.azimuth']), 'law': cfg['collector.law'],
             'tracking_step': float(cfg['collector.tracking_step'])}
    if description is not None:
        from .prototype import field_geometry
        m = description.movements[JOINTS[0]]
        lo = max(m.range[0], JOINT_LIMITS[JOINTS[0]][0])
        hi = min(m.range[1], JOINT_LIMITS[JOINTS[0]][1])
        extra.update(description=description, mirror_min=lo, mirror_max=hi, sleeping=min(max(m.sleep, lo), hi),
                     geometry=field_geometry(description), azimuth=description.optics.azimuth,
                     law=description.longitudinal_law)
        if 'step_s' in m.law_params:
            extra['tracking_step'] = float(m.law_params['step_s'])
    return Collector(**extra,
                     pre_dawn_lead=float(cfg['collector.pre_dawn_lead']),
                     stow_duration=float(cfg['collector.stow_duration']))


@dataclass
class DaySchedule:
    """One local solar day's schedule: its per-second table (the seed's database),
    sun events and tracking window.

    Attributes
    ----------
    day : int
        Local mean solar date, days since 1970-01-01.
    start : float
        0:00 local mean solar time of that date [s, UTC epoch].
    table : TrackingTable
        Whole UTC seconds floor(start) .. floor(start) + 86400 (86,401 rows).
    events : SunEvents
        Sunrise, solar noon, sunset of the day (core :func:`events.sun_events`).
    window : tuple of float or None
        Effective (tracking start, tracking end) [s] when a tracking window is set.
    """

    day: int
    start: float
    table: TrackingTable
    events: SunEvents
    window: tuple[float, float] | None = None

    @property
    def date(self) -> datetime.date:
        return _EPOCH + datetime.timedelta(days=self.day)

    def describe(self) -> str:
        """One line: date, day type, events in UTC."""
        def hms(t):
            return '-' if t is None else datetime.datetime.fromtimestamp(
                t, datetime.timezone.utc).strftime('%H:%M:%SZ')
        ev = self.events
        text = (f'{self.date.isoformat()} {ev.day_type}: sunrise {hms(ev.sunrise)}, '
                f'noon {hms(ev.solar_noon)}, sunset {hms(ev.sunset)}')
        if self.window is not None:
            text += f'; tracking {hms(self.window[0])}-{hms(self.window[1])}'
        return text


class DayCycle:
    """The day cycle of one site and collector configuration: the schedule of each
    local solar day (computed on demand, a few cached) and, from it, the automatic
    phase, setpoints and horizons at any instant.

    Parameters
    ----------
    cfg : dict
        Validated planner parameters (:mod:`sslfr_planner.planner_params`).
    site_fix : SiteFix
        Where to plan for [deg, m].
    description : Description, optional
        The collector description whose mirror law the mirrors follow (:func:`make_collector`).

    Raises
    ------
    ValueError
        When the core refuses the site or collector (message says why).
    """

    def __init__(self, cfg: dict, site_fix: SiteFix, description=None):
        self.cfg = cfg
        self.site_fix = site_fix
        self.description = description
        self.site = make_site(cfg, site_fix)
        self.collector = make_collector(cfg, description)
        ts, te = float(cfg['collector.tracking_start']), float(cfg['collector.tracking_end'])
        self.window = (ts, te) if ts >= 0 and te >= 0 else None
        self.utc_offset = float(cfg['collector.utc_offset'])
        self._lon_s = math.degrees(self.site.longitude) * 240.0   # longitude as time [s]
        self._schedules: dict[int, DaySchedule] = {}
        self.current_schedule: DaySchedule | None = None

    @staticmethod
    def check_config(cfg: dict) -> None:
        """Raise ValueError if the core would refuse ``cfg`` (site from parameters)."""
        make_site(cfg, SiteFix(cfg['site.latitude_deg'], cfg['site.longitude_deg'],
                               cfg['site.elevation'], 'parameters'))
        make_collector(cfg)

    # ---------------------------------------------------------------- day schedules
    def day_index(self, t: float) -> int:
        """Local mean solar date of instant ``t`` [days since 1970-01-01]."""
        return int(math.floor((t + self._lon_s) / 86400.0))

    def day_start(self, day: int) -> float:
        """0:00 local mean solar time of ``day`` [s]."""
        return day * 86400.0 - self._lon_s

    def needs_new_day(self, now: float) -> bool:
        """True when ``now`` is past the current schedule's day (seed 000 Step 5)."""
        return self.current_schedule is None or self.day_index(now) != self.current_schedule.day

    def plan(self, now: float) -> DaySchedule:
        """Compute today's schedule afresh (drops cached days) and make it current."""
        self._schedules.clear()
        self.current_schedule = self.schedule(self.day_index(now))
        return self.current_schedule

    def schedule(self, day: int) -> DaySchedule:
        """The schedule of local solar ``day`` (cached; at most three days are kept)."""
        plan = self._schedules.get(day)
        if plan is None:
            start = self.day_start(day)
            t = math.floor(start) + np.arange(86401, dtype=np.float64)
            events = sun_events(_EPOCH + datetime.timedelta(days=day), self.site)
            table = evaluate(t, self.site, self.collector, events)
            window = self._window(events, start) if self.window else None
            if window is not None:
                self._apply_window(table, window)
            plan = DaySchedule(day, start, table, events, window)
            if len(self._schedules) >= 3:
                keep = self.current_schedule.day if self.current_schedule else day
                for d in sorted(self._schedules, key=lambda d: abs(d - keep), reverse=True)[:1]:
                    del self._schedules[d]
            self._schedules[day] = plan
        return plan

    # ------------------------------------------------------------ tracking window
    def _window(self, ev: SunEvents, start: float) -> tuple[float, float]:
        """Effective tracking interval of the day [s] (module docstring)."""
        local_date = math.floor((ev.solar_noon + self.utc_offset) / 86400.0)
        midnight = local_date * 86400.0 - self.utc_offset
        ws, we = midnight + self.window[0], midnight + self.window[1]
        if ev.day_type == 'polar_night':
            return (ws, ws)                       # empty: no tracking
        if ev.day_type == 'normal':
            ws = max(ws, ev.sunrise if ev.sunrise is not None else start)
            we = min(we, ev.sunset if ev.sunset is not None else start + 86400.0)
        return (ws, max(ws, we))

    def _apply_window(self, table: TrackingTable, window: tuple[float, float]) -> None:
        """Rewrite phases and commands of ``table`` in place for a tracking window."""
        ws, we = window
        t = table.t
        c = self.collector
        rest = self._rest(t)
        phase = np.full(t.size, Phase.NIGHT, dtype=np.uint8)
        if we > ws:
            tracking = (t >= ws) & (t < we) & (table.phase == Phase.TRACKING)
            pre = (t < ws) & (t >= ws - c.pre_dawn_lead) & (c.pre_dawn_lead > 0)
            stowing = (t >= we) & (t < we + c.stow_duration)
            phase[tracking] = Phase.TRACKING
            phase[pre] = Phase.PRE_DAWN
            phase[stowing] = Phase.STOWING
            # the first tracking row of the table is the initial position (Step 2)
            k = int(np.argmax(tracking)) if tracking.any() else 0
            first_pose = (table.mirrors[k], table.mobile_structure[k], table.secondary_reflector[k])
        else:
            tracking = np.zeros(t.size, dtype=bool)
            pre = tracking
        idle = ~tracking
        for k, name in enumerate(JOINTS):
            arr = getattr(table, name)
            arr[idle] = rest[:, k][idle]
            if we > ws:
                arr[pre] = first_pose[k]
        table.phase = phase

    def _rest(self, t: np.ndarray) -> np.ndarray:
        """NIGHT / STOW pose at instants t: mirrors sleeping, longitudinal axes at rest [rad].

        The longitudinal values are the core's own NIGHT commands (``tracking_table._resting``:
        the rest position under the moving laws, the fixed/day's value otherwise).
        """
        bm, ba = tracking_table._resting(t, self.site, self.collector)
        return np.stack([np.full(t.size, self.collector.sleeping), bm, ba], axis=1)

    def sleep_pose(self, t: float) -> np.ndarray:
        """Stow target at ``t``: (sleeping, structure rest, reflector rest) [rad]."""
        return self._rest(np.array([float(t)]))[0]

    # ----------------------------------------------------------------- lookups
    def table_at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Phase codes and setpoints (N, 3) [rad] at instants ``t`` [s].

        Whole-second instants inside a planned day are read from that day's table
        (seed 000 Step 1.3: the tracker follows the tabulated database); any other
        instant is evaluated by the core with the same (deterministic) algorithm, so
        both give identical numbers.
        """
        t = np.asarray(t, dtype=np.float64)
        phase = np.empty(t.size, dtype=np.uint8)
        pos = np.empty((t.size, 3))
        days = np.floor((t + self._lon_s) / 86400.0).astype(np.int64)
        for day in np.unique(days):
            sel = np.nonzero(days == day)[0]
            ts = t[sel]
            plan = self._schedules.get(int(day))
            if plan is None and self.current_schedule is not None and abs(int(day) - self.current_schedule.day) <= 1:
                plan = self.schedule(int(day))    # tomorrow, when a horizon crosses 0:00
            if plan is not None and np.all(ts == np.floor(ts)):
                idx = (ts - plan.table.t[0]).astype(np.int64)
                if idx.min() >= 0 and idx.max() < plan.table.t.size:
                    tab = plan.table
                    phase[sel] = tab.phase[idx]
                    pos[sel, 0] = tab.mirrors[idx]
                    pos[sel, 1] = tab.mobile_structure[idx]
                    pos[sel, 2] = tab.secondary_reflector[idx]
                    continue
            tab = evaluate(ts, self.site, self.collector)
            if self.window is not None:
                ev = sun_events(_EPOCH + datetime.timedelta(days=int(day)), self.site)
                self._apply_window(tab, self._window(ev, self.day_start(int(day))))
            phase[sel] = tab.phase
            pos[sel] = np.stack([tab.mirrors, tab.mobile_structure, tab.secondary_reflector], axis=1)
        return phase, pos

    def auto_phase(self, now: float) -> int:
        """Day-cycle phase at ``now`` (the table row of the current second)."""
        return int(self.table_at(np.array([math.floor(now)]))[0][0])

    def auto_pose(self, now: float) -> np.ndarray:
        """Day-cycle setpoints at ``now`` (the table row of the current second) [rad]."""
        return self.table_at(np.array([math.floor(now)]))[1][0]

    def auto_horizon(self, t: np.ndarray) -> Horizon:
        """The day-cycle setpoints at the horizon instants ``t`` with their rates.

        Rates [rad/s] are central differences over the neighbouring instants; where
        either one-sided slope exceeds :data:`STEP_RATE` the change is a step and the
        rate is 0.
        """
        step = float(t[1] - t[0]) if t.size > 1 else 1.0
        ext = np.concatenate([[t[0] - step], t, [t[-1] + step]])
        _, pos = self.table_at(ext)
        back = (pos[1:-1] - pos[:-2]) / step
        fwd = (pos[2:] - pos[1:-1]) / step
        vel = (back + fwd) / 2.0
        vel[(np.abs(back) > STEP_RATE) | (np.abs(fwd) > STEP_RATE)] = 0.0
        return Horizon(t, pos[1:-1].copy(), vel)

    def sun(self, now: float):
        """Sun at ``now``: zenith, azimuth, transversal, longitudinal [rad], above horizon, algorithm."""
        s = spa.sun_position(np.array([now]), self.site, collector_azimuth=self.collector.azimuth)
        above = bool(s.elevation_geometric[0] > math.radians(H0_DEG))
        return (float(s.zenith[0]), float(s.azimuth[0]), float(s.transversal[0]),
                float(s.longitudinal[0]), above, 'spa')
