"""A recorded day: a bag decoded once into time series, and the ideal reference of
its run. Pure Python + numpy (no rclpy); messages are decoded through the bag's own
schemas.

The day report (:mod:`.report`), the what-if comparison (:mod:`.bag.whatif`) and the
simulated-day tests read a bag through :func:`read_day`, and build the ideal axis
angles with :func:`reference`: the collector and site parameters of the run's own site
config (:func:`planner_config`, read once) and the collector description it names
(:func:`run_description`: the movements the collector has, their laws, its optics) at
the site the planner reported.

Times are ROS time [s since the Unix epoch]: each message's ``header.stamp``, or its
log time when the stamp is zero or the type has no header; angles [rad].
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sslfr_common.contract import (ROSOUT, ABSORBER_TEMPERATURE, AXIS_STATUS, DIAGNOSTICS, GPS_FIX, IRRADIANCE_BEAM, JOINT_STATES,
                                   JOINTS, SAFETY_STATE, THERMAL_POWER, TRACKER_PHASE, TRACKER_TRAJECTORY)
from sslfr_common.timeconv import to_sec

from .bag.metadata import BagError
from .bag.reader import BagReader, message_time

ROSOUT_KEY = ROSOUT.name.lstrip('/')   # found in any namespace, like the graph's relative names

#: the day's topics (relative names; found in any namespace) -> Day attribute
TOPICS = {
    TRACKER_PHASE.name: 'phase', SAFETY_STATE.name: 'safety', GPS_FIX.name: 'fix',
    ABSORBER_TEMPERATURE.of('inlet'): 'inlet', ABSORBER_TEMPERATURE.of('outlet'): 'outlet',
    IRRADIANCE_BEAM.name: 'beam', TRACKER_TRAJECTORY.name: 'trajectory', JOINT_STATES.name: 'joints',
    ROSOUT_KEY: 'logs', THERMAL_POWER.name: 'thermal',
    **{AXIS_STATUS.of(a): 'axes' for a in JOINTS},
}
#: topic -> its columns (a key of _FIELDS); joint_states is split by joint instead
_KIND = {TRACKER_PHASE.name: 'phase', SAFETY_STATE.name: 'safety', GPS_FIX.name: 'fix', IRRADIANCE_BEAM.name: 'beam',
         ABSORBER_TEMPERATURE.of('inlet'): 'temperature', ABSORBER_TEMPERATURE.of('outlet'): 'temperature',
         TRACKER_TRAJECTORY.name: 'trajectory', ROSOUT_KEY: 'log', THERMAL_POWER.name: 'thermal', **{AXIS_STATUS.of(a): 'status' for a in JOINTS}}


@dataclass
class Series:
    """Columns of one topic (numpy arrays for numbers, lists otherwise; equal length),
    sorted by time ``t`` [s]."""

    t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cols: dict = field(default_factory=dict)

    def __getitem__(self, key):
        return self.cols[key]

    def __len__(self) -> int:
        return int(self.t.size)

    def between(self, t0: float, t1: float) -> 'Series':
        k = (self.t >= t0) & (self.t <= t1)
        return Series(self.t[k], {c: (v[k] if isinstance(v, np.ndarray) else [x for x, kk in zip(v, k) if kk])
                                  for c, v in self.cols.items()})


@dataclass
class Trajectory:
    """One JointTrajectory: absolute point times [s] and positions [rad] per joint."""

    stamp: float
    joints: list[str]
    times: np.ndarray          # (n,) absolute [s]
    positions: np.ndarray      # (n, len(joints)) [rad]


@dataclass
class Day:
    """Time series of a recorded day (see :func:`read_day`).

    ``axes``: axis -> ``axes/<axis>/status`` (measured, setpoint, commanded, error [rad],
    state, link_state, frames_lost, frames_bad, homed, fault_bits, steps); ``joints``:
    axis -> ``joint_states`` positions (measured), read only when the bag has no axis
    status; ``phase``: ``tracker/phase`` (phase, name, reason, mode, site_source,
    latitude, longitude [deg], altitude [m], day_type, sunrise, solar_noon, sunset [s]);
    ``safety``: level, reasons, stow_required, stopped_axes; ``inlet``/``outlet``:
    absorber temperature value [degC]; ``beam``: g [W/m^2], saturated; ``fix``: status,
    latitude, longitude, altitude; ``trajectory``: points per trajectory at the log time
    it was sent, ``trajectories`` the same messages as :class:`Trajectory`; ``logs``:
    the nodes' log lines (``/rosout``: level, name, msg) at their log time; ``topics``:
    message count per topic; ``diagnostics`` (decoded on first use): name, level,
    message, values; ``thermal``: ``absorber/thermal_power`` (volume_flow [m^3/s],
    mass_flow [kg/s], power [W], beam [W/m^2], aperture [m^2], efficiency [-]; empty
    for a collector without a flow meter).
    """

    bag: str
    start: float
    end: float
    axes: dict[str, Series]
    joints: dict[str, Series]
    phase: Series
    safety: Series
    inlet: Series
    outlet: Series
    beam: Series
    fix: Series
    trajectory: Series
    trajectories: list[Trajectory]
    topics: dict[str, int]
    logs: Series = field(default_factory=Series)     # /rosout: level, name (node), msg at log time
    has_rosout: bool = False
    thermal: Series = field(default_factory=Series)  # absorber/thermal_power (a flow meter only)
    _reader: BagReader | None = field(default=None, repr=False)
    _diagnostics: Series | None = field(default=None, repr=False)

    @property
    def diagnostics(self) -> Series:
        if self._diagnostics is None:
            self._diagnostics = _read_diagnostics(self._reader) if self._reader is not None else Series(
                cols={'name': [], 'level': np.zeros(0), 'message': [], 'values': []})
        return self._diagnostics

    @property
    def site(self) -> dict:
        """Where the run was: the last ``tracker/phase``'s site (latitude, longitude
        [deg], altitude [m], source), else the first valid ``gps/fix``; {} when neither."""
        if len(self.phase):
            return {'latitude': float(self.phase['latitude'][-1]), 'longitude': float(self.phase['longitude'][-1]),
                    'altitude': float(self.phase['altitude'][-1]), 'source': str(self.phase['site_source'][-1])}
        ok = np.flatnonzero(np.asarray(self.fix['status']) >= 0) if len(self.fix) else []
        if len(ok):
            i = int(ok[0])
            return {'latitude': float(self.fix['latitude'][i]), 'longitude': float(self.fix['longitude'][i]),
                    'altitude': float(self.fix['altitude'][i]), 'source': GPS_FIX.name}
        return {}

    def counter(self, status_prefix: str, key: str) -> Series:
        """A numeric diagnostics value over time (statuses whose name starts with
        ``status_prefix``), e.g. ``counter('mobile_structure_driver', 'board_resets')``."""
        t, v = [], []
        for ti, name, values in zip(self.diagnostics.t, self.diagnostics['name'], self.diagnostics['values']):
            if name.startswith(status_prefix) and key in values:
                try:
                    v.append(float(values[key]))
                    t.append(ti)
                except ValueError:
                    pass
        return Series(np.asarray(t, dtype=float), {'value': np.asarray(v, dtype=float)})

    def phase_changes(self) -> list[tuple[float, str]]:
        """(time, phase_name) at each change of the published phase."""
        out = []
        last = None
        for t, name in zip(self.phase.t, self.phase['name']):
            if name != last:
                out.append((float(t), name))
                last = name
        return out


def find_topic(topics, name: str) -> str | None:
    """The recorded topic for the relative ``name``: ``/name``, else the first topic
    ending in ``/name`` (a namespaced graph: ``/sslfr1/tracker/phase``)."""
    for cand in ('/' + name.lstrip('/'), name):
        if cand in topics:
            return cand
    suffix = '/' + name.lstrip('/')
    for t in topics:
        if t.endswith(suffix):
            return t
    return None


#: per topic: the columns decoded from each message
_FIELDS = {
    'status': {'measured': lambda m: float(m.measured), 'setpoint': lambda m: float(m.setpoint),
               'commanded': lambda m: float(m.commanded), 'error': lambda m: float(m.error),
               'state': lambda m: m.state, 'link_state': lambda m: int(m.link_state),
               'frames_lost': lambda m: int(m.frames_lost), 'frames_bad': lambda m: int(m.frames_bad),
               'homed': lambda m: bool(m.homed), 'fault_bits': lambda m: int(m.fault_bits),
               'steps': lambda m: int(m.steps), 'moving': lambda m: bool(m.moving)},
    'phase': {'phase': lambda m: int(m.phase), 'name': lambda m: m.phase_name, 'reason': lambda m: str(m.reason),
              'mode': lambda m: m.mode, 'site_source': lambda m: str(m.site_source),
              'latitude': lambda m: float(m.latitude), 'longitude': lambda m: float(m.longitude),
              'altitude': lambda m: float(m.altitude), 'day_type': lambda m: int(m.day_type),
              'sunrise': lambda m: to_sec(m.sunrise), 'solar_noon': lambda m: to_sec(m.solar_noon),
              'sunset': lambda m: to_sec(m.sunset)},
    'safety': {'level': lambda m: int(m.level), 'reasons': lambda m: [str(r) for r in m.reasons],
               'stow_required': lambda m: bool(m.stow_required), 'stopped_axes': lambda m: list(m.stopped_axes)},
    'temperature': {'value': lambda m: float(m.temperature)},
    'beam': {'g': lambda m: float(m.beam), 'saturated': lambda m: bool(m.saturated)},
    'fix': {'status': lambda m: int(m.status.status), 'latitude': lambda m: float(m.latitude),
            'longitude': lambda m: float(m.longitude), 'altitude': lambda m: float(m.altitude)},
    'trajectory': {'points': lambda m: len(m.points)},
    'thermal': {'volume_flow': lambda m: float(m.volume_flow), 'mass_flow': lambda m: float(m.mass_flow),
                'power': lambda m: float(m.power), 'beam': lambda m: float(m.beam),
                'aperture': lambda m: float(m.aperture), 'efficiency': lambda m: float(m.efficiency)},
    'log': {'level': lambda m: int(m.level), 'name': lambda m: str(m.name), 'msg': lambda m: str(m.msg)},
}


def _series(rows: list, fields) -> Series:
    """A Series of ``(t, values)`` rows, sorted by time (stable)."""
    rows.sort(key=lambda r: r[0])
    cols = {}
    for i, key in enumerate(fields):
        values = [r[1][i] for r in rows]
        numeric = values and all(isinstance(v, (bool, int, float)) for v in values)
        cols[key] = np.asarray(values) if numeric or not values else values
    return Series(np.asarray([r[0] for r in rows], dtype=float), cols)


def _trajectory(msg, t0: float) -> Trajectory | None:
    joints = list(msg.joint_names)
    if not msg.points or not joints:
        return None
    times = np.array([t0 + to_sec(p.time_from_start) for p in msg.points])
    pos = np.full((len(msg.points), len(joints)), np.nan)
    for i, p in enumerate(msg.points):
        n = min(len(p.positions), len(joints))
        pos[i, :n] = list(p.positions)[:n]
    return Trajectory(t0, joints, times, pos)


def read_day(bag: str | Path | BagReader, start_ns: int | None = None, end_ns: int | None = None,
             topics=None) -> Day:
    """Decode a bag directory (or .mcap file, or an open :class:`BagReader`) once into
    a :class:`Day`, optionally only [``start_ns``, ``end_ns``) of log time and only the
    day's ``topics`` named (keys of :data:`TOPICS`; the others stay empty, and
    ``Day.topics`` then counts only those).

    Raises
    ------
    BagError
        The bag cannot be read, or a message of the day's topics cannot be decoded.
    """
    reader = bag if isinstance(bag, BagReader) else BagReader(bag)
    names = {key: find_topic(reader.topics, key) if topics is None or key in topics else None for key in TOPICS}
    if any(names[AXIS_STATUS.of(a)] for a in JOINTS):
        names[JOINT_STATES.name] = None          # the status holds the measured angles
    by_topic = {t: k for k, t in names.items() if t}
    rows: dict[str, list] = {k: [] for k in _KIND}
    joint_rows: dict[str, list] = {a: [] for a in JOINTS}
    trajectories: list[Trajectory] = []
    counts: dict[str, int] = {}
    for raw in reader.messages(None if topics is None else list(by_topic), start_ns, end_ns):
        counts[raw.topic] = counts.get(raw.topic, 0) + 1
        key = by_topic.get(raw.topic)
        if key is None:
            continue
        try:
            m = reader.decoder(raw.type)(raw.data)
        except BagError:
            raise
        except Exception as exc:  # noqa: BLE001 - decoder errors vary
            raise BagError(f'cannot decode a {raw.type} message on {raw.topic}: {exc}') from exc
        if key == JOINT_STATES.name:
            t = message_time(m.header, raw.log_time)
            for name, pos in zip(m.name, m.position):
                if name in joint_rows:
                    joint_rows[name].append((t, [float(pos)]))
            continue
        values = [f(m) for f in _FIELDS[_KIND[key]].values()]
        if key == ROSOUT_KEY:
            # a line's own stamp is its node's system clock: the log time is the day's ROS
            # time (simulated or replayed days included)
            rows[key].append((to_sec(raw.log_time), values))
            continue
        if key == TRACKER_TRAJECTORY.name:
            # a trajectory's stamp is its first point's time: when it was sent is the log time
            rows[key].append((to_sec(raw.log_time), values))
            tr = _trajectory(m, message_time(m.header, raw.log_time))
            if tr is not None:
                trajectories.append(tr)
            continue
        rows[key].append((message_time(m.header, raw.log_time), values))
    trajectories.sort(key=lambda tr: tr.stamp)
    series = {k: _series(rows[k], _FIELDS[kind]) for k, kind in _KIND.items()}
    return Day(
        bag=str(reader.path), start=to_sec(reader.start_ns), end=to_sec(reader.end_ns),
        axes={a: series[AXIS_STATUS.of(a)] for a in JOINTS},
        joints={a: _series(joint_rows[a], ('measured',)) for a in JOINTS if joint_rows[a]},
        phase=series[TRACKER_PHASE.name], safety=series[SAFETY_STATE.name],
        inlet=series[ABSORBER_TEMPERATURE.of('inlet')], outlet=series[ABSORBER_TEMPERATURE.of('outlet')],
        beam=series[IRRADIANCE_BEAM.name], fix=series[GPS_FIX.name], trajectory=series[TRACKER_TRAJECTORY.name],
        trajectories=trajectories, topics=counts, logs=series[ROSOUT_KEY],
        has_rosout=names[ROSOUT_KEY] is not None, thermal=series[THERMAL_POWER.name], _reader=reader)


def _read_diagnostics(reader: BagReader) -> Series:
    topic = find_topic(reader.topics, DIAGNOSTICS.name)
    rows = []
    for raw, msg in (reader.decoded([topic]) if topic else ()):
        for st in msg.status:
            rows.append((message_time(msg.header, raw.log_time), st.name,
                         int(st.level) if not isinstance(st.level, bytes) else st.level[0],
                         st.message, {kv.key: kv.value for kv in st.values}))
    rows.sort(key=lambda r: r[0])
    return Series(np.asarray([r[0] for r in rows], dtype=float),
                  {'name': [r[1] for r in rows], 'level': np.asarray([r[2] for r in rows]),
                   'message': [r[3] for r in rows], 'values': [r[4] for r in rows]})


# ------------------------------------------------------------------------------ reference
def default_config() -> Path:
    """The site config a run uses when none is named: the node set's default
    (``config/nodeset.yaml``), the one ``sslfr up`` and ``sslfr sim`` start with."""
    from sslfr_bringup import nodeset
    return nodeset.resolve_config(None, default=nodeset.load().config)


def planner_config(config: str | Path | None) -> dict:
    """The planner's parameter values for a site config (a path, or a name in the node
    set's config directory): its defaults overlaid with the config's ``/**`` and
    ``planner`` sections; None: the planner's defaults alone. The file is judged as
    ``sslfr up`` judges it (the nodes' own parameter tables): NodeSetError naming the
    file and each bad key."""
    from sslfr_bringup import nodeset
    from sslfr_planner.planner_params import PLANNER_PARAMS

    cfg = PLANNER_PARAMS.defaults()
    if config:
        flat = nodeset.node_params(nodeset.checked_params(nodeset.load(), nodeset.resolve_config(config)), 'planner')
        cfg.update(PLANNER_PARAMS.coerce({k: v for k, v in flat.items() if k in cfg}))
    return cfg


def run_description(config: str | Path | None):
    """The collector description the run's site config names (``collector.description``
    of its planner section, relative to the config as the planner finds it), or None
    when the config names none (or no config: the planner's defaults).
    :class:`sslfr_planner.description.DescriptionError` (a ValueError) when it is broken."""
    from sslfr_bringup import nodeset
    from sslfr_planner import description

    if not config:
        return None
    name = planner_config(config).get('collector.description') or ''
    if not name:
        return None
    return description.load(description.find(name, [str(nodeset.resolve_config(config))]))


@dataclass(frozen=True)
class Reference:
    """The ideal of a run: the ephemeris core's tracking table
    (:func:`sslfr_planner.tracking_table.evaluate`, NREL SPA + seed 000 eqs. 9-16; the
    mirrors on the description's law) for the run's collector at its site. ``ref(t)`` is
    the table at times ``t`` [s]; ``description`` the run's collector description (None:
    the config names none)."""

    config: str                # the site config it was built from ('' for the planner's defaults)
    collector: object          # sslfr_planner.collector.Collector
    site: object               # sslfr_planner.site.Site
    description: object = None  # sslfr_planner.description.Description or None

    @property
    def joints(self) -> tuple[str, ...]:
        """The collector's movements (the description's; every contract joint without one)."""
        return self.description.joints if self.description is not None else JOINTS

    def __call__(self, t):
        from sslfr_planner import tracking_table
        return tracking_table.evaluate(np.atleast_1d(np.asarray(t, dtype=float)), self.site, self.collector)

    def angles(self, t) -> dict[str, np.ndarray]:
        """Ideal angle of each of the collector's movements at ``t`` [rad]."""
        table = self(t)
        return {a: np.asarray(getattr(table, a), dtype=float) for a in self.joints}


def reference(config: str | Path | None, latitude_deg: float, longitude_deg: float, elevation: float) -> Reference:
    """The one ideal reference of a run: the collector (its parameters and the collector
    description they name, :func:`run_description`) and the site parameters (pressure,
    temperature, delta-T) of its site config (:func:`planner_config`) at the site the
    planner reported in ``tracker/phase`` [deg, deg, m]."""
    from sslfr_planner.day_cycle import make_collector, make_site
    from sslfr_planner.site_source import SiteFix

    cfg = planner_config(config)
    desc = run_description(config)
    return Reference(str(config or ''), make_collector(cfg, desc),
                     make_site(cfg, SiteFix(latitude_deg, longitude_deg, elevation, 'parameters')), desc)
