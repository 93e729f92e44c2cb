"""Check a recorded (simulated or real) day against the ephemeris: the numbers the
system scenario tests assert on. Pure Python + numpy (no rclpy); reads bags with
:class:`sslfr_recording.bag.reader.BagReader`.

- :func:`read_day` turns a bag into time series (ROS time [s since the Unix epoch]
  of each message's header stamp; angles [rad]).
- :func:`tracking_error` compares each axis' measured angle with the ideal command
  of :func:`sslfr_planner.tracking_table.evaluate` (seed 000 eqs. 9-13 and the
  collector's longitudinal law) for the same site and collector.

Time quantisation in simulation. At ``--speed X`` the drivers poll their board on a
steady (wall) clock and ``/clock`` advances in steps, so a measured angle stamped
``t`` belongs to a setpoint between ``t - lag`` and ``t`` with
``lag = X * (wall latency)``. :func:`tracking_error` therefore reports the distance
from the measured angle to the ideal angles over ``[t - lag, t]`` (zero lag: the
plain difference), and the tests bound it by one motor step plus the position
sensor noise.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sslfr_common.contract import JOINTS
from sslfr_common.timeconv import to_sec



@dataclass
class Series:
    """Columns of one topic (numpy arrays / lists, equal length)."""

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
class Day:
    """Time series of a recorded day (see :func:`read_day`)."""

    axes: dict[str, Series]
    phase: Series
    safety: Series
    outlet: Series
    inlet: Series
    fix: Series
    trajectory: Series
    topics: dict[str, int]
    diagnostics: Series = field(default_factory=Series)

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


def _collect(reader, topic: str, fields: dict, log_time: bool = False) -> Series:
    """Rows of ``topic`` sorted by header stamp (by the recorder's log time when there
    is no header or with ``log_time``)."""
    rows = []
    for raw, msg in reader.decoded([topic]):
        header = getattr(msg, 'header', None)
        t = to_sec(header.stamp) if header is not None and not log_time else to_sec(raw.log_time)
        rows.append((t, [f(msg) for f in fields.values()]))
    rows.sort(key=lambda r: r[0])
    cols = {}
    for i, key in enumerate(fields):
        values = [r[1][i] for r in rows]
        numeric = values and all(isinstance(v, (bool, int, float)) for v in values)
        cols[key] = np.asarray(values) if numeric or not values else values
    return Series(np.asarray([r[0] for r in rows], dtype=float), cols)


def read_day(bag: str | Path) -> Day:
    """Read the tracker's topics from a bag directory (or .mcap file)."""
    from sslfr_recording.bag.reader import BagReader

    reader = BagReader(bag)
    topics = {}
    for raw in reader.messages():
        topics[raw.topic] = topics.get(raw.topic, 0) + 1
    axes = {}
    for axis in JOINTS:
        axes[axis] = _collect(reader, f'/axes/{axis}/status', {
            'measured': lambda m: float(m.measured), 'setpoint': lambda m: float(m.setpoint),
            'commanded': lambda m: float(m.commanded), 'error': lambda m: float(m.error),
            'state': lambda m: m.state, 'link_state': lambda m: int(m.link_state),
            'frames_lost': lambda m: int(m.frames_lost), 'homed': lambda m: bool(m.homed),
            'fault_bits': lambda m: int(m.fault_bits), 'steps': lambda m: int(m.steps)})
    phase = _collect(reader, '/tracker/phase', {
        'phase': lambda m: int(m.phase), 'name': lambda m: m.phase_name, 'reason': lambda m: m.reason,
        'mode': lambda m: m.mode, 'site_source': lambda m: m.site_source,
        'latitude': lambda m: float(m.latitude), 'longitude': lambda m: float(m.longitude),
        'sunrise': lambda m: to_sec(m.sunrise), 'sunset': lambda m: to_sec(m.sunset)})
    safety = _collect(reader, '/safety/state', {
        'level': lambda m: int(m.level), 'reasons': lambda m: list(m.reasons),
        'stow_required': lambda m: bool(m.stow_required), 'stopped_axes': lambda m: list(m.stopped_axes)})
    outlet = _collect(reader, '/absorber/outlet_temperature', {'value': lambda m: float(m.temperature)})
    inlet = _collect(reader, '/absorber/inlet_temperature', {'value': lambda m: float(m.temperature)})
    fix = _collect(reader, '/gps/fix', {'status': lambda m: int(m.status.status),
                                        'latitude': lambda m: float(m.latitude)})
    # a trajectory's stamp is its first point's time: when it was sent is the log time
    traj = _collect(reader, '/tracker/trajectory', {'points': lambda m: len(m.points)}, log_time=True)
    rows = []
    for raw, msg in reader.decoded(['/diagnostics']):
        for st in msg.status:
            rows.append((to_sec(msg.header.stamp), st.name, int(st.level) if not isinstance(st.level, bytes)
                         else st.level[0], st.message, {kv.key: kv.value for kv in st.values}))
    rows.sort(key=lambda r: r[0])
    diag = Series(np.asarray([r[0] for r in rows], dtype=float),
                  {'name': [r[1] for r in rows], 'level': np.asarray([r[2] for r in rows]),
                   'message': [r[3] for r in rows], 'values': [r[4] for r in rows]})
    return Day(axes, phase, safety, outlet, inlet, fix, traj, topics, diag)


def interval_distance(value: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from ``value`` to the closed interval between ``a`` and ``b`` (any order)."""
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return np.maximum(0.0, np.maximum(lo - value, value - hi))


def tracking_error(t: np.ndarray, measured: np.ndarray, ideal_fn, lag: float = 0.0,
                   samples: int = 8) -> np.ndarray:
    """|measured - ideal| [rad] allowing the measurement to lag by up to ``lag`` [s].

    Parameters
    ----------
    t : numpy.ndarray
        Stamps of the measurements [s since the Unix epoch].
    measured : numpy.ndarray
        Measured joint angles [rad].
    ideal_fn : callable
        ``ideal_fn(t_array) -> angles [rad]``, e.g. a column of
        ``sslfr_planner.tracking_table.evaluate``.
    lag : float
        Allowed lag [s] (>= 0); the ideal path over ``[t - lag, t]`` is sampled at
        ``samples`` points and the distance to the nearest is returned.
    """
    t = np.asarray(t, dtype=float)
    measured = np.asarray(measured, dtype=float)
    if lag <= 0:
        return np.abs(measured - ideal_fn(t))
    best = np.full(t.shape, np.inf)
    prev = ideal_fn(t - lag)
    for k in range(1, samples + 1):
        cur = ideal_fn(t - lag + lag * k / samples)
        best = np.minimum(best, interval_distance(measured, prev, cur))
        prev = cur
    return best


# ------------------------------------------------------------------------------ reference
def planner_config(config: str | Path) -> dict:
    """The planner's parameter values for a site config: its defaults overlaid by the
    config's ``/**`` and ``planner`` sections (``sslfr_planner.planner_params``)."""
    from sslfr_bringup import nodeset
    from sslfr_planner.planner_params import PLANNER_PARAMS

    cfg = PLANNER_PARAMS.defaults()
    for key, value in nodeset.node_params(nodeset.read_params(config), 'planner').items():
        if key in cfg:
            cfg[key] = value
    return cfg


def reference(config: str | Path, latitude_deg: float, longitude_deg: float, elevation: float):
    """``table(t) -> TrackingTable``: the ephemeris core's ideal table
    (:func:`sslfr_planner.tracking_table.evaluate`, NREL SPA + seed 000 eqs. 9-16) for the
    config's collector at the given site [deg, deg, m] (the site the planner reports
    in ``tracker/phase``)."""
    from sslfr_planner import tracking_table
    from sslfr_planner.day_cycle import make_collector, make_site
    from sslfr_planner.site_source import SiteFix

    cfg = planner_config(config)
    site = make_site(cfg, SiteFix(latitude_deg, longitude_deg, elevation, 'parameters'))
    collector = make_collector(cfg)
    return lambda t: tracking_table.evaluate(np.atleast_1d(np.asarray(t, dtype=float)), site, collector)


# ------------------------------------------------------------------------------ running
def run_sim(args: list[str], env: dict, out: str | Path, timeout: float = 300.0):
    """Run ``sslfr sim ARGS --out OUT`` as a process; return
    ``(completed_process, summary dict from OUT/sim.json, newest bag dir or None)``."""
    import json
    import os
    import subprocess

    root = Path(os.environ.get('SSLFR_ROOT') or Path(__file__).resolve().parents[3])
    out = Path(out)
    proc = subprocess.run([str(root / 'sslfr'), 'sim', *args, '--out', str(out)], env=env,
                          capture_output=True, text=True, timeout=timeout)
    summary = json.loads((out / 'sim.json').read_text()) if (out / 'sim.json').exists() else {}
    bags = sorted((p for p in (Path(summary['bags']).iterdir() if summary.get('bags') else [])
                   if (p / 'metadata.yaml').exists()), key=lambda p: p.stat().st_mtime)
    return proc, summary, (bags[-1] if bags else None)
